"""Held-out judgement: the prediction of data the fit did not see, two ways, and bootstrap intervals over
conditions.

- Condition folds: whole conditions (replicates and a condition's specimens' phases stay together; its undriven
  dwell apart, `folds`) left out, each predicted by the model refitted without it: does the model carry to a new
  drive condition?
- Specimen folds (where the data hold two or more specimen groups): each specimen left out and predicted from the
  population, its gains at the prior's centre, in units of the predictive spread (noise and the tolerance prior's
  spread of its gains): does the model carry to a new specimen? This is where a fabrication shift common to every
  specimen shows: in-sample each specimen's gains absorb it, but a new specimen is predicted as far off as the
  shift, while specimen scatter alone is predicted to within the tolerance spread (z ~ 1).

The held-out z of a model is both vectors together; under the right model its RMS is ~1 (the noise floor).

Every model on one problem is measured in the same units: each row's predictive spread as the nominal fit has it
(the judge's reference). A model's own spread would include the uncertainty of its own parameters, so a vaguer
model (a force baseline whose coefficients a left-out file barely constrains, ~2 mN wide against a ~0.2 mN
noise) would divide its own errors by more and look better held out without predicting better. In the
reference's units, a smaller held-out z is a smaller prediction error.

The refit without a fold is one Gauss-Newton step from the full-data optimum on the training rows (and the other
prior rows), with the full fit's Jacobian: the standard linearised cross-validation, exact for a model linear in
its parameters near the optimum and far cheaper than a nonlinear refit per fold. A left-out specimen's gains are
set to the prior's centre exactly (the model re-evaluated there), not by a linear step."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits  # type: ignore[import-untyped]

from analysis.gap.problem import Fit, Problem
from analysis.gap.results import HeldOut

N_FOLDS = 5
UNDRIVEN_PHASE = "low_late"   # the settled part of a cycle's low dwell (`features.PHASES`)
N_BOOT = 400
NAN_Z = 1e3       # a row the model cannot evaluate (as `problem.NAN_RESIDUAL`)


def condition_ids(p: Problem) -> np.ndarray:
    """Condition index per row: (fixture, layers / design, mode, voltage, sag), shared by the specimens and runs
    measured there, so a fold leaves a whole condition out for every specimen."""
    keys = []
    for r in p.rows:
        run = p.data.runs[r.run]
        keys.append((run.fixture, run.layers, run.design or 0, r.protocol, r.mode, round(r.voltage_V / 5.0),
                     round(r.sag_m, 7)))
    uniq = sorted(set(keys), key=str)
    index = {k: i for i, k in enumerate(uniq)}
    return np.array([index[k] for k in keys])


def folds(p: Problem) -> list[np.ndarray]:
    """The condition folds' held-out rows: conditions dealt round N_FOLDS folds, each condition's undriven dwell
    (`UNDRIVEN_PHASE`) in the next fold from its driven rows. A force baseline is read at the undriven dwell of the
    same cycles: left out with the rest of its file, a file's level is seen by no training row, and no model
    could be credited for a baseline (on imported traces each file is one step, one level per file). Every row is
    still held out once."""
    cid = condition_ids(p)
    n = int(cid.max()) + 1 if cid.size else 0
    k = min(N_FOLDS, max(n, 1))
    fold = cid % k
    undriven = np.array([r.phase == UNDRIVEN_PHASE for r in p.rows], bool)
    fold = np.where(undriven, (fold + 1) % k, fold)
    out = [fold == j for j in range(k)]
    return [f for f in out if f.any() and not f.all()]


def strata(p: Problem) -> np.ndarray:
    """Stratum per row for the bootstrap: one experiment (fixture, mode): each resample keeps the plan."""
    keys = [(p.data.runs[r.run].fixture, r.mode, r.quantity) for r in p.rows]
    uniq = sorted(set(keys))
    return np.array([uniq.index(k) for k in keys])


def specimen_folds(p: Problem) -> list[str]:
    """The specimen groups that can each be left out (none when the data hold a single group: nothing would
    remain to predict it from)."""
    return list(p.groups) if len(p.groups) >= 2 else []


def specimen_errors(p: Problem, fit: Fit, groups: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per row, its error (noise units) when its specimen was left out and predicted from the population: its
    gains at 0, the rest refitted by one linearised step without its rows and prior rows; and its predictive
    spread sqrt(1 + j Sigma j^T) (j: the row's sensitivity to its specimen's gains, Sigma: their tolerance
    prior)."""
    n = fit.layout.n_rows
    lay = fit.layout
    out = np.zeros(n)
    spreads = np.ones(n)
    prior_rows = p.prior_rows(lay)
    scales = lay.scales()
    for g in groups:
        rows = np.zeros(n, bool)
        for k, e in enumerate(p.engines):
            if p.group_of(e) == g:
                rows[p.slices[k]] = True
        cols = [lay.index[("gain", g, 0)], lay.index[("gain", g, 1)]]
        keep_cols = np.ones(len(lay.params), bool)
        keep_cols[cols] = False
        train = np.r_[~rows, np.ones(fit.residual.size - n, bool)]
        for c in cols:
            for j in prior_rows.get(c, []):
                train[n + j] = False
        scale = scales[keep_cols]
        u, sv, vt = np.linalg.svd(fit.jac[np.ix_(train, keep_cols)] * scale, full_matrices=False)
        kept = determined(sv)
        step = -(vt[kept].T / sv[kept]) @ (u[:, kept].T @ fit.residual[train]) * scale
        x0 = fit.x.copy()
        x0[cols] = 0.0
        z_pop = (p.y - p.model(lay, x0)) / p.sigma
        z_pop = np.where(np.isfinite(z_pop), z_pop, NAN_Z)
        jg = fit.jac[:n][rows][:, cols]
        cov = np.linalg.inv(p.gain_whitening[g].T @ p.gain_whitening[g])
        spreads[rows] = np.sqrt(1.0 + np.einsum("ij,jk,ik->i", jg, cov, jg))
        out[rows] = z_pop[rows] + fit.jac[:n][np.ix_(rows, keep_cols)] @ step
    return out, spreads


