"""How the unpublished lift-transmission geometry was chosen for each kappa reading (run offline; the results are
frozen in designs.GEOMETRIES).

Maximises the worst signed margin over the fitted transmission claims (claims.transmission_margins: zero-sag
thresholds, sag sweep reaching 5.3 mN, design-4 force rising with sag, free-displacement order, both static sags)
over (crank r, coupler l, offset e, fabricated crank angle theta_fab, leg length L, leg angle alpha_0) inside
physically plausible bounds (PC-MEMS link scale, HAMR leg scale). The design-3 "falls with sag" claim is NOT in
the objective (it stays a prediction). Degenerate optima are rejected (`plausible`): the leg more than 70 degrees
from horizontal at any design's neutral, or a design whose 250 V free stroke parks the linkage at its dead point or
strokes less than 0.1 mm.

Two stages:
1. global: differential evolution (scipy) on the nominal worst margin, then Nelder-Mead from its best point
   (--method de), or Sobol samples and Nelder-Mead from the best few (--method multistart);
2. robust (--robust): Nelder-Mead on the worst margin over the geometry and its twelve one-at-a-time 1 %
   perturbations (robustness.one_at_a_time), started from stage 1's best. This trades nominal margin for margin
   that survives fabrication tolerance.

    python3 -m hamr_bench.model.geometry_search --kappa-units mixed [--method de|multistart] [--seed 1]
        [--maxiter 60] [--popsize 12] [--random 4096] [--starts 8] [--robust] [--no-buckling]

Prints the evaluations and wall time of each stage and the rounded geometry (1 um, 1 mrad) with its margins.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass

import numpy as np

from hamr_bench.errors import ModelError
from hamr_bench.model.designs import KAPPA_READINGS
from hamr_bench.model.robustness import GEOMETRY_KEYS, one_at_a_time, worst_margin
from hamr_bench.model.transmission import SliderCrankGeometry

BOUNDS = {  # name: (low, high), SI
    "crank_m": (0.3e-3, 1.2e-3),
    "coupler_m": (0.4e-3, 3.0e-3),
    "offset_m": (-1.0e-3, 1.0e-3),
    "theta_fab_rad": (-np.pi, np.pi),
    "leg_length_m": (4e-3, 12e-3),
    "leg_angle0_rad": (-0.9, 0.9),   # leg inclined up to ~50 deg from horizontal at fabrication
}
KEYS = list(GEOMETRY_KEYS)
assert list(BOUNDS) == KEYS
MAX_LEG_ANGLE_RAD = np.radians(70.0)   # beyond this the foot moves mostly sideways: not a lift mechanism
MIN_STROKE_M = 0.1e-3                  # every design visibly strokes in Fig. 9
_BAD, _IMPLAUSIBLE = -10.0, -5.0


def geometry_of(x: np.ndarray) -> SliderCrankGeometry:
    return SliderCrankGeometry(**dict(zip(KEYS, map(float, x))))


def score(x: np.ndarray, kappa_units: str, **design_changes) -> float:
    """Worst fitted-claim margin of the geometry x (negative sentinels outside the bounds or if implausible)."""
    from hamr_bench.model.claims import powertrains

    for k, v in zip(KEYS, x):
        lo, hi = BOUNDS[k]
        if not lo <= v <= hi:
            return _BAD
    try:
        g = geometry_of(x)
        with np.errstate(all="ignore"):
            if not plausible(powertrains(g, kappa_units, **design_changes)):
                return _IMPLAUSIBLE
    except (ModelError, FloatingPointError, ValueError):
        return _BAD
    return worst_margin(g, kappa_units, **design_changes)[0]


def robust_score(x: np.ndarray, kappa_units: str, **design_changes) -> float:
    """min(nominal margin, margin after each one-at-a-time 1 % perturbation)."""
    nominal = score(x, kappa_units, **design_changes)
    if nominal <= _IMPLAUSIBLE:
        return nominal
    return min(nominal, one_at_a_time(geometry_of(x), kappa_units, **design_changes).worst)


def plausible(pts) -> bool:
    """Reject degenerate optima: a neutral with the leg nearly vertical, or a design parked at a dead point."""
    for p in pts.values():
        g = p.geometry
        if abs(g.leg_angle0_rad + p.theta_neutral_rad - g.theta_fab_rad) > MAX_LEG_ANGLE_RAD:
            return False
        u = p.free_actuator_deflection_m(250.0, 250.0)
        th = p._solve(np.atleast_1d(u), np.zeros(1), p.theta_neutral_rad)[0]
        if not np.isfinite(th) or th >= p._grid[-2]:
            return False          # no interior free equilibrium: the drive parks the linkage at its dead point
        if -float(p.foot_height_m(th)) < MIN_STROKE_M:
            return False
    return True


def rounded(x: np.ndarray) -> np.ndarray:
    """Lengths to 1 um, angles to 1 mrad (what designs.GEOMETRIES stores)."""
    return np.array([round(v, 6) if k.endswith("_m") else round(v, 3) for k, v in zip(KEYS, x)])


@dataclass
class Stage:
    name: str
    evaluations: int
    seconds: float
    best: float
    x: np.ndarray


def _counted(f):
    calls = [0]

    def g(z):
        calls[0] += 1
        return f(z)
    return g, calls


def global_stage(kappa_units: str, seed: int, maxiter: int, popsize: int, **design_changes) -> Stage:
    from scipy.optimize import differential_evolution, minimize

    f, calls = _counted(lambda z: -score(z, kappa_units, **design_changes))
    t0 = time.perf_counter()
    res = differential_evolution(f, [BOUNDS[k] for k in KEYS], seed=seed, maxiter=maxiter, popsize=popsize,
                                 polish=False, tol=0.0, mutation=(0.5, 1.0), recombination=0.7, init="sobol")
    nm = minimize(f, res.x, method="Nelder-Mead", options=dict(maxiter=800, xatol=1e-7, fatol=1e-5))
    x = nm.x if nm.fun < res.fun else res.x
    return Stage("differential evolution + Nelder-Mead", calls[0], time.perf_counter() - t0, -min(nm.fun, res.fun), x)


def multistart_stage(kappa_units: str, seed: int, n_random: int, n_starts: int, **design_changes) -> Stage:
    """Sobol samples over the bounds, then Nelder-Mead from the best `n_starts` (the project's first method,
    scaled up)."""
    from scipy.optimize import minimize
    from scipy.stats import qmc

    f, calls = _counted(lambda z: -score(z, kappa_units, **design_changes))
    t0 = time.perf_counter()
    lo = np.array([BOUNDS[k][0] for k in KEYS])
    hi = np.array([BOUNDS[k][1] for k in KEYS])
    cands = qmc.scale(qmc.Sobol(len(KEYS), seed=seed).random(n_random), lo, hi)
    scores = np.array([f(c) for c in cands])
    best = (np.inf, cands[0])
    for i in np.argsort(scores)[:n_starts]:
        res = minimize(f, cands[i], method="Nelder-Mead", options=dict(maxiter=800, xatol=1e-7, fatol=1e-5))
        print(f"  start {-scores[i]:+.4f} -> {-res.fun:+.4f}", flush=True)
        if res.fun < best[0]:
            best = (res.fun, res.x)
    return Stage(f"{n_random} Sobol samples + Nelder-Mead from the best {n_starts}", calls[0],
                 time.perf_counter() - t0, -best[0], best[1])


def robust_stage(kappa_units: str, x0: np.ndarray, maxiter: int, **design_changes) -> Stage:
    from scipy.optimize import minimize

    f, calls = _counted(lambda z: -robust_score(z, kappa_units, **design_changes))
    t0 = time.perf_counter()
    steps = 0.05 * np.array([BOUNDS[k][1] - BOUNDS[k][0] for k in KEYS])
    simplex = np.vstack([x0] + [x0 + np.eye(len(KEYS))[i] * steps[i] for i in range(len(KEYS))])
    nm = minimize(f, x0, method="Nelder-Mead",
                  options=dict(maxiter=maxiter, xatol=1e-7, fatol=1e-5, initial_simplex=simplex))
    return Stage("robust Nelder-Mead (1 % one-at-a-time)", calls[0] * 13, time.perf_counter() - t0, -nm.fun, nm.x)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python3 -m hamr_bench.model.geometry_search", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--kappa-units", choices=tuple(KAPPA_READINGS), required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--method", choices=("de", "multistart"), default="de")
    ap.add_argument("--random", type=int, default=4096, help="multistart: Sobol samples")
    ap.add_argument("--starts", type=int, default=8, help="multistart: Nelder-Mead starts")
    ap.add_argument("--maxiter", type=int, default=60, help="differential-evolution generations")
    ap.add_argument("--popsize", type=int, default=12, help="population = popsize x 6 parameters")
    ap.add_argument("--robust", action="store_true", help="second stage: maximise the 1 %-perturbed worst margin")
    ap.add_argument("--robust-maxiter", type=int, default=400)
    ap.add_argument("--no-buckling", action="store_true", help="coupler strips never buckle (rigid in series)")
    args = ap.parse_args(argv)
    changes = {"coupler_buckling": False} if args.no_buckling else {}
    if args.method == "de":
        stage = global_stage(args.kappa_units, args.seed, args.maxiter, args.popsize, **changes)
    else:
        stage = multistart_stage(args.kappa_units, args.seed, args.random, args.starts, **changes)
    stages = [stage]
    if args.robust:
        stages.append(robust_stage(args.kappa_units, stage.x, args.robust_maxiter, **changes))
    for s in stages:
        print(f"{s.name}: {s.evaluations} model evaluations, {s.seconds:.0f} s, best {s.best:+.4f}", flush=True)
    x = rounded(stages[-1].x)
    g = geometry_of(x)
    oat = one_at_a_time(g, args.kappa_units, **changes)
    print(f"rounded: {dict(zip(KEYS, x.tolist()))}")
    print(f"worst margin {worst_margin(g, args.kappa_units, **changes)}; after any 1 % change {oat.worst:+.4f} "
          f"({oat.where})")


if __name__ == "__main__":
    main()
