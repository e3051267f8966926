"""How the unpublished lift-transmission geometry was chosen (run once; the result is frozen in designs.GEOMETRY).

Maximises the worst signed margin over the transmission claims (claims.transmission_margins: zero-sag thresholds,
sag sweep reaching 5.3 mN, design-4 force rising with sag, free-displacement order, both static sags) over
(crank r, coupler l, offset e, fabricated crank angle theta_fab, leg length L, leg angle alpha_0) inside
physically plausible bounds (PC-MEMS link scale, HAMR leg scale). Random search, then Nelder-Mead from the best.
The design-3 "falls with sag" claim is deliberately NOT in the objective (see claims.py). Degenerate optima are
rejected (`plausible`): the leg more than 70 degrees from horizontal at any design's neutral, or a design whose
250 V free stroke parks the linkage at its dead point or strokes less than 0.1 mm.

    python3 -m hamr_bench.model.geometry_search [n_random] [seed] [n_starts] [kappa_unit_N_m_per_rad]

(kappa_unit 1.0 = Table III read literally as N m/rad: used to check that no geometry rescues that reading.)
"""

from __future__ import annotations

import sys

import numpy as np

from hamr_bench.errors import ModelError

BOUNDS = {  # name: (low, high), SI
    "crank_m": (0.3e-3, 1.2e-3),
    "coupler_m": (0.4e-3, 3.0e-3),
    "offset_m": (-1.0e-3, 1.0e-3),
    "theta_fab_rad": (-np.pi, np.pi),
    "leg_length_m": (4e-3, 12e-3),
    "leg_angle0_rad": (-0.9, 0.9),   # leg inclined up to ~50 deg from horizontal at fabrication
}
KEYS = list(BOUNDS)


def score(x: np.ndarray, kappa_unit: float | None = None) -> float:
    from hamr_bench.model.claims import powertrains, transmission_figures, transmission_margins
    from hamr_bench.model.transmission import SliderCrankGeometry

    for k, v in zip(KEYS, x):
        lo, hi = BOUNDS[k]
        if not lo <= v <= hi:
            return -10.0
    try:
        g = SliderCrankGeometry(**dict(zip(KEYS, map(float, x))))
        pts = powertrains(g, kappa_unit)
        if not plausible(pts):
            return -5.0
        m = transmission_margins(transmission_figures(pts))
    except (ModelError, FloatingPointError, ValueError):
        return -10.0
    return min(m.values())


MAX_LEG_ANGLE_RAD = np.radians(70.0)   # beyond this the foot moves mostly sideways: not a lift mechanism
MIN_STROKE_M = 0.1e-3                  # every design visibly strokes in Fig. 9


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


def main(n_random: int = 3000, seed: int = 1, n_starts: int = 5, kappa_unit: float | None = None) -> None:
    from scipy.optimize import minimize

    rng = np.random.default_rng(seed)
    lo = np.array([BOUNDS[k][0] for k in KEYS])
    hi = np.array([BOUNDS[k][1] for k in KEYS])
    with np.errstate(all="ignore"):
        cands = lo + (hi - lo) * rng.random((n_random, len(KEYS)))
        scores = np.array([score(c, kappa_unit) for c in cands])
        order = np.argsort(scores)[::-1][:n_starts]
        best = (scores[order[0]], cands[order[0]])
        for i in order:
            res = minimize(lambda z: -score(z, kappa_unit), cands[i], method="Nelder-Mead",
                           options=dict(maxiter=600, xatol=1e-7, fatol=1e-4))
            if -res.fun > best[0]:
                best = (-res.fun, res.x)
            print(f"start {scores[i]:+.3f} -> {-res.fun:+.3f}  {dict(zip(KEYS, res.x.tolist()))}", flush=True)
    print("best worst-case margin", best[0])
    print(dict(zip(KEYS, best[1].tolist())))


if __name__ == "__main__":
    args = sys.argv[1:]
    main(*(int(a) for a in args[:3]), *(float(a) for a in args[3:4]))
