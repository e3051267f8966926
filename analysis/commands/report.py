"""`hamr-bench report RECORDINGS... --out DIR`: fit, draw the paper's Figs. 7-10 from the data and the fitted model,
and write them with a Markdown summary (analysis/report.py)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("report", help="figures (paper Figs. 7-10) and a Markdown summary of recordings")
    parser.add_argument("recordings", type=Path, nargs="+", help="MCAP recordings (or directories of them)")
    parser.add_argument("--out", type=Path, required=True, help="directory for the PNGs and report.md")
    parser.add_argument("--method", choices=("nelder-mead", "least-squares"), default="least-squares")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from analysis.report import write_report

    path = write_report(args.recordings, args.out, method=args.method)
    print(f"wrote {path}")
    return 0
