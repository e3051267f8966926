"""Benchmark: the whole simulated campaign (`hamr-bench campaign --sim`): wall time, the simulated time it
covers, and the virtual-clock speed-up (simulated seconds per wall second).

    python3 -m benchmarks.bench_campaign [--jobs N] [--json]
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path


def run(jobs: int | None = None, set_options: list[str] | None = None) -> dict:
    from hamr_bench.protocols.campaign import campaign_runs, run_campaign
    from hamr_bench.recording import RecordingReader

    with tempfile.TemporaryDirectory() as tmp:
        runs = campaign_runs(Path(tmp), {}, 0, True, set_options or [])
        start = time.perf_counter()
        results = run_campaign(runs, jobs=jobs, progress=False)
        wall_s = time.perf_counter() - start
        simulated_s = 0.0
        for run_ in runs:
            events = RecordingReader(run_.request.out).events()
            simulated_s += events[-1].time_s - events[0].time_s
    failed = [r for r in results if r[1] != "success"]
    return {"runs": len(runs), "failed": len(failed), "wall_s": wall_s, "simulated_s": simulated_s,
            "speedup": simulated_s / wall_s}


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    jobs = int(argv[argv.index("--jobs") + 1]) if "--jobs" in argv else None
    result = run(jobs)
    if "--json" in argv:
        print(json.dumps(result))
    else:
        print(f"campaign: {result['runs']} runs ({result['failed']} failed) in {result['wall_s']:.1f} s wall, "
              f"{result['simulated_s']:.0f} s simulated: {result['speedup']:.0f}x real time")
    return 0


if __name__ == "__main__":
    sys.exit(main())
