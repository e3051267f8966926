"""`hamr-bench demo`: a tour on the simulated bench that runs every analysis step that exists so far and ends with
where to look at the results."""

from __future__ import annotations

import argparse
import importlib
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("demo", help="run a simulated campaign and the analysis steps, end to end")
    parser.add_argument("--out", type=Path, default=Path("demo-out"), help="output folder (default: demo-out)")
    parser.set_defaults(func=run)


def _available(module_name: str) -> bool:
    try:
        importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name == module_name:
            return False
        raise
    return True


def run(args: argparse.Namespace) -> int:
    print("hamr-bench demo")
    steps = [("paper reproduction", "hamr_bench.commands.paper")]
    for title, module_name in steps:
        if not _available(module_name):
            print(f"- {title}: not built yet")
    return 0
