"""`hamr-bench run PROTOCOL`: one characterisation test on a rig (a rig file, or the simulated bench with
`--sim`), recorded to one MCAP file."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

EXIT_RUN_FAILED = 1


def add_run_options(parser: argparse.ArgumentParser) -> None:
    """Options shared by `run` and `campaign`."""
    parser.add_argument("--effects", default="", metavar="NAME=STRENGTH,...",
                        help="realistic-bench effects on the simulated bench, e.g. hysteresis=0.15,creep=0.01")
    parser.add_argument("--seed", type=int, default=0, help="random seed of the simulated bench (default 0)")
    parser.add_argument("--force", action="store_true", help="overwrite existing output files")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")
    add_recording_options(parser)


def add_recording_options(parser: argparse.ArgumentParser) -> None:
    """Options shared by everything that records a run (`run`, `campaign`, `replay`): live view, camera storage."""
    parser.add_argument("--live", metavar="[HOST:]PORT", default=None,
                        help="serve every stream live over Foxglove's WebSocket protocol while recording "
                        "(localhost unless HOST is given; PORT 0 picks a free one); prints the URL and the control "
                        "token (docs/live-view.md)")
    parser.add_argument("--camera-storage", default="roi", metavar="MODE",
                        help="how camera frames are kept: roi (default: a 64 px region around the marker every "
                        "frame + a full frame a second; roi:SIZE_PX[:INTERVAL_S]), full (every frame, raw), png "
                        "(every frame, lossless compressed), none (docs/log-format.md)")


def recording_options(args: argparse.Namespace):  # -> tuple[LiveOptions | None, CameraStorage]
    """The parsed `--live` and `--camera-storage` (a bad value is one ConfigError line)."""
    from hamr_bench.live.options import LiveOptions
    from hamr_bench.recording.camera_storage import CameraStorage

    live = LiveOptions.parse(args.live) if args.live is not None else None
    return live, CameraStorage.parse(args.camera_storage)


def register(subparsers: argparse._SubParsersAction) -> None:
    from hamr_bench.protocols import PROTOCOLS  # light: plans only

    parser = subparsers.add_parser(
        "run", help="run one characterisation test and record it",
        description="Run one test protocol on a rig and record it to RUN.mcap. Protocols: "
        + "; ".join(f"{name}: {m.SUMMARY}" for name, m in PROTOCOLS.items()))
    parser.add_argument("protocol", choices=list(PROTOCOLS), metavar="PROTOCOL")
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--rig", type=Path, metavar="RIG.toml", help="rig file (see rigs/ and docs/rig-file.md)")
    where.add_argument("--sim", action="store_true", help="use the simulated bench")
    parser.add_argument("--design", type=int, default=4, choices=range(1, 6), metavar="{1..5}",
                        help="transmission design (paper Table II; default 4)")
    parser.add_argument("--layers", type=int, default=2, choices=(1, 2, 3),
                        help="actuator central carbon-fibre layers (default 2)")
    parser.add_argument("--protocol-file", type=Path, metavar="FILE.toml", help="protocol parameters file")
    parser.add_argument("--set", dest="set_options", action="append", default=[], metavar="NAME=VALUE",
                        help="override a protocol parameter, e.g. --set voltages_V=100,200 --set drive.cycles=5")
    parser.add_argument("--record-traffic", action="store_true",
                        help="also record the raw bytes exchanged with each serial device")
    parser.add_argument("--fault", dest="faults", action="append", default=[], metavar="DEVICE:FAULT[@T]",
                        help="simulated bench only: inject a fault at T s of simulated time, e.g. "
                        "stage:following_error@20 (devices: stage, force_sensor, daq, camera)")
    parser.add_argument("--out", type=Path, required=True, metavar="RUN.mcap")
    parser.add_argument("--specimen", default="", metavar="LABEL",
                        help="label of the mounted specimen, written into every step (`gap` and `fit` treat "
                        "recordings with different labels as different specimens; unlabelled ones as one)")
    add_run_options(parser)
    parser.set_defaults(func=run)


def specimen_label(text: str) -> str:
    """`--specimen`: any label without line breaks (it is one field of every step event)."""
    from hamr_bench.errors import ConfigError

    label = text.strip()
    if any(c in label for c in "\r\n\t"):
        raise ConfigError(f"--specimen: expected a one-line label, got {text!r}")
    return label


def run(args: argparse.Namespace) -> int:
    from hamr_bench.config import parse_effects
    from hamr_bench.live.session import open_live_view
    from hamr_bench.protocols.session import RunRequest, run_protocol

    live, camera_storage = recording_options(args)
    with open_live_view(live) as view:
        result = run_protocol(RunRequest(
            protocol=args.protocol, out=args.out, rig_path=None if args.sim else args.rig, design=args.design,
            layers=args.layers, effects=parse_effects(args.effects), seed=args.seed,
            protocol_file=args.protocol_file, set_options=args.set_options, overwrite=args.force,
            quiet=args.quiet, record_traffic=args.record_traffic, faults=args.faults,
            camera_storage=camera_storage, live=view, specimen=specimen_label(args.specimen)))
    if result.ok:
        if not args.quiet:
            print(f"{args.out}: {args.protocol} completed, {result.steps_done} steps")
        return 0
    print(f"hamr-bench: run {result.exit_status}: {result.reason} (recording closed: {args.out})", file=sys.stderr)
    return EXIT_RUN_FAILED
