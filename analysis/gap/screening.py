"""Stage 1, screen: every candidate fitted alone on top of the nominal fit (its strength and shapes with the
specimen gains and every nuisance refitted), and a likelihood-ratio test of its improvement, scaled by the
over-dispersion the best single candidate leaves, at 0.01 / (number of candidates) (Bonferroni)."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np
from scipy import stats

from analysis.gap.families import FAMILIES
from analysis.gap.problem import Fit, Problem
from analysis.gap.results import Screened

SCREEN_ALPHA = 0.01


def grid_start(p: Problem, base: Fit, name: str) -> dict[tuple, float]:
    """Start values for adding `name` to `base`: base's parameters and the best strength on a coarse grid (the
    landscape of a memory or contact effect is not convex from 0)."""
    return grid_best(p, base, name)[1]


def grid_best(p: Problem, base: Fit, name: str) -> tuple[float, dict[tuple, float]]:
    """(objective, start values) at the best strength of `name` on the coarse grid, everything else held at
    `base`'s values (a baseline family: base's objective and values)."""
    names = tuple(base.names) + (name,)
    lay = p.layout(names)
    start = dict(base.values())
    f = FAMILIES[name]
    if f.kind == "baseline":
        return base.objective, start
    lo, hi = f.bounds
    grid = [s * f.scale for s in (-4, -2, -1, -0.5, 0.5, 1, 2, 4, 8)]
    grid = [min(max(g, lo), hi) for g in grid if lo <= g <= hi or (lo < g and hi == math.inf)]
    # A drive effect and a sensor chain's lag trade on a ramp (a lag fitted without the effect stands in for a
    # loop): each strength is also tried with each fixture's lags at zero, and the best start kept.
    starts = [start]
    if f.kind == "drive":
        for fixture in sorted({k[1] for k in start if k[0] == "lag"}):
            starts.append({**start, **{k: 0.0 for k in start if k[0] == "lag" and k[1] == fixture}})
    best, best_start = math.inf, start
    for s0 in starts:
        for s in sorted(set(grid)):
            x = lay.vector({**s0, ("strength", name): s})
            r = p.residual(lay, x)
            c = float(r @ r)
            if c < best:
                best, best_start = c, {**s0, ("strength", name): s}
    return best, best_start


def n_params(p: Problem, name: str) -> int:
    """Free parameters a candidate adds: its strength and shapes (the drift: its baseline coefficients)."""
    f = FAMILIES[name]
    if f.kind == "baseline":
        return max(1, p.layout((name,)).params.__len__() - p.layout(()).params.__len__())
    return 1 + len(f.shapes)


def overdispersion(p: Problem, fit: Fit, n_extra: int = 0) -> float:
    dof = max(p.y.size - len(fit.layout.params) - n_extra, 1)
    return max(1.0, fit.objective / dof)


def threshold(p: Problem, name: str, scale2: float, n_candidates: int) -> float:
    return float(stats.chi2.ppf(1 - SCREEN_ALPHA / max(n_candidates, 1), n_params(p, name))) * scale2


AddEach = Callable[[Fit, Sequence[str], int], dict[str, Fit]]


def add_each_here(p: Problem) -> AddEach:
    """Candidate fits one after another in this process (`fitpool.FitPool.add_each` runs them side by side)."""
    def add_each(base: Fit, names: Sequence[str], max_nfev: int) -> dict[str, Fit]:
        return {n: p.solve(tuple(base.names) + (n,), grid_start(p, base, n), max_nfev=max_nfev) for n in names}
    return add_each


def screen(p: Problem, nominal: Fit, names: list[str], add_each: AddEach | None = None
           ) -> tuple[list[Screened], dict[str, Fit]]:
    fits = (add_each or add_each_here(p))(nominal, names, 25)
    best = min((f.objective for f in fits.values()), default=nominal.objective)
    scale2 = max(1.0, best / max(p.y.size - len(nominal.layout.params) - 2, 1))
    out = []
    for n, f in fits.items():
        imp = nominal.objective - f.objective
        thr = threshold(p, n, scale2, len(names))
        strength = f.effects[n].strength
        out.append(Screened(n, float(strength), dict(f.effects[n].shapes), float(imp), thr,
                            bool(imp > thr and np.isfinite(imp)), start=f.values()))
    return out, fits
