"""Stage 3, rank: forward selection by held-out gap. From the nominal fit, each promising candidate is added in turn to
the effects named so far and the whole refitted (in batches of MAX_TRIED by screening improvement, widened so as not
to split candidates the screening could not tell apart, the next batch only when none of the last passes; at the
first step after the nominal fit, each candidate the screening turned down is looked at again by a short fit beside
the first batch, and fitted outright if it shows there and either nothing passed or it improves more than what did);
of those whose in-sample improvement passes the likelihood-ratio test and whose held-out reduction's bootstrap
interval is above 0, the one that lowers the held-out gap most is named. Candidates whose addition is as good on
both counts are named with it as one ambiguous set. A rival of a step's lead (it passed there too and explained at
least half as much in-sample) is fitted at the next step from its own fit as well as from the lead's, and the better
fit kept: two effects that explain much the same misfit can leave their joint fit in whichever basin it started
from. When none passes alone, two may pass together (`joint_entry`): both are named, as two bars of the waterfall.
The selection stops when nothing passes, when the held-out gap after a named effect is at the noise floor, or after
MAX_EFFECTS. The waterfall is the held-out gap after each addition."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from functools import partial

import numpy as np
from scipy import stats

from analysis.gap.families import FAMILIES
from analysis.gap.heldout import Judge
from analysis.gap.joint_entry import joint_entry
from analysis.gap.problem import Fit, Problem
from analysis.gap.results import HeldOut, Screened, StepCandidate, WaterfallStep
from analysis.gap.screening import (AddEach, AddOnto, GridObjectives, Start, add_each_here, add_onto_here,
                                    carried_start, grid_objectives_here, improvement, overdispersion, threshold)

MAX_EFFECTS = 4
MAX_TRIED = 4            # promising candidates tried at each step (by screening improvement)
TIE_RATIO = 1.1          # held-out RMS within 10 % counts as a tie
STEP_ALPHA = 0.01
RIVAL_SHARE = 0.5        # a candidate explaining this share of the lead's in-sample improvement is its rival
LOOK_NFEV = 6            # evaluations of a turned-down candidate's second look (a short fit)


@dataclass
class Selection:
    steps: list[WaterfallStep]
    fits: list[Fit]                      # the fit after each step (fits[0]: nominal)
    rejected: list[StepCandidate] = field(default_factory=list)      # tried after the last named step
    # the final model with each rejected candidate that passed the in-sample test (its held-out one failed)
    unruled: dict[str, Fit] = field(default_factory=dict)


def _closed(before: float, after: float) -> float:
    return (before - after) / (before - 1.0) if before > 1.0 else 0.0


def select(p: Problem, nominal: Fit, screened: list[Screened], judge: Judge, gap: bool,
           add_each: AddEach | None = None, screen_fits: dict[str, Fit] | None = None,
           grid_objectives: GridObjectives | None = None, add_onto: AddOnto | None = None) -> Selection:
    """`screen_fits`: the screening's fits (nominal + one candidate); at the first step a converged one is that
    step's fit of its candidate (the same problem), not fitted again. `add_each`, `grid_objectives` and
    `add_onto`: where the candidates' fits, coarse grids and pairs run (`fitpool.FitPool`: side by side)."""
    ho0 = judge.heldout(nominal)
    steps = [WaterfallStep(None, (), ho0, 0.0)]
    fits = [nominal]
    pool = [s.name for s in sorted(screened, key=lambda s: -s.improvement) if s.promising]
    current = nominal
    rejected: list[StepCandidate] = []
    unruled: dict[str, Fit] = {}
    spent: set[str] = set()   # named, alone or in an ambiguous set
    rivals: dict[str, Fit] = {}   # the last step's rivals of its lead: their fits there, by candidate
    rescreened = False    # the turned-down candidates' short fits: once, at the first step after the nominal
    while gap and pool and len(current.names) < MAX_EFFECTS:
        if current is not nominal and judge.heldout(current).reaches_noise_floor:
            # at the noise floor; not tested on the nominal fit: the gap tests opened the diagnosis, and the
            # paired held-out reduction each candidate must pass is the stronger test there
            break
        extra, looks = _second_look(p, current, screened, set(pool) | spent, grid_objectives) \
            if current is not nominal else ([], [])
        if rescreened:
            looks = []
        rescreened = current is not nominal
        screened_fits = screen_fits if current is nominal and screen_fits else {}
        tried, rows, passing, scale2 = _fit_step(p, current, pool, extra, looks, judge, add_each or add_each_here(p),
                                                 screened_fits, rivals, screened)
        if not passing:
            bar = partial(_step_bar, p, scale2, len(pool))
            joint = joint_entry(p, current, rows, tried, judge, add_onto or add_onto_here(p), bar, STEP_ALPHA,
                                scale2) if len(current.names) + 2 <= MAX_EFFECTS else None
            if joint is None:
                rejected = rows
                unruled = {c.name: tried[c.name] for c in rows if c.improvement > c.bar}
                break
            alone = tried[joint.first]
            for name, fit, step_rows, other in ((joint.first, alone, rows, joint.second),
                                                (joint.second, joint.fit, [joint.row], joint.first)):
                ho = judge.heldout(fit)
                steps.append(WaterfallStep(name, tuple(fit.names), ho, _closed(ho0.rms, ho.rms), (), step_rows,
                                           joint_with=(other,)))
                fits.append(fit)
            current = joint.fit
            pool = [n for n in pool if n not in (joint.first, joint.second)]
            rivals = {}
            spent |= {joint.first, joint.second}
            continue
        lead = _lead(passing, tried, judge)
        ambiguous = tuple(c.name for c in rows if c.name != lead.name and _tie(c, lead, tried, judge, scale2))
        current = tried[lead.name]
        ho = judge.heldout(current)
        steps.append(WaterfallStep(lead.name, tuple(current.names), ho, _closed(ho0.rms, ho.rms), ambiguous, rows))
        fits.append(current)
        pool = [n for n in pool if n != lead.name and n not in ambiguous]
        rivals = {c.name: tried[c.name] for c in passing
                  if c.name in pool and c.improvement >= RIVAL_SHARE * lead.improvement}
        spent |= {lead.name, *ambiguous}
    return Selection(steps, fits, rejected, unruled)


