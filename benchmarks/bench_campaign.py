"""Benchmark: the whole simulated campaign (`hamr-bench campaign --sim`): wall time, the simulated time it
covers, and the virtual-clock speed-up (simulated seconds per wall second).

    python3 -m benchmarks.bench_campaign [--jobs N] [--effects NAME=STRENGTH,...] [--json]

`--effects` switches the bench's effects on for every run (e.g. the realistic mix
`hysteresis=0.1,creep=0.015,field_dependent_d31=0.5,sensor_drift=2e-5,bias_error=3e-5`): the speed with the
effects' generators in the loop, not only the dynamics.
"""

from __future__ import annotations

import json
import os
import resource
import sys
import tempfile
import time
from pathlib import Path


def _cpu_s() -> float:
    """CPU seconds of this process and of its finished children (the campaign's pool workers)."""
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


def run(jobs: int | None = None, set_options: list[str] | None = None, out_dir: Path | None = None,
        effects: dict[str, float] | None = None, **subset: tuple) -> dict:
    """The campaign (all of it, or `designs=`, `layers=`, `protocols=` of `campaign_runs`) into `out_dir` (kept) or
    a temporary directory. CPU time counts the pool's worker processes once they have exited."""
    from hamr_bench.protocols.campaign import campaign_runs, run_campaign
    from hamr_bench.recording import RecordingReader

    with tempfile.TemporaryDirectory() as tmp:
        runs = campaign_runs(Path(out_dir or tmp), dict(effects or {}), 0, True, set_options or [], **subset)
        cpu0 = _cpu_s()
        start = time.perf_counter()
        results = run_campaign(runs, jobs=jobs, progress=False)
        wall_s = time.perf_counter() - start
        cpu_s = _cpu_s() - cpu0
        simulated_s = 0.0
        for run_ in runs:
            events = RecordingReader(run_.request.out).events()
            simulated_s += events[-1].time_s - events[0].time_s
    failed = [r for r in results if r[1] != "success"]
    return {"runs": len(runs), "failed": len(failed), "wall_s": wall_s, "cpu_s": cpu_s, "simulated_s": simulated_s,
            "speedup": simulated_s / wall_s, "speedup_per_cpu_s": simulated_s / cpu_s,
            "jobs": jobs or min(len(runs), os.cpu_count() or 1), "effects": dict(effects or {})}


def _effects(text: str) -> dict[str, float]:
    """NAME=STRENGTH,... as `hamr-bench run --effects` reads it; a malformed item is one clear line."""
    from hamr_bench.config import parse_effects
    from hamr_bench.errors import ConfigError

    try:
        return parse_effects(text)
    except ConfigError as exc:
        raise SystemExit(str(exc)) from None


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    jobs = int(argv[argv.index("--jobs") + 1]) if "--jobs" in argv else None
    effects = _effects(argv[argv.index("--effects") + 1]) if "--effects" in argv else {}
    result = run(jobs, effects=effects)
    if "--json" in argv:
        print(json.dumps(result))
    else:
        print(f"campaign: {result['runs']} runs ({result['failed']} failed) in {result['wall_s']:.1f} s wall, "
              f"{result['simulated_s']:.0f} s simulated: {result['speedup']:.0f}x real time"
              + (f" (effects {result['effects']})" if result["effects"] else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
