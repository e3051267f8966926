"""The `hamr-bench` command line: builds the parser from the modules in `hamr_bench.commands` and turns every
expected failure (`HamrBenchError`) into one line on stderr and a non-zero exit code. A command module that fails
to import is such a failure too (it names the module and why): a broken command must not silently vanish from
the command line."""

from __future__ import annotations

import argparse
import importlib
import sys

from hamr_bench import __version__
from hamr_bench.errors import HamrBenchError

# Order here is the order in `hamr-bench --help`.
COMMAND_MODULES = [
    "demo",
    "run",
    "campaign",
    "info",
    "recover",
    "model",
    "paper",
    "sim",
    "import_cmd",
    "fit",
    "report",
    "replay",
    "compare",
    "gap",
    "selfcheck",
]

EXIT_ERROR = 2
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hamr-bench",
        description="Run, simulate and analyse powertrain characterisation tests of miniature legged robots.",
    )
    parser.add_argument("--version", action="version", version=f"hamr-bench {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        module_name = f"hamr_bench.commands.{name}"
        try:
            module = importlib.import_module(module_name)
        except Exception as exc:  # any import failure: named in one line, never skipped
            why = " ".join(str(exc).split())  # one line, whatever the exception's message looks like
            raise HamrBenchError(f"command module {module_name} cannot be loaded: {type(exc).__name__}: {why}") \
                from exc
        module.register(subparsers)
    return parser


def main(argv: list[str] | None = None) -> int:
    try:
        parser = build_parser()
    except HamrBenchError as exc:
        print(f"hamr-bench: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return EXIT_ERROR
    try:
        return int(args.func(args) or 0)
    except HamrBenchError as exc:
        print(f"hamr-bench: error: {exc}", file=sys.stderr)
        return EXIT_ERROR
    except KeyboardInterrupt:
        print("hamr-bench: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
