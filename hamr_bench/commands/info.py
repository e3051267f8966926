"""`hamr-bench info RUN.mcap`: a readable summary of a recording (topics, rates, time span, how the run ended,
metadata highlights, CRC check). Exit code 0 for a complete file that passes the CRC check, 1 otherwise."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("info", help="summarise a recording (topics, rates, metadata, CRC check)")
    parser.add_argument("recording", type=Path, help="an MCAP recording (RUN.mcap)")
    parser.add_argument("--json", action="store_true", help="print the summary as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import json

    from hamr_bench.recording.info import format_summary, summarise

    summary = summarise(args.recording)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        print(format_summary(summary))
    return 0 if summary["complete"] and summary["crc"]["result"] == "ok" else 1
