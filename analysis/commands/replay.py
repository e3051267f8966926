"""`hamr-bench replay RUN.mcap --out TWIN.mcap`: re-execute a recording's commands (stage set-points, voltage
ramps, drive waveforms, at their recorded times) on the simulated bench through the real drivers and emulators,
recording a twin with the same steps and timeline (docs/replay.md)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from hamr_bench.commands.run import add_recording_options, recording_options


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "replay", help="re-drive a recording through the simulated bench (a twin to compare with)",
        description="Read the commands of RUN.mcap from its command streams and events and re-execute them on "
        "the simulated bench, writing TWIN.mcap. Seed and effects default to the source's when it is simulated.")
    parser.add_argument("recording", type=Path, metavar="RUN.mcap")
    parser.add_argument("--out", type=Path, required=True, metavar="TWIN.mcap")
    parser.add_argument("--params", type=Path, metavar="FIT.json",
                        help="model parameters from `hamr-bench fit --json` (default: the bench's nominal ones)")
    parser.add_argument("--effects", default=None, metavar="NAME=STRENGTH,...",
                        help="realistic-bench effects (default: the source's if it is simulated, else none)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (default: the source's, else 0)")
    parser.add_argument("--rig", type=Path, metavar="RIG.toml", help="a simulated rig file (default rigs/sim.toml)")
    parser.add_argument("--record-traffic", action="store_true", help="record serial traffic in the twin")
    parser.add_argument("--serve-traffic", action="store_true",
                        help="serve the stage and force sensor from RUN.mcap's recorded serial traffic (a run made "
                        "with --record-traffic) instead of the emulators: tests the drivers against what the "
                        "devices said")
    parser.add_argument("--force", action="store_true", help="overwrite TWIN.mcap if it exists")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_recording_options(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from analysis.replay import replay_recording
    from hamr_bench.config import parse_effects
    from hamr_bench.live.session import open_live_view

    effects = parse_effects(args.effects) if args.effects is not None else None
    live, camera_storage = recording_options(args)
    with open_live_view(live) as view:
        result, source = replay_recording(
            args.recording, args.out, params_path=args.params, effects=effects, seed=args.seed, rig_path=args.rig,
            overwrite=args.force, quiet=args.quiet, record_traffic=args.record_traffic,
            serve_traffic=args.serve_traffic, camera_storage=camera_storage, live=view)
    if result.ok:
        if not args.quiet:
            print(f"{args.out}: replay of {args.recording} ({source.protocol}, {source.steps} steps, "
                  f"{source.duration_s:.1f} s recorded, source ended {source.exit_status})")
        return 0
    print(f"hamr-bench: replay {result.exit_status}: {result.reason} (twin closed: {args.out})", file=sys.stderr)
    return 1
