"""Scale-out of batch analysis (analysis/parallel.py): the same batch over many recordings in one process, on the
local process pool, and on a local Dask cluster (when the optional extra is installed); the figure is the speed-up.

The batch item is what `fit` and `gap` do first to every recording: read it (CRC-validated) and turn its streams into
per-step observations (`analysis.dataset.load_run`); each worker returns only a small summary so that the figure
measures the work, not the pickling of results. Dask's cluster start-up is timed separately and left out of its
figure (a cluster is normally running already).

Run: `python -m benchmarks.bench_scaleout DIR_OF_RECORDINGS [--workers N] [--json]`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from analysis.parallel import default_jobs, parallel_map

T = TypeVar("T")


def observations_of(path: str) -> tuple[str, int]:
    from analysis.dataset import load_run

    run = load_run(path)
    return Path(path).name, len(run.observations)


def _timed(fn: Callable[[], T], repeat: int) -> tuple[float, T]:
    if repeat < 1:
        raise ValueError(f"repeat {repeat}: at least one run")
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def run(paths: list[Path], workers: int | None = None, repeat: int = 1) -> dict:
    items = [str(p) for p in paths]
    workers = workers or default_jobs(len(items))
    serial_s, serial = _timed(lambda: parallel_map(observations_of, items, jobs=1), repeat)
    local_s, local = _timed(lambda: parallel_map(observations_of, items, jobs=workers), repeat)
    assert local == serial, "the pool gave other results than the serial run"
    out: dict[str, Any] = {"items": len(items), "workers": workers, "serial_s": serial_s, "local_s": local_s,
           "observations": sum(n for _, n in serial)}
    try:
        import distributed
    except ImportError:
        out["dask_s"] = None
        out["dask_note"] = "Dask not installed (optional extra: pip install 'hamr-bench[dask]')"
        return out
    t0 = time.perf_counter()
    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=None, silence_logs=40)
    client = distributed.Client(cluster)
    out["dask_start_s"] = time.perf_counter() - t0
    try:
        dask_s, dask = _timed(lambda: parallel_map(observations_of, items, scheduler=client), repeat)
        assert dask == serial, "Dask gave other results than the serial run"
        out["dask_s"] = dask_s
    finally:
        client.close()
        cluster.close()
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("directory", type=Path)
    parser.add_argument("--workers", type=int, default=None)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    r = run(sorted(args.directory.glob("*.mcap")), args.workers)
    if args.json:
        print(json.dumps(r, indent=1))
        return 0
    print(f"{r['items']} recordings: serial {r['serial_s']:.2f} s, local pool ({r['workers']} workers) "
          f"{r['local_s']:.2f} s = {r['serial_s'] / r['local_s']:.2f}x", end="")
    if r.get("dask_s"):
        print(f", Dask {r['dask_s']:.2f} s = {r['serial_s'] / r['dask_s']:.2f}x (cluster start {r['dask_start_s']:.1f}"
              f" s, not counted)")
    else:
        print(f"; {r.get('dask_note', '')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