def _next_batch(queue: list[str], screened: list[Screened], bar: float) -> tuple[list[str], list[str]]:
    """(the next batch, the rest): the first MAX_TRIED of the queue (by screening improvement), and after them
    each whose screening improvement is as good as the last of those within `bar` (the in-sample bar of a tie,
    `_tie_bar`). A batch boundary must not split candidates the screening could not tell apart: one left behind
    is never tried once its batch-mates pass, and the ambiguous set named then lacks it (a sensor spring whose
    improvement equalled the base spring's, fifth in the queue)."""
    n = min(MAX_TRIED, len(queue))
    if n == 0:
        return [], []
    gain = {s.name: s.improvement for s in screened}
    floor = gain.get(queue[n - 1], math.inf) - bar
    while n < len(queue) and gain.get(queue[n], -math.inf) > floor:
        n += 1
    return queue[:n], queue[n:]


def _fit_step(p: Problem, current: Fit, pool: list[str], extra: list[str], looks: list[str], judge: Judge,
              add_each: AddEach, screened_fits: dict[str, Fit], rivals: dict[str, Fit], screened: list[Screened]
              ) -> tuple[dict[str, Fit], list[StepCandidate], list[StepCandidate], float]:
    """One step's fits and how they fare (`_judged`): the promising candidates in batches (`_next_batch`) until
    one passes, since the largest in-sample improvements can all fail held out (a spring or a d31 curve fitting
    what a fabrication shift causes) and the candidates behind them must still be tried; `extra` fitted outright
    and `looks` by a short fit beside the first batch. A look that shows is fitted
    outright at this step: next if nothing passed, and beside what passed only if its short fit already improves
    more than they do."""
    tried: dict[str, Fit] = {}
    judged: dict[str, tuple[HeldOut, tuple[float, float]]] = {}
    looked: dict[str, Fit] = {}   # looks that showed: their short fits, to start from
    queue = list(pool)
    first = True
    batch_bar = _tie_bar(overdispersion(p, current, 0))
    while True:
        batch, queue = _next_batch(queue, screened, batch_bar)
        names = batch + (extra if first else [])
        reuse = {n: f for n in names if (f := screened_fits.get(n)) is not None and f.extra.get("converged")}
        # an unconverged screening fit (the same problem) goes on from where it stopped; a rival of the last
        # step's lead (it passed there and explained at least RIVAL_SHARE of what the lead did in-sample: much
        # the same misfit) is also fitted from its fit there, the lead carried over: started only from the lead's
        # fit, their joint fit can stay in the lead's basin with the rival at a sliver
        starts: dict[str, list[Start | None]] = {n: [screened_fits[n].values()] for n in names
                                                  if n in screened_fits and n not in reuse}
        starts |= {n: [None, carried_start(current, rivals[n], n)] for n in names if n in rivals}
        starts |= {n: [looked[n].values()] for n in names if n in looked}
        step_looks = looks if first else []
        fitted = add_each(current, [n for n in names if n not in reuse], 40, starts, step_looks, LOOK_NFEV)
        tried.update({n: reuse[n] if n in reuse else fitted[n] for n in names})
        found = _passed_looks(p, current, {n: fitted[n] for n in step_looks}, len(screened))
        looked |= found
        rows, passing, scale2 = _judged(p, current, tried, judge, len(pool), judged)
        first = False
        if found:
            lead_improvement = max((c.improvement for c in passing), default=-math.inf)
            contenders = [n for n, f in found.items() if improvement(current, f, scale2) > lead_improvement]
            queue = contenders + ([] if passing else queue)
        if not queue or (passing and not found):
            return tried, rows, passing, scale2


