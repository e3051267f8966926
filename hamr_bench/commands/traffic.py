"""`hamr-bench traffic export RUN.mcap --device stage --out FILE.json`: one serial device's conversation, recorded
with `--record-traffic`, as a byte-exact driver test file (the driver's calls, each with the bytes it wrote and the
replies it got). `tests/drivers/test_recorded_traffic.py` replays every file under `tests/drivers/traffic/` against
the driver and against the emulator; docs/hardware.md says how a lab with hardware contributes one. The exporter
lives in `drivers` and is found by name (backend `traffic-test-export`)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hamr_bench.errors import ConfigError
from hamr_bench.backends import traffic_test_export
from hamr_bench.recording.contract import TRAFFIC_PREFIX

# Which driver speaks on a traffic topic, from the device name the rig builder gives it.
_DRIVER_OF_DEVICE = {"stage": "smc100", "force_sensor": "loadstar"}


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("traffic", help="recorded serial traffic (turn it into driver tests)")
    sub = parser.add_subparsers(dest="traffic_command", metavar="TRAFFIC_COMMAND")
    export = sub.add_parser(
        "export",
        help="write one device's recorded conversation as a byte-exact driver test file",
        description=f"Read {TRAFFIC_PREFIX}DEVICE of a recording made with --record-traffic and write the driver "
        "calls it holds, each with its (sent, reply) exchanges, as JSON. tests/drivers/test_recorded_traffic.py "
        "replays every file in tests/drivers/traffic/ against the real driver and the emulator.",
    )
    export.add_argument("recording", type=Path, metavar="RUN.mcap")
    export.add_argument("--device", required=True, choices=sorted(_DRIVER_OF_DEVICE),
                        help="which serial device's traffic (stage: SMC100, force_sensor: Loadstar)")
    export.add_argument("--out", required=True, type=Path, metavar="FILE.json")
    export.set_defaults(func=run_export)
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])


def run_export(args: argparse.Namespace) -> int:
    from hamr_bench.recording import RecordingReader

    if not args.recording.exists():
        raise ConfigError(f"{args.recording}: no such recording")
    reader = RecordingReader(args.recording)
    topic = f"{TRAFFIC_PREFIX}{args.device}"
    if topic not in reader.topics():
        found = ", ".join(t for t in reader.topics() if t.startswith(TRAFFIC_PREFIX)) or "none"
        hint = f"record the run with --record-traffic; traffic topics: {found}"
        raise ConfigError(f"{args.recording}: no {topic} ({hint})")
    export = traffic_test_export()
    n_calls = export(reader.traffic(topic), _DRIVER_OF_DEVICE[args.device], args.device, args.recording.name,
                     args.out)
    print(f"{args.out}: {n_calls} driver calls from {topic} of {args.recording}")
    return 0
