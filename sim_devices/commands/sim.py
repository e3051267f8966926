"""`hamr-bench sim serve {smc100,loadstar}`: run one serial emulator on a pseudo-terminal with a real clock,
so a terminal program, a MATLAB script or the real driver can open it like a device. The pty path is the first
line of output; it serves until SIGINT/SIGTERM. Effects and faults are switched on by name."""

from __future__ import annotations

import argparse
import signal
import sys

import numpy as np

from hamr_bench.clock import RealClock
from hamr_bench.errors import ConfigError
from sim_devices.faults import parse_fault_spec
from sim_devices.loadstar_emulator import LoadstarEmulator, LoadstarParams
from sim_devices.pty_server import PtyServer
from sim_devices.serial_link import LineEndpoint
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol

# Effects each emulator models when served on its own: name -> meaning and unit of the strength.
SERVE_EFFECTS: dict[str, dict[str, str]] = {
    "smc100": {"stage_backlash": "backlash dead band on reversal, m"},
    "loadstar": {
        "sensor_drift": "random-walk drift of the zero, N/sqrt(s)",
        "measurement_noise": "reading noise, standard deviation in counts (default 1)",
    },
}


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("sim", help="simulated devices (serve an emulator on a pseudo-terminal)")
    sim_sub = parser.add_subparsers(dest="sim_command", metavar="SIM_COMMAND")
    serve = sim_sub.add_parser(
        "serve",
        help="serve an SMC100 or Loadstar emulator on a pty; prints its path first",
        description="Serve a serial device emulator on a pseudo-terminal. The first line of output is the "
        "port path; open it at any baud rate (the emulator models its own latency). Stop with Ctrl-C.",
    )
    serve.add_argument("device", choices=sorted(SERVE_EFFECTS), help="which emulator")
    serve.add_argument(
        "--effects",
        default="",
        metavar="NAME=STRENGTH,...",
        help="smc100: stage_backlash=<m>; loadstar: sensor_drift=<N/sqrt(s)>, measurement_noise=<counts>",
    )
    serve.add_argument(
        "--fault",
        action="append",
        default=[],
        metavar="NAME[@T_S]",
        help="inject a fault now or T_S seconds after start (repeatable): no_reply, garbage_bytes, "
        "dropped_bytes, disconnect; smc100: following_error, end_of_run; loadstar: overload",
    )
    serve.add_argument("--seed", type=int, default=0, help="random seed (noise, garbage bytes)")
    serve.add_argument("--address", type=int, default=1, help="smc100 controller address 1-31 (default 1)")
    serve.add_argument(
        "--command-set", choices=["di1000", "iload"], default="di1000", help="loadstar interface"
    )
    serve.add_argument(
        "--force-N", type=float, default=0.0, help="loadstar: constant true force on the sensor, N"
    )
    serve.set_defaults(func=run_serve)
    parser.set_defaults(func=lambda args: (parser.print_help(), 2)[1])


def parse_effects(text: str, device: str) -> dict[str, float]:
    """`a=1e-6,b=2` -> {'a': 1e-6, 'b': 2.0}, names checked against what `device` models."""
    effects: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, sep, value = item.partition("=")
        name = name.strip()
        if name not in SERVE_EFFECTS[device]:
            known = ", ".join(SERVE_EFFECTS[device])
            message = f"--effects: {name!r} is not modelled by the {device} emulator (known: {known})"
            raise ConfigError(message)
        try:
            strength = float(value) if sep else 1.0
        except ValueError as exc:
            raise ConfigError(f"--effects: strength of {name!r} must be a number, got {value!r}") from exc
        if not strength >= 0:
            raise ConfigError(f"--effects: strength of {name!r} must be >= 0, got {value!r}")
        effects[name] = strength
    return effects


def build_endpoint(args: argparse.Namespace) -> LineEndpoint:
    clock = RealClock()
    effects = parse_effects(args.effects, args.device)
    rng = np.random.default_rng(args.seed)
    endpoint: LineEndpoint
    if args.device == "smc100":
        if not 1 <= args.address <= 31:
            raise ConfigError(f"--address {args.address}: SMC100 addresses are 1..31")
        emulator = Smc100Emulator(
            clock, Smc100Params(address=args.address, backlash_m=effects.get("stage_backlash", 0.0))
        )
        endpoint = Smc100Protocol(emulator, rng=rng)
    else:
        drift = effects.get("sensor_drift", 0.0)
        params = LoadstarParams(
            command_set=args.command_set,
            drift="random_walk" if drift > 0 else "none",
            drift_strength=drift,
            noise_counts=effects.get("measurement_noise", 1.0),
        )
        force_N = float(args.force_N)
        endpoint = LoadstarEmulator(clock, lambda time_s: force_N, rng, params)
    for spec in args.fault:
        name, at_s = parse_fault_spec(spec)
        endpoint.faults.inject(name, None if at_s == float("-inf") else clock.now_s() + at_s)
    return endpoint


def run_serve(args: argparse.Namespace) -> int:
    endpoint = build_endpoint(args)
    server = PtyServer(endpoint)
    print(server.path, flush=True)
    print(
        f"hamr-bench: {args.device} emulator serving on {server.path}; Ctrl-C or SIGTERM to stop",
        file=sys.stderr,
        flush=True,
    )

    def _stop(signum: int, frame: object) -> None:
        server.stop()

    previous = {sig: signal.signal(sig, _stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        server.serve_forever()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        server.close()
    if server.disconnected:
        print("hamr-bench: emulator disconnected (fault); pty closed", file=sys.stderr)
    return 0
