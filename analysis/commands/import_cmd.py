"""`hamr-bench import points|trace FILE.csv --out RUN.mcap`: turn a CSV table or time series into a recording that
every later command reads like a recorded run (formats and rules: docs/log-format.md, "Importing CSV
measurements")."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("import", help="import CSV measurements (points or a trace) as a recording")
    sub = parser.add_subparsers(dest="import_command", metavar="FORMAT")

    p = sub.add_parser("points", help="one row per measurement: protocol, design, layers, voltage_V, sag_m, "
                                      "repetition, force_N, displacement_m")
    p.add_argument("csv", type=Path)
    p.add_argument("--out", type=Path, required=True, help="recording to write (RUN.mcap)")
    p.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    _common(p)
    p.set_defaults(func=run_points)

    t = sub.add_parser("trace", help="a time series: time_s, voltage_V, stage_position_m, force_N, displacement_m")
    t.add_argument("csv", type=Path)
    t.add_argument("--protocol", required=True,
                   choices=("actuator", "blocked-force", "sag-sweep", "free-displacement", "static"))
    t.add_argument("--design", type=int, choices=(1, 2, 3, 4, 5))
    t.add_argument("--layers", type=int, choices=(1, 2, 3), default=2)
    t.add_argument("--zero-sag", type=float, default=None, metavar="STAGE_M",
                   help="stage position of zero sag (default: the first step's position)")
    t.add_argument("--out", type=Path, required=True, help="recording to write (RUN.mcap)")
    t.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    _common(t)
    t.set_defaults(func=run_trace)
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])


def _common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--session", metavar="NAME",
                   help="the session (one specimen mounted once) these rows belong to, where the CSV has no "
                        "session column: files of one specimen and session share their setup's nuisances")
    p.add_argument("--delimiter", choices=(",", ";", "tab", "|"),
                   help="the CSV's delimiter (default: sniffed from the header; with ';', tab or '|' a decimal "
                        "comma is accepted)")


def run_points(args: argparse.Namespace) -> int:
    from analysis.importer import import_points

    n = import_points(args.csv, args.out, overwrite=args.force, session=args.session, delimiter=args.delimiter)
    print(f"{args.out}: {n} measurement steps imported from {args.csv}")
    return 0


def run_trace(args: argparse.Namespace) -> int:
    from analysis.importer import import_trace

    n = import_trace(args.csv, args.out, args.protocol, args.design, args.layers, zero_sag_m=args.zero_sag,
                     overwrite=args.force, session=args.session, delimiter=args.delimiter)
    print(f"{args.out}: {n} steps of {args.protocol} imported from {args.csv}")
    return 0