def _judged(p: Problem, current: Fit, tried: dict[str, Fit], judge: Judge, n_pool: int,
            judged: dict[str, tuple[HeldOut, tuple[float, float]]]) -> tuple[list[StepCandidate],
                                                                               list[StepCandidate], float]:
    """Every candidate tried at a step, by held-out gap, and those that pass: each against its own gate (one with
    many parameters, the drift spline, that fails it must not hide one with few that passes). `judged` keeps each
    fit's held-out bootstraps across a step's batches; only the improvement depends on the batch (through the
    over-dispersion of the best fit tried so far)."""
    scale2 = overdispersion(p, min(tried.values(), key=lambda f: f.objective), 0)
    rows = []
    for name, f in tried.items():
        if name not in judged:
            judged[name] = (judge.heldout(f), judge.reduction_ci(current, f))
        ho, ci = judged[name]
        rows.append(StepCandidate(name, improvement(current, f, scale2), ho, ci, float(f.effects[name].strength),
                                  _step_bar(p, scale2, n_pool, name)))
    rows.sort(key=lambda c: c.heldout.rms)
    passing = [c for c in rows if c.reduction_ci95[0] > 0 and c.improvement > c.bar]
    return rows, passing, scale2


def _step_bar(p: Problem, scale2: float, n_pool: int, name: str) -> float:
    """A step's likelihood-ratio bar for one candidate's in-sample improvement."""
    return threshold(p, name, scale2, n_pool, STEP_ALPHA)


def _second_look(p: Problem, current: Fit, screened: list[Screened], exclude: set[str],
                 grid_objectives: GridObjectives | None = None) -> tuple[list[str], list[str]]:
    """The candidates the screening against the nominal fit turned down, looked at again on the current fit: a
    large effect named first can hide a smaller one from a fit started at the nominal model (its fit stopped short
    of the nominal objective itself). Returns (those to fit at this step outright, those to look at by a short fit
    beside the step's first batch, `_passed_looks`).

    A fabrication shift is looked at on its coarse grid, the specimens' gains moved by what it changes
    (`screening.compensated`): that is all a shift needs to follow the fit; it is fitted outright where a grid
    strength lowers the objective by more than the screening threshold. A baseline family has no grid and is
    fitted outright (a large drive effect inflates the over-dispersion its screening threshold is scaled by, and
    hides a drift under it). A drive, contact, design or stage effect gets a short fit: held at the current
    fit's lags and gains, a creep hidden under a d31 curve raised the objective at every grid strength, and a few
    evaluations that let them follow lowered it by twenty times the bar."""
    scale2 = overdispersion(p, current, 0)
    left = [s.name for s in screened if not (s.promising or s.name in exclude)]
    shifts = [n for n in left if FAMILIES[n].kind == "params"]
    objective = (grid_objectives or grid_objectives_here(p))(current, shifts)
    outright = [n for n in shifts if current.objective - objective[n] > threshold(p, n, scale2, len(screened))]
    outright += [n for n in left if FAMILIES[n].kind == "baseline"]
    return outright, [n for n in left if n not in shifts and FAMILIES[n].kind != "baseline"]


def _passed_looks(p: Problem, current: Fit, fits: dict[str, Fit], n_screened: int) -> dict[str, Fit]:
    """The short fits whose improvement on the current fit passes the screening threshold."""
    scale2 = overdispersion(p, current, 0)
    return {n: f for n, f in fits.items() if improvement(current, f, scale2) > threshold(p, n, scale2, n_screened)}


def _lead(rows: list[StepCandidate], tried: dict[str, Fit], judge: Judge) -> StepCandidate:
    """The lowest held-out gap, unless the held-out data cannot tell it from another (within 10 %, or their paired
    difference's interval holding 0): then the better in-sample objective + 2 x parameters leads."""
    best = rows[0]
    tied = [c for c in rows if c.heldout.rms < TIE_RATIO * best.heldout.rms
            or (c.reduction_ci95[0] > 0 and judge.difference_ci(tried[c.name], tried[best.name])[0] <= 0)]
    return min(tied, key=lambda c: tried[c.name].objective + 2 * len(tried[c.name].layout.params))


