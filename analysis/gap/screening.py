"""Stage 1, screen: every candidate fitted alone on top of the nominal fit (its strength and shapes with the
specimen gains and every nuisance refitted), and a likelihood-ratio test of its improvement, the data rows' part
scaled by the over-dispersion the best single candidate leaves (the prior rows' part not), at 0.01 / (number of
candidates) (Bonferroni)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Protocol

import numpy as np
from scipy import optimize, stats

from analysis.gap import tolerances as tol
from analysis.gap.engine import base_compliance_m_per_N
from analysis.gap.families import FAMILIES
from analysis.gap.problem import Fit, Problem
from analysis.gap.results import Screened
from hamr_bench.model import actuator as act

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
    grid = sorted({min(max(g, lo), hi) for g in grid if lo <= g <= hi or (lo < g and hi == math.inf)})
    starts = [{**start, ("strength", name): s} for s in grid]
    for alt in f.grid_shapes:
        shapes = {("shape", name, k): v for k, v in alt.items()}
        starts += [{**start, **shapes, ("strength", name): s} for s in grid]
    plain = list(starts)
    if f.kind == "drive":
        # A drive effect and a sensor chain's lag trade on a ramp (a lag fitted without the effect stands in for a
        # loop): each strength is also tried with each fixture's lags at zero, and the best start kept.
        for fixture in sorted({k[1] for k in start if k[0] == "lag"}):
            zero = {k: 0.0 for k in start if k[0] == "lag" and k[1] == fixture}
            starts += [{**s0, **zero} for s0 in plain]
    if f.kind in ("params", "contact"):
        # A fabrication shift and the specimens' gains trade exactly on the rows (a linear series spring on the
        # actuator's blocked force nearly so): moved alone from the base fit it spoils what the gains fitted, and a
        # fit from there crawls along the valley. So each strength starts with the gains moved by what it changes
        # (the rows as they were, only the tolerance prior differs), and the strength that brings the gains
        # nearest the prior's centre is tried too.
        grid.append(prior_strength(p, base, name))
        starts += [compensated(p, base, name, s) for s in grid]
    best, best_start = math.inf, start
    for s0 in starts:
        r = p.residual(lay, lay.vector(s0))
        c = float(r @ r)
        if c < best:
            best, best_start = c, s0
    return best, best_start


def gain_change(p: Problem, base: Fit, g: str, name: str, s: float) -> np.ndarray:
    """What effect `name` at strength s does to specimen group g's (log stroke, log stiffness) from `base`: the
    coordinates of its gains, so gains minus this leave the rows as they were. Exact for a fabrication shift; for
    a series spring (its shapes at their defaults: linear, the same both ways) the stiffness the actuator must gain
    to keep its blocked force, k / (1 + C k) as before."""
    gains = (base.value("gain", g, 0), base.value("gain", g, 1))
    a = p.group_engine[g].actuator_for(base.effects, gains)
    if FAMILIES[name].kind == "params":
        return tol.log_outputs(tol.scaled(a, name, s)) - tol.log_outputs(a)
    c = base_compliance_m_per_N(s, 1.0) if name == "base_compliance" else s
    ck = c * act.stiffness_N_per_m(a)
    return np.array([0.0, math.log1p(-min(ck, 0.9))])


def compensated(p: Problem, base: Fit, name: str, s: float) -> dict[tuple, float]:
    """`base`'s values with `name` at strength s and every specimen's gains moved by what it changes."""
    out = {**base.values(), ("strength", name): s}
    for g in p.groups:
        d = gain_change(p, base, g, name, s)
        for j in (0, 1):
            out[("gain", g, j)] = base.value("gain", g, j) - float(d[j])
    return out


def prior_strength(p: Problem, base: Fit, name: str) -> float:
    """The strength that, taken out of every specimen's gains, leaves them nearest the tolerance prior's centre."""
    gains = {g: np.array([base.value("gain", g, 0), base.value("gain", g, 1)]) for g in p.groups}

    def prior(s: float) -> float:
        return sum(float(np.sum((p.gain_whitening[g] @ (gains[g] - gain_change(p, base, g, name, s))) ** 2))
                   for g in p.groups)

    f = FAMILIES[name]
    lo, hi = max(f.bounds[0], -9.0 * f.scale), min(f.bounds[1], 9.0 * f.scale)
    return float(optimize.minimize_scalar(prior, bounds=(lo, hi), method="bounded",
                                          options={"xatol": 1e-4 * f.scale}).x)


def n_params(p: Problem, name: str) -> int:
    """Free parameters a candidate adds: its strength and shapes (the drift: its baseline coefficients; an effect
    that reads the field: each specimen's plate thickness too)."""
    return max(1, len(p.params_of((name,))) - len(p.params_of(())))


def overdispersion(p: Problem, fit: Fit, n_extra: int = 0) -> float:
    dof = max(p.y.size - len(fit.layout.params) - n_extra, 1)
    return max(1.0, fit.objective / dof)


def improvement(before: Fit, after: Fit, scale2: float) -> float:
    """The objective's decrease, the specimen gains' prior rows weighted by the over-dispersion, so that when it is
    compared with a threshold x over-dispersion only the rest is diluted by it: a model's misfit inflates the
    scatter of the data rows, not the tolerance prior, and a fabrication shift common to the specimens shows
    there, in their gains. (The shapes' priors and the drift spline's smoothness are regularisers of the fit and
    count as the data do.)"""
    def gain_prior(f: Fit) -> float:
        rows = f.residual[f.layout.n_rows:f.layout.n_rows + f.n_gain_prior_rows]
        return float(rows @ rows)

    g = gain_prior(before) - gain_prior(after)
    return (before.objective - after.objective) - g + scale2 * g


def threshold(p: Problem, name: str, scale2: float, n_candidates: int, alpha: float = SCREEN_ALPHA) -> float:
    """The likelihood-ratio test's bar for candidate `name` among n_candidates (Bonferroni), x over-dispersion."""
    return lr_bar(n_params(p, name), scale2, n_candidates, alpha)


def lr_bar(dof: int, scale2: float, n_tests: int, alpha: float) -> float:
    """The likelihood-ratio bar for `dof` added parameters, one of n_tests (Bonferroni), x over-dispersion."""
    return float(stats.chi2.ppf(1 - alpha / max(n_tests, 1), dof)) * scale2


Start = Mapping[tuple, float]


class AddEach(Protocol):
    """For each name, `base`'s effects plus that one, refitted from each of the name's `starts` (None: `base` and
    the name's best strength on the coarse grid; the default for a name not in `starts`), the fit with the lowest
    objective kept. Each of `looks` (names not among `names`) is fitted in the same batch from its grid start for
    only `look_nfev` evaluations: a second look, run beside the full fits rather than before them."""
    def __call__(self, base: Fit, names: Sequence[str], max_nfev: int,
                 starts: Mapping[str, Sequence[Start | None]] | None = None, looks: Sequence[str] = (),
                 look_nfev: int = 0) -> dict[str, Fit]: ...


GridObjectives = Callable[[Fit, Sequence[str]], dict[str, float]]
# one fit per (base, name, start): that name added to that base (different bases, unlike AddEach)
AddOnto = Callable[[Sequence[tuple[Fit, str, Start]], int], list[Fit]]


def add_onto_here(p: Problem) -> AddOnto:
    """`AddOnto` one fit after another in this process (`fitpool.FitPool.add_onto`: side by side)."""
    def add_onto(tasks: Sequence[tuple[Fit, str, Start]], max_nfev: int) -> list[Fit]:
        return [fit_added(p, base, name, start, max_nfev) for base, name, start in tasks]
    return add_onto


def grid_objectives_here(p: Problem) -> GridObjectives:
    """Each candidate's best objective on its coarse grid added to a fit (`grid_best`), in this process."""
    def objectives(base: Fit, names: Sequence[str]) -> dict[str, float]:
        return {n: grid_best(p, base, n)[0] for n in names}
    return objectives


def add_each_here(p: Problem) -> AddEach:
    """Candidate fits one after another in this process (`fitpool.FitPool.add_each` runs them side by side)."""
    def add_each(base: Fit, names: Sequence[str], max_nfev: int,
                 starts: Mapping[str, Sequence[Start | None]] | None = None, looks: Sequence[str] = (),
                 look_nfev: int = 0) -> dict[str, Fit]:
        out = {n: min((fit_added(p, base, n, s0, max_nfev) for s0 in (starts or {}).get(n, [None])),
                      key=lambda f: f.objective) for n in names}
        return out | {n: fit_added(p, base, n, None, look_nfev) for n in looks}
    return add_each


def fit_added(p: Problem, base: Fit, name: str, start: Start | None, max_nfev: int) -> Fit:
    """`base`'s effects plus `name`, fitted from `start` (None: from `base` and `name`'s grid start)."""
    return p.solve(tuple(base.names) + (name,), dict(start) if start is not None else grid_start(p, base, name),
                   max_nfev=max_nfev, free_lags=_lags_stand_in(base, name))


def _lags_stand_in(base: Fit, name: str) -> bool:
    """Adding drive effect `name` to the nominal fit (screening, a selection's first step): its lags may stand in
    for the effect's delayed response on the ramps, and are moved along their envelope first (`lag_envelope`).
    Later fits start from the screened fit's lags. Freeing them too wherever the base holds no drive effect cost
    the five-effect campaign ~9 s of its 60 for one drift more on 90 self-check trials (docs/gap.md, Method)."""
    return FAMILIES[name].kind == "drive" and not base.names


def carried_start(base: Fit, other: Fit, name: str) -> dict[tuple, float]:
    """`base`'s values with `name`'s own parameters (strength, shapes) as `other` fitted them, and whatever else
    `other` has that `base` lacks (a field effect's plates). Two effects that explain overlapping parts of the gap
    (a d31 curve and a hysteresis both bend the stroke against amplitude) can leave their joint fit started from
    one's fit in that one's basin, with the other at a sliver of its strength."""
    theirs = other.values()
    own = {k: v for k, v in theirs.items() if k[0] in ("strength", "shape") and k[1] == name}
    return {**theirs, **base.values(), **own}


def screen(p: Problem, nominal: Fit, names: list[str], add_each: AddEach | None = None
           ) -> tuple[list[Screened], dict[str, Fit]]:
    fits = (add_each or add_each_here(p))(nominal, names, 25)
    best = min((f.objective for f in fits.values()), default=nominal.objective)
    scale2 = max(1.0, best / max(p.y.size - len(nominal.layout.params) - 2, 1))
    out = []
    for n, f in fits.items():
        imp = improvement(nominal, f, scale2)
        thr = threshold(p, n, scale2, len(names))
        strength = f.effects[n].strength
        out.append(Screened(n, float(strength), dict(f.effects[n].shapes), float(imp), thr,
                            bool(imp > thr and np.isfinite(imp)), start=f.values()))
    return out, fits
