"""Benchmark: 10,000 (voltage, sag) conditions of the leg model, and 10,000 free/static solves. Prints the figures.

    python3 -m benchmarks.bench_model [--json]
"""

from __future__ import annotations

import json
import sys
import time

import numpy as np


def _best_of(fn, repeats: int = 7) -> float:
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def run() -> dict:
    from hamr_bench.model import powertrain

    p = powertrain(4)
    rng = np.random.default_rng(0)
    n = 10_000
    v = rng.uniform(0.0, 250.0, n)
    s = rng.uniform(0.0, 3e-3, n)
    f = rng.uniform(0.0, 2.65e-3, n)
    out = {
        "conditions": n,
        "blocked_force_ms": 1e3 * _best_of(lambda: p.blocked_force_N(v, s)),
        "foot_force_ms": 1e3 * _best_of(lambda: p.foot_force_N(v, 0.5 * v, s)),
        "free_foot_height_ms": 1e3 * _best_of(lambda: p.free_foot_height_m(v, v), 3),
        "static_displacement_ms": 1e3 * _best_of(lambda: p.static_displacement_m(f), 3),
        "construct_powertrain_ms": 1e3 * _best_of(lambda: powertrain(4), 3),
    }
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    r = run()
    if "--json" in argv:
        print(json.dumps(r))
    else:
        for k, v in r.items():
            print(f"{k:28s} {v:.3f}" if isinstance(v, float) else f"{k:28s} {v}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
