"""Stage 1, screen: every candidate fitted alone on top of the nominal fit (its strength and shapes with the
specimen gains and every nuisance refitted), and a likelihood-ratio test of its improvement, scaled by the
over-dispersion the best single candidate leaves, at 0.01 / (number of candidates) (Bonferroni)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from analysis.gap.families import FAMILIES
from analysis.gap.problem import Fit, Problem
from analysis.gap.results import Screened

SCREEN_ALPHA = 0.01
FULL_FITS = 6   # candidates given a full fit after the grid (the others cannot pass: their grid gain is least)


def grid_start(p: Problem, base: Fit, name: str) -> tuple[dict[tuple, float], float]:
    """Start values for adding `name` to `base`: base's parameters and the best strength on a coarse grid (the
    landscape of a memory or contact effect is not convex from 0); and the objective there."""
    names = tuple(base.names) + (name,)
    lay = p.layout(names)
    start = dict(base.values())
    f = FAMILIES[name]
    if f.kind == "baseline":
        r = p.residual(lay, lay.vector(start))
        return start, float(r @ r)
    lo, hi = f.bounds
    grid = [s * f.scale for s in (-4, -2, -1, -0.5, 0.5, 1, 2, 4, 8)]
    grid = [g for g in grid if lo <= g <= hi]
    best, best_s = math.inf, 0.0
    for s in sorted(set(grid)):
        r = p.residual(lay, lay.vector({**start, ("strength", name): s}))
        c = float(r @ r)
        if c < best:
            best, best_s = c, s
    start[("strength", name)] = best_s
    return start, best


def n_params(p: Problem, name: str) -> int:
    """Free parameters a candidate adds: its strength and shapes (the drift: its baseline coefficients)."""
    f = FAMILIES[name]
    if f.kind == "baseline":
        return max(1, len(p.layout((name,)).params) - len(p.layout(()).params))
    return 1 + len(f.shapes)


def overdispersion(p: Problem, fit: Fit) -> float:
    """chi^2 of the rows per degree of freedom left (at least 1): model-form error the noise floor misses."""
    dof = max(p.y.size - len(fit.layout.params), 1)
    return max(1.0, fit.chi2_rows / dof)


def threshold(p: Problem, name: str, n_candidates: int) -> float:
    return float(stats.chi2.ppf(1 - SCREEN_ALPHA / max(n_candidates, 1), n_params(p, name)))


def screen(p: Problem, nominal: Fit, names: list[str]) -> tuple[list[Screened], dict[str, Fit]]:
    """A coarse strength grid for every candidate (the nuisances held at the nominal fit), then a full fit of the
    FULL_FITS best by that grid; the others keep their grid figures and are not promising."""
    grids = {n: grid_start(p, nominal, n) for n in names}
    order = sorted(names, key=lambda n: grids[n][1])
    fits: dict[str, Fit] = {}
    for n in order[:FULL_FITS]:
        if grids[n][1] < nominal.objective:
            fits[n] = p.solve(tuple(nominal.names) + (n,), grids[n][0], max_nfev=20)
    best = min(fits.values(), key=lambda f: f.chi2_rows, default=nominal)
    scale2 = overdispersion(p, best)
    out = []
    for n in names:
        thr = threshold(p, n, len(names))
        if n in fits:
            f = fits[n]
            stat = f.statistic_against(nominal, scale2)
            out.append(Screened(n, float(f.effects[n].strength), dict(f.effects[n].shapes), float(stat), thr,
                                bool(stat > thr and np.isfinite(stat)), start=f.values()))
        else:
            start, obj = grids[n]
            out.append(Screened(n, float(start.get(("strength", n), 0.0)), {},
                                float((nominal.objective - obj) / scale2), thr, False, start=start))
    return out, fits
