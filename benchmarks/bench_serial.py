"""Benchmark: SMC100 `1TP?` round trips over a pseudo-terminal (emulator on a real clock, raw os.read/os.write
and through the real driver) and in-process on a virtual clock (wall time per exchange). Prints the figures.

    python3 -m benchmarks.bench_serial [--json]

The pty figure includes the emulator's modelled reply latency (reported alongside), so the transport's own
cost is the difference."""

from __future__ import annotations

import json
import os
import select
import sys
import time
import tty

import numpy as np


def _pty_raw_round_trips_s(path: str, n: int) -> np.ndarray:
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    times = []
    try:
        for _ in range(n):
            t0 = time.perf_counter()
            os.write(fd, b"1TP?\r\n")
            data = b""
            while not data.endswith(b"\r\n"):
                select.select([fd], [], [], 1.0)
                data += os.read(fd, 64)
            times.append(time.perf_counter() - t0)
    finally:
        os.close(fd)
    return np.array(times)


def run(n: int = 200) -> dict:
    from drivers.newport_smc100 import NewportSMC100
    from hamr_bench.clock import RealClock, VirtualClock
    from sim_devices.pty_server import PtyServer
    from sim_devices.serial_link import register_endpoint, unregister_endpoint
    from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
    from sim_devices.smc100_protocol import Smc100Protocol

    params = Smc100Params()
    reply_bytes = len(b"1TP0\r\n")
    modelled_s = params.reply_latency_s + reply_bytes * 10 / params.baudrate
    out: dict = {"exchanges": n, "modelled_reply_latency_ms": 1e3 * modelled_s}

    clock = RealClock()
    with PtyServer(Smc100Protocol(Smc100Emulator(clock, params))) as server:
        raw = _pty_raw_round_trips_s(server.path, n)
        stage = NewportSMC100(server.path, clock)
        via_driver = []
        for _ in range(n):
            t0 = time.perf_counter()
            stage.position_m()
            via_driver.append(time.perf_counter() - t0)
        stage.close()
    out["pty_raw_median_ms"] = 1e3 * float(np.median(raw))
    out["pty_raw_p95_ms"] = 1e3 * float(np.percentile(raw, 95))
    out["pty_driver_median_ms"] = 1e3 * float(np.median(via_driver))
    out["pty_transport_overhead_median_ms"] = out["pty_raw_median_ms"] - out["modelled_reply_latency_ms"]

    vclock = VirtualClock()
    url = register_endpoint("bench-smc100", Smc100Protocol(Smc100Emulator(vclock, params)), replace=True)
    stage = NewportSMC100(url, vclock)
    m = 20 * n
    t0 = time.perf_counter()
    for _ in range(m):
        stage.position_m()
    wall_s = time.perf_counter() - t0
    stage.close()
    unregister_endpoint("bench-smc100")
    out["inprocess_wall_us_per_exchange"] = 1e6 * wall_s / m
    out["inprocess_virtual_ms_per_exchange"] = 1e3 * vclock.now_s() / m
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    result = run()
    if "--json" in argv:
        print(json.dumps(result))
    else:
        for key, value in result.items():
            print(f"{key:36s} {value:.3f}" if isinstance(value, float) else f"{key:36s} {value}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
