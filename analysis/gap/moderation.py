"""Pure-error moderation: each run's cycle-to-cycle variance of a window, shrunk toward what the lab's other runs
show for the same window (empirical Bayes, Smyth 2004, the "squeezed" variances of limma).

A row's standard error comes from a handful of cycles: a run of 8 cycles gives its window's variance 7 degrees of
freedom, so an exact model's z scatters as Student's t with 7 dof (RMS 1.18, not 1), and a run whose cycles
happened to agree gets a tiny standard error that a fit then chases. Every run's windows of one kind (fixture,
quantity, phase) are measured by the same sensor through the same chain, so their variances are samples around
a common level; how far they spread beyond what their dof alone would give says how much they truly differ. The
moderated variance is

    s~^2 = (d0 s0^2 + d s^2) / (d0 + d)

with s0^2 the level (a linear trend in log |V_bias| where the runs span three or more voltages: a ramp window's
scatter grows with the ramp's slope) and d0 the prior degrees of freedom, both estimated from the runs: d0 is
infinite when the variances spread no more than sampling alone would (they are then all the level), and small
when they truly differ (each run keeps its own). A window kind seen in fewer than three runs is left as it is."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import optimize, special

MIN_UNITS = 3        # runs of one window kind needed to estimate a level and its spread
MIN_TREND_UNITS = 6  # ... and to fit a trend in voltage as well (on three or more distinct voltages)


@dataclass(frozen=True)
class Squeezed:
    variance: np.ndarray    # moderated variance per unit
    prior_dof: float        # d0 (inf: every unit at the level)
    trend: bool             # whether the level follows log |V_bias|


def _trigamma_inverse(v: float) -> float:
    """y > 0 with trigamma(y) = v (trigamma decreases from +inf to 0)."""
    f = lambda log_y: float(special.polygamma(1, math.exp(log_y))) - v  # noqa: E731
    return math.exp(optimize.brentq(f, -30.0, 30.0, xtol=1e-10))


def squeeze(variance: np.ndarray, dof: np.ndarray, covariate: np.ndarray | None = None) -> Squeezed:
    """Moderated variances of units with sample variances `variance` on `dof` degrees of freedom each.
    Units with dof 0 or a variance that is 0 or not finite take the level alone and do not inform it."""
    s2 = np.asarray(variance, float)
    d = np.asarray(dof, float)
    ok = np.isfinite(s2) & (s2 > 0) & (d > 0)
    if ok.sum() < MIN_UNITS:
        return Squeezed(s2.copy(), 0.0, False)
    # log s^2 is biased by digamma(d/2) - log(d/2) and spreads by trigamma(d/2) from sampling alone
    e = np.log(s2[ok]) - special.digamma(d[ok] / 2) + np.log(d[ok] / 2)
    x = np.zeros(s2.size) if covariate is None else np.asarray(covariate, float)
    trend = bool(ok.sum() >= MIN_TREND_UNITS and np.unique(np.round(x[ok], 6)).size >= 3)
    design = np.column_stack([np.ones(s2.size), x]) if trend else np.ones((s2.size, 1))
    coef, *_ = np.linalg.lstsq(design[ok], e, rcond=None)
    resid = e - design[ok] @ coef
    excess = float(resid @ resid) / (ok.sum() - design.shape[1]) - float(np.mean(special.polygamma(1, d[ok] / 2)))
    # below ~1e-12 the spread beyond sampling is nil to double precision (and past trigamma's bracket)
    d0 = 2.0 * _trigamma_inverse(excess) if excess > 1e-12 else math.inf
    log_level = design @ coef
    if math.isfinite(d0):
        level = np.exp(log_level + special.digamma(d0 / 2) - math.log(d0 / 2))
        post = np.where(ok, (d0 * level + d * np.where(ok, s2, 0.0)) / (d0 + d), level)
    else:
        post = np.exp(log_level)
    return Squeezed(post, d0, trend)
