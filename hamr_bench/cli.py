"""The `hamr-bench` command line: builds the parser from the command modules declared under the entry-point group
`hamr_bench.commands` and turns every expected failure (`HamrBenchError`) into one line on stderr and a non-zero
exit code.

A command module lives in the layer it uses (`hamr_bench/commands/` for the ones that need only `hamr_bench`,
`analysis/commands/` for analysis, `sim_devices/commands/` for the emulators), so `hamr_bench` never imports the
packages above it; the command line finds them by name, as `hamr_bench.backends` finds the backends. Each entry
point names a `register(subparsers)` function; the commands appear in `--help` in the order pyproject.toml declares
them. A declared module that fails to import is such a failure too (it names the module and why): a broken command
must not silently vanish from the command line.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

from hamr_bench import __version__, entry_points
from hamr_bench.errors import HamrBenchError

COMMAND_GROUP = "hamr_bench.commands"

EXIT_ERROR = 2
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hamr-bench",
        description="Run, simulate and analyse powertrain characterisation tests of miniature legged robots.",
    )
    parser.add_argument("--version", action="version", version=f"hamr-bench {__version__}")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, value in declared_commands().items():
        register_command(subparsers, name, value)
    return parser


def declared_commands() -> dict[str, str]:
    """name -> "module:register" of every declared command module, in `--help` order."""
    return entry_points.declared(COMMAND_GROUP)


def register_command(subparsers: Any, name: str, value: str) -> None:
    """Import one declared command module and let it add its parser; any failure is one `HamrBenchError` line."""
    try:
        register = entry_points.resolve(value)
    except Exception as exc:  # any import failure: named in one line, never skipped
        why = " ".join(str(exc).split())  # one line, whatever the exception's message looks like
        raise HamrBenchError(f"command {name!r} ({value}) cannot be loaded: {type(exc).__name__}: {why}") from exc
    if not callable(register):
        raise HamrBenchError(f"command {name!r} ({value}) is not a register(subparsers) function")
    register(subparsers)


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
