"""Gap-diagnosis figures: (1) the time of a full diagnosis of one campaign; (2) the blind self-check over N trials
(top-1 accuracy, false attributions on nulls, decoys unexplained, interval coverage, predicted vs realised
reduction). Usage:

    python3 -m benchmarks.bench_gap campaign DIR            # time `diagnose` on a campaign's recordings
    python3 -m benchmarks.bench_gap evaluations DIR         # ms per model evaluation, per candidate
    python3 -m benchmarks.bench_gap selfcheck [N] [SEED] [JOBS]
    python3 -m benchmarks.bench_gap design [N] [SEED]       # the bars' ceilings per data design (no simulation)
"""

from __future__ import annotations

import json
import sys
import time


def bench_campaign(directory: str) -> None:
    from analysis.gap.diagnose import diagnose
    from analysis.gap.features import load_gap_data

    t0 = time.perf_counter()
    data = load_gap_data([directory])
    t1 = time.perf_counter()
    result = diagnose(data)
    t2 = time.perf_counter()
    print(f"campaign {directory}: {len(data.runs)} runs, {len(data.rows)} rows")
    print(f"load {t1 - t0:.1f} s, diagnose {t2 - t1:.1f} s, total {t2 - t0:.1f} s; best = {result.best}")
    for w in result.waterfall:
        print(f"  {w.added or 'nominal'}: held-out RMS {w.heldout.rms:.2f} {list(w.heldout.ci95)}"
              + (f" (or {', '.join(w.ambiguous_with)})" if w.ambiguous_with else ""))
    for e in result.named:
        print(f"  {e.name}: {e.verdict}, strength {e.strength:.4g} {list(e.strength_ci95)}")


def bench_evaluations(directory: str, n: int = 60) -> None:
    """What one evaluation of the residual costs on a campaign (ms), the nominal model and each applicable
    candidate alone at a typical strength, over n parameter vectors that each move a fifth of the parameters
    (so the engines' caches miss as in a fit's first evaluations at a new point, not as in a Jacobian's columns).
    One process, one BLAS thread."""
    import numpy as np
    from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

    from analysis.gap.diagnose import applicable
    from analysis.gap.families import CANDIDATES, FAMILIES
    from analysis.gap.features import load_gap_data
    from analysis.gap.problem import Problem

    p = Problem(load_gap_data([directory]))
    start = p.initial_nuisances()
    print(f"campaign {directory}: {len(p.engines)} runs, {p.y.size} rows")
    with threadpool_limits(limits=1):
        for names in [()] + [(c,) for c in applicable(p, list(CANDIDATES))]:
            lay = p.layout(names)
            x0 = lay.vector(start)
            for c in names:
                if ("strength", c) in lay.index:
                    x0[lay.index[("strength", c)]] = FAMILIES[c].scale
            rng = np.random.default_rng(0)
            scale = lay.scales()
            lo, hi = lay.bounds()
            xs = [np.clip(x0 + rng.normal(0.0, 0.05, x0.size) * scale * (rng.random(x0.size) < 0.2), lo, hi)
                  for _ in range(n)]
            t0 = time.perf_counter()
            for x in xs:
                p.residual(lay, x)
            print(f"  {names[0] if names else 'nominal'}: {(time.perf_counter() - t0) / n * 1e3:.1f} ms per evaluation")


def bench_design(n: int, seed: int) -> None:
    """Of the self-check's N draws at SEED, how many hidden shifts and springs each data design can tell from
    fabrication scatter, and the top-1 and multi-effect figures no honest method can exceed there
    (`analysis.gap.design_study`)."""
    from analysis.gap.design_study import Design, design_shares

    designs = [Design((2,), k) for k in (3, 6, 12)] + [Design((1, 2, 3), k) for k in (3, 5, 10)]
    seeds = [seed * 100_000 + i for i in range(n)]
    print(f"{n} self-check draws, seed {seed} (the self-check builds 3 specimens of the 2-layer actuator)")
    print(f"{'design':34s} {'single: gain effects detectable':>32s} {'top-1 ceiling':>14s} "
          f"{'multi: gain effects detectable':>31s} {'named ceiling':>14s}")
    for r in design_shares(seeds, designs):
        print(f"{r.design.label:34s} {r.single_gain_detectable:>14d} of {r.single_gain:<3d} ({r.single} trials)"
              f" {r.single_ceiling:>13.1%} {r.multi_gain_detectable:>14d} of {r.multi_gain:<3d} "
              f"({r.multi_effects} effects) {r.multi_ceiling:>11.1%}")


def bench_selfcheck(n: int, seed: int, jobs: int) -> None:
    from analysis.gap.selfcheck import selfcheck

    t0 = time.perf_counter()
    out = selfcheck(trials=n, seed=seed, jobs=jobs, progress=True, raw_path=f"/tmp/bench_gap_raw_{n}_{seed}.json")
    wall = time.perf_counter() - t0
    per_trial = out.pop("per_trial")
    print(json.dumps(out, indent=1))
    print(f"wall {wall:.0f} s for {n} trials with {jobs} jobs")
    with open(f"/tmp/bench_gap_selfcheck_{n}_{seed}.json", "w") as fh:
        json.dump({"summary": out, "trials": per_trial}, fh, indent=1)


if __name__ == "__main__":
    args = sys.argv[1:]
    if args and args[0] == "campaign":
        bench_campaign(args[1])
    elif args and args[0] == "evaluations":
        bench_evaluations(args[1])
    elif args and args[0] == "design":
        bench_design(int(args[1]) if len(args) > 1 else 200, int(args[2]) if len(args) > 2 else 2056)
    else:
        n = int(args[1]) if len(args) > 1 else 100
        seed = int(args[2]) if len(args) > 2 else 1
        jobs = int(args[3]) if len(args) > 3 else 2
        bench_selfcheck(n, seed, jobs)
