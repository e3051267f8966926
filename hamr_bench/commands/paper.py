"""`hamr-bench paper [--json | --markdown | --readings] [--kappa-units R] [--samples N] [--seed S]`: the seed
paper's claims next to the model's values with their Monte-Carlo bands, computed now (progress on stderr when it
is a terminal)."""

from __future__ import annotations

import argparse
import json
import sys


def register(subparsers: argparse._SubParsersAction) -> None:
    from hamr_bench.model.designs import DEFAULT_KAPPA_UNITS, KAPPA_READINGS
    from hamr_bench.model.reproduction import DEFAULT_SAMPLES

    parser = subparsers.add_parser("paper",
                                   help="reproduction table of the seed paper's claims (computed by the model)")
    fmt = parser.add_mutually_exclusive_group()
    fmt.add_argument("--json", action="store_true", help="JSON: the claims with kind, margin, band, reproduced")
    fmt.add_argument("--markdown", action="store_true", help="Markdown (docs/paper-reproduction.md)")
    fmt.add_argument("--readings", action="store_true",
                     help="Markdown tables comparing the kappa-unit readings (docs/model.md)")
    parser.add_argument("--kappa-units", choices=tuple(KAPPA_READINGS), default=DEFAULT_KAPPA_UNITS,
                        help=f"reading of Table III's kappa units (default {DEFAULT_KAPPA_UNITS})")
    parser.add_argument("--samples", type=int, default=DEFAULT_SAMPLES,
                        help=f"Monte-Carlo draws for the bands (default {DEFAULT_SAMPLES})")
    parser.add_argument("--seed", type=int, default=0, help="Monte-Carlo seed (default 0)")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hamr_bench.errors import ConfigError
    from hamr_bench.model.readings import compare_readings, readings_markdown
    from hamr_bench.model.reproduction import as_json, as_markdown, as_text, reproduce

    if args.samples < 1:
        raise ConfigError(f"--samples must be at least 1, got {args.samples}")
    def show(message: str) -> None:
        print(f"\r\033[K{message} ...", end="", file=sys.stderr, flush=True)

    progress = show if sys.stderr.isatty() else None

    if args.readings:
        print(readings_markdown(compare_readings(seed=args.seed, progress=progress)), end="")
    else:
        r = reproduce(args.kappa_units, args.samples, args.seed, progress)
        if progress:
            print("\r\033[K", end="", file=sys.stderr, flush=True)
        if args.json:
            print(json.dumps(as_json(r), indent=2))
        elif args.markdown:
            print(as_markdown(r), end="")
        else:
            print(as_text(r), end="")
    return 0
