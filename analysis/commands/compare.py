"""`hamr-bench compare A.mcap B.mcap`: align two recordings by step and time and report, per channel and step,
the difference (mean, RMS, max), each side's noise and whether the difference exceeds it (definitions in
analysis/compare.py and docs/replay.md). Exit code 0 whether or not they differ; differences are results."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "compare", help="compare two recordings channel by channel and step by step",
        description="Align A and B by step and time; per channel and step report the difference, the noise of "
        "each side and whether the difference exceeds it.")
    parser.add_argument("a", type=Path, metavar="A.mcap")
    parser.add_argument("b", type=Path, metavar="B.mcap")
    parser.add_argument("--json", action="store_true", help="print the full comparison as JSON")
    parser.add_argument("--plots", type=Path, metavar="DIR", help="write overlay plots (one PNG per channel)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json
    import math

    from analysis.compare import compare_recordings, format_comparison

    result = compare_recordings(args.a, args.b)
    if args.plots:
        from analysis.compare_plots import write_overlays

        result["plots"] = [str(p) for p in write_overlays(args.a, args.b, args.plots, result)]
    if args.json:
        def clean(value):  # JSON has no infinity: a ratio over zero noise prints as null
            if isinstance(value, float) and not math.isfinite(value):
                return None
            if isinstance(value, dict):
                return {k: clean(v) for k, v in value.items()}
            if isinstance(value, list):
                return [clean(v) for v in value]
            return value

        print(json.dumps(clean(result), indent=2))
    else:
        print(format_comparison(result))
        if args.plots:
            print(f"plots: {', '.join(result['plots'])}")
    return 0