def determined(s: np.ndarray) -> np.ndarray:
    """Which singular directions of a Jacobian (columns in the parameters' scaled units, rows in noise units) the
    data determine: above 1e-10 of the largest (rounding), and above 1e-3, where a thousand of the parameters'
    scales move the rows by one noise width. Below that a direction is the data's blind spot: a lag read on a
    staircase drive whose sampled sensor sees no step within its settling moves no row, and the one row whose
    finite difference caught a step edge would have set a step of 10^6 scales along it."""
    return (s > 1e-10 * (s[0] if s.size else 0.0)) & (s > 1e-3)


def heldout_errors(fit: Fit, fold_masks: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Per row, its error (noise units) when its fold was left out of the fit, and its predictive spread; and each
    fold's parameter step (for jackknives).

    The spread is sqrt(1 + j (J_t^T J_t)^+ j^T) (j: the row's sensitivities, J_t: the training rows' and priors'
    Jacobian): a condition predicted from the others carries the uncertainty of the parameters estimated without
    it, so even the right model's raw held-out z would scatter wider than the noise (~1.4-1.5 x on the
    self-check's effect-free trials); in these units its RMS is ~1, the noise floor the held-out gap is read
    against. Directions the training rows leave undetermined are dropped from the step and from the spread
    alike (the pseudo-inverse's cut, on the Jacobian's columns in the parameters' scaled units: in their own
    units a direction's singular value says as much about its unit as about the data, and a near-undetermined
    lag kept by an unscaled cut took steps of 10^6 of its scale, which FD noise in its column turned into
    held-out errors of 10^3 noise units)."""
    n = fit.layout.n_rows
    scale = fit.layout.scales()
    r, j = fit.residual, fit.jac * scale       # columns in the parameters' scaled units (`Layout.scales`)
    out = np.zeros(n)
    spreads = np.ones(n)
    steps = []
    for held in fold_masks:
        train = np.r_[~held, np.ones(r.size - n, bool)]
        u, s, vt = np.linalg.svd(j[train], full_matrices=False)
        keep = determined(s)
        proj = vt[keep].T / s[keep]                       # V S^-1 on the kept directions
        step = -proj @ (u[:, keep].T @ r[train])
        jh = j[:n][held]
        spreads[held] = np.sqrt(1.0 + np.sum((jh @ proj) ** 2, axis=1))
        out[held] = r[:n][held] + jh @ step
        steps.append(step * scale)
    return out, spreads, steps


def rms(v: np.ndarray) -> float:
    return float(np.sqrt(np.mean(v * v))) if v.size else 0.0


def _boot_rows(cid: np.ndarray, sid: np.ndarray, rng: np.random.Generator, n: int) -> list[np.ndarray]:
    groups = [np.unique(cid[sid == k]) for k in np.unique(sid)]
    idx_of = {c: np.flatnonzero(cid == c) for c in np.unique(cid)}
    out = []
    for _ in range(n):
        pick = np.concatenate([rng.choice(g, g.size, replace=True) for g in groups])
        out.append(np.concatenate([idx_of[c] for c in pick]))
    return out


class Judge:
    """Held-out figures of any fit on one problem, with one fixed set of bootstrap resamples (so differences
    between models are paired), in the predictive spreads of one `reference` fit (the nominal; without one, each
    fit in its own)."""

    def __init__(self, p: Problem, seed: int = 0, reference: Fit | None = None) -> None:
        self.p = p
        self.folds = folds(p)
        self.specimens = specimen_folds(p)
        cid, sid = condition_ids(p), strata(p)
        rows = _boot_rows(cid, sid, np.random.default_rng(seed), N_BOOT)
        n = p.y.size
        # a resample of rows takes both of a row's held-out z (condition and specimen) together
        self.resamples = [np.r_[r, r + n] for r in rows] if self.specimens else rows
        self.spread: np.ndarray | None = None
        if reference is not None:
            e, self.spread = self._errors(reference)
            reference.extra["heldout_z"] = e / self.spread      # judged once: its own spreads are the units

    def z(self, fit: Fit) -> np.ndarray:
        """Held-out z per row: the condition folds', then (with two or more specimens) the specimen folds'.
        Computed on one BLAS thread, as in the fit workers (`fitpool`), so the figures do not depend on where
        they were computed (a thread count changes a pseudo-inverse's last digits, and with them its cut)."""
        if "heldout_z" not in fit.extra:
            e, spread = self._errors(fit)
            z = e / (spread if self.spread is None else self.spread)
            fit.extra["heldout_z"] = z
        return fit.extra["heldout_z"]

    def _errors(self, fit: Fit) -> tuple[np.ndarray, np.ndarray]:
        """Held-out errors (noise units) and the fit's own predictive spreads, condition folds then specimen
        folds; keeps the fold steps in `fit.extra` (the strength jackknife reads them)."""
        with threadpool_limits(limits=1):
            e, spread, fit.extra["fold_steps"] = heldout_errors(fit, self.folds)
            if self.specimens:
                es, ss = specimen_errors(self.p, fit, self.specimens)
                e, spread = np.r_[e, es], np.r_[spread, ss]
        return e, spread

    def heldout(self, fit: Fit) -> HeldOut:
        z = self.z(fit)
        boot = np.array([rms(z[r]) for r in self.resamples])
        return HeldOut(rms(z), (float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))))

    def reduction_ci(self, base: Fit, new: Fit) -> tuple[float, float]:
        """Bootstrap 95 % interval of 1 - RMS(new) / RMS(base) on the held-out z (paired resamples)."""
        zb, zn = self.z(base), self.z(new)
        boot = np.array([1.0 - rms(zn[r]) / max(rms(zb[r]), 1e-300) for r in self.resamples])
        return float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))

    def difference_ci(self, a: Fit, b: Fit) -> tuple[float, float]:
        """Bootstrap 95 % interval of mean(z_a^2) - mean(z_b^2) held out (paired)."""
        za, zb = self.z(a), self.z(b)
        boot = np.array([float(np.mean(za[r] ** 2) - np.mean(zb[r] ** 2)) for r in self.resamples])
        return float(np.percentile(boot, 2.5)), float(np.percentile(boot, 97.5))