def _tie(c: StepCandidate, lead: StepCandidate, tried: dict[str, Fit], judge: Judge, scale2: float) -> bool:
    """Another explanation this data cannot tell from the lead: held-out errors within 10 % or their paired
    difference's interval holding 0, AND in-sample objectives within the 1 % point of chi^2(1) x over-dispersion,
    AND it explains a real part of the gap itself."""
    if c.reduction_ci95[0] <= 0:
        return False
    lo, _ = judge.difference_ci(tried[c.name], tried[lead.name])
    close_heldout = lo <= 0 or c.heldout.rms < TIE_RATIO * lead.heldout.rms
    in_sample = abs(tried[c.name].objective - tried[lead.name].objective)
    return bool(close_heldout and in_sample < _tie_bar(scale2))


def _tie_bar(scale2: float) -> float:
    """How far apart two fits' in-sample objectives may be and still tie: the 1 % point of chi^2(1) x
    over-dispersion."""
    return float(stats.chi2.ppf(0.99, 1)) * scale2


def strength_estimate(p: Problem, fit: Fit, name: str, judge: Judge) -> tuple[float, tuple[float, float]]:
    """A strength and its 95 % interval from the joint fit: the Wald half-width from the Jacobian (noise, scaled by
    the over-dispersion) and the delete-a-fold jackknife of the held-out steps (model form across conditions), the
    jackknife's excess over the noise added in quadrature; clipped to the family's range. The drift's wander is
    derived from its baseline coefficients (`_drift_estimate`)."""
    f = FAMILIES[name]
    scale2 = overdispersion(p, fit)
    cov = fit.covariance() * scale2
    if f.kind == "baseline":
        return _drift_estimate(p, fit, cov, fit.drift_strength)
    i = fit.layout.index[("strength", name)]
    s = float(fit.x[i])
    wald = 1.96 * float(np.sqrt(max(cov[i, i], 0.0)))
    judge.z(fit)
    fold = [s + float(step[i]) for step in fit.extra.get("fold_steps", [])]
    jack = 0.0
    if len(fold) >= 2:
        k = len(fold)
        se = float(np.sqrt((k - 1) / k * np.sum((np.array(fold) - np.mean(fold)) ** 2)))
        jack = float(stats.t.ppf(0.975, k - 1)) * se
    half = float(np.sqrt(wald ** 2 + max(0.0, jack ** 2 - wald ** 2)))
    lo, hi = f.bounds
    return s, (max(lo, s - half), min(hi, s + half))


def within_unruled_models(name: str, estimate: tuple[float, tuple[float, float]], unruled: Iterable[Fit]
                          ) -> tuple[float, tuple[float, float]]:
    """A strength's interval widened to hold the strength each unruled model gives it (`Selection.unruled`: the
    final model with one more candidate, which passed the in-sample test and not the held-out one). The data do
    not rule those models out, and an effect left out of a model biases the strengths of those in it (measured in
    docs/gap.md, Method stage 6). The drift's wander is derived from its coefficients, not held in a strength, and
    is left as it is."""
    s, (lo, hi) = estimate
    if FAMILIES[name].kind == "baseline":
        return estimate
    others = [float(f.effects[name].strength) for f in unruled if name in f.effects]
    return s, (min([lo, *others]), max([hi, *others]))


def _drift_estimate(p: Problem, fit: Fit, cov: np.ndarray, s: float) -> tuple[float, tuple[float, float]]:
    """The wander rate, bias-corrected, and its basic (pivot) interval from draws of the baseline coefficients.

    The wander is a sum of squares of the fitted baseline's changes: noise in the coefficients adds to it, so the
    fitted value sits above the truth by about as much as the draws sit above the fitted value. The pivot
    interval corrects for that, and the point reported is corrected the same way (2 s - median of the draws), so
    it lies inside its own interval."""
    idx = [i for i, q in enumerate(fit.layout.params) if q.kind == "drift"]
    if not idx:
        return 0.0, (0.0, 0.0)
    rng = np.random.default_rng(0)
    draws = rng.multivariate_normal(fit.x[idx], cov[np.ix_(idx, idx)], size=200, method="eigh")
    vals = []
    for d in draws:
        x = fit.x.copy()
        x[idx] = d
        vals.append(p.drift_strength(fit.layout, x))
    lo, mid, hi = np.percentile(vals, [2.5, 50.0, 97.5])
    return max(0.0, 2 * s - float(mid)), (max(0.0, 2 * s - float(hi)), max(0.0, 2 * s - float(lo)))


__all__ = ["MAX_EFFECTS", "HeldOut", "Selection", "select", "strength_estimate", "within_unruled_models"]
