"""Screening: each candidate's signature (the change of the z-residual per unit strength at zero strength, with
the nuisance directions (zero offsets, and for drift its own slopes) projected out), its score-test statistic
against the nominal residual, and the angles between signatures: |cos| near 1 = this data cannot tell the two
effects apart at first order."""

from __future__ import annotations

import numpy as np
from scipy import stats

from analysis.gap.library import CANDIDATES
from analysis.gap.problem import Problem

# finite-difference steps (small against realistic strengths, large against round-off)
STEP = {"field_dependent_d31": 0.02, "hysteresis": 0.01, "creep": 0.003, "base_compliance": 0.02,
        "sensor_compliance": 5e-5, "width_loss": 0.02, "bias_error": 3e-6, "stage_backlash": 2e-6}


def _project_out(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    if a.shape[1] == 0:
        return v
    coef, *_ = np.linalg.lstsq(a, v, rcond=None)
    return v - a @ coef


def signatures(problem: Problem, names: list[str], z0: np.ndarray) -> dict[str, np.ndarray]:
    a = problem.design([])
    m0 = problem.model({})
    out = {}
    for n in names:
        if n == "sensor_drift":
            d = problem._drift_cols
            if d.shape[1] == 0:
                continue
            # the drift subspace's best single direction for this residual
            proj = _project_out(a, d)
            coef, *_ = np.linalg.lstsq(proj, z0, rcond=None)
            out[n] = proj @ coef
            continue
        h = STEP[n]
        dm = (problem.model({n: h}) - m0) / h / problem.sigma
        out[n] = _project_out(a, -np.nan_to_num(dm))   # a positive strength moves z by -dm
    return out


def screen(problem: Problem, z0: np.ndarray, names: list[str] | None = None) -> dict:
    names = names or list(CANDIDATES)
    sig = signatures(problem, names, z0)
    scores = {}
    for n, s in sig.items():
        ss = float(s @ s)
        if ss <= 0:
            scores[n] = {"score_chi2": 0.0, "p_value": 1.0}
            continue
        df = problem._drift_cols.shape[1] if n == "sensor_drift" else 1
        chi2 = float((s @ z0) ** 2 / ss)
        scores[n] = {"score_chi2": chi2, "p_value": float(stats.chi2.sf(chi2, df))}
    keys = list(sig)
    cos = {}
    for i, a in enumerate(keys):
        for b in keys[i + 1:]:
            na, nb = np.linalg.norm(sig[a]), np.linalg.norm(sig[b])
            cos[(a, b)] = float(abs(sig[a] @ sig[b]) / (na * nb)) if na > 0 and nb > 0 else 0.0
    return {"scores": scores, "cos": cos, "signatures": sig}


def confusable_pairs(cos: dict, threshold: float = 0.95) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    for (a, b), c in cos.items():
        if c >= threshold:
            out.setdefault(a, []).append(b)
            out.setdefault(b, []).append(a)
    return out
