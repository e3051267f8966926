"""Specimen-to-specimen scatter: several specimens of one build (three actuators of one layer count, say) differ
in their nominal parameters by fabrication. That scatter is neither noise nor lack of fit nor an effect: the fit
fits each specimen on its own (per-specimen parameters) and reports the POPULATION: the mean over specimens, the
95 % interval of that mean (Student t with n - 1 degrees of freedom: the specimens are the sample), the
between-specimen standard deviation (the paper's error bars: "the standard deviation of ... 3 actuators"), and
tau, the part of that spread beyond each specimen's own estimation error (a random-effects estimate:
tau^2 = max(0, sample variance - mean squared standard error)).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats


def population(values: list[float], standard_errors: list[float] | None = None,
               level: float = 0.95) -> dict[str, Any] | None:
    """Mean, its interval, the between-specimen SD and tau of per-specimen estimates (None with fewer than 2)."""
    v = np.asarray([x for x in values if math.isfinite(x)], dtype=float)
    if v.size < 2:
        return None
    mean = float(v.mean())
    sd = float(v.std(ddof=1))
    half = float(stats.t.ppf(0.5 + 0.5 * level, v.size - 1)) * sd / math.sqrt(v.size)
    se = np.asarray([x for x in (standard_errors or []) if math.isfinite(x)], dtype=float)
    tau = math.sqrt(max(0.0, sd**2 - float(np.mean(se**2)))) if se.size == v.size else math.nan
    return {"value": mean, "ci95": [mean - half, mean + half], "between_specimen_sd": sd,
            "tau": tau if math.isfinite(tau) else None, "n_specimens": int(v.size)}


def standard_error(entry: dict[str, Any], level: float = 0.95) -> float:
    """A per-specimen estimate's standard error from its interval (half-width / the normal quantile: an
    approximation when the interval is a t interval, conservative by the ratio of the two quantiles)."""
    ci = entry.get("ci95")
    if not ci or ci[0] is None or ci[1] is None:
        return math.nan
    return (float(ci[1]) - float(ci[0])) / 2.0 / float(stats.norm.ppf(0.5 + 0.5 * level))
