"""`hamr-bench campaign --sim --out DIR`: the paper's whole test matrix on the simulated bench, one recording per
run."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from hamr_bench.commands.run import add_run_options


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "campaign", help="run the paper's whole test matrix on the simulated bench",
        description="All three actuators (actuator test) and all five designs (blocked-force, sag-sweep, "
        "free-displacement, static), one recording each in DIR.")
    parser.add_argument("--sim", action="store_true", required=True, help="use the simulated bench (required)")
    parser.add_argument("--out", type=Path, required=True, metavar="DIR")
    parser.add_argument("--jobs", type=int, default=None, help="parallel runs (default: number of cores)")
    parser.add_argument("--set", dest="set_options", action="append", default=[], metavar="NAME=VALUE",
                        help="override a parameter in every protocol that has it, e.g. --set drive.cycles=2")
    add_run_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hamr_bench.commands.run import recording_options
    from hamr_bench.config import parse_effects
    from hamr_bench.live.session import open_live_view
    from hamr_bench.protocols.campaign import campaign_runs, run_campaign

    live, camera_storage = recording_options(args)
    args.out.mkdir(parents=True, exist_ok=True)
    runs = campaign_runs(args.out, parse_effects(args.effects), args.seed, args.force, args.set_options,
                         camera_storage=camera_storage)
    start = time.perf_counter()
    with open_live_view(live) as view:
        if view is not None and args.jobs not in (None, 1):
            print("hamr-bench: campaign --live runs one run at a time (the view follows one run)", file=sys.stderr)
        results = run_campaign(runs, jobs=args.jobs, progress=not args.quiet, live=view)
    wall_s = time.perf_counter() - start
    failed = [r for r in results if r[1] != "success"]
    for name, status, reason in failed:
        print(f"hamr-bench: {name}: {status}: {reason}", file=sys.stderr)
    print(f"{args.out}: {len(results) - len(failed)}/{len(results)} runs succeeded in {wall_s:.1f} s")
    return 1 if failed else 0
