"""What each protocol measures, as a function of the model: the observation model the fits invert.

The model's own definitions (docs/model.md) are one-sided and idealised; the protocols measure something slightly
different. Exactly:

| protocol / quantity | the recording gives (analysis/dataset.py) | model prediction |
|---|---|---|
| actuator, blocked, force_N | mean force over each high dwell (V_bias = V_drive = V) | F_b(V) + f0_run |
| actuator, free, displacement_m | tip stroke high dwell - low dwell (V_drive V vs 0, bias V) | 2 delta(V) (peak-to-peak) |
| actuator, stiffness, force_N | mean force over the hold, undriven, stage pushed sag_m past contact | max(0, k_act sag + f0_run) |
| blocked-force / sag-sweep, force_N | mean force over each high dwell | max(0, foot_force_N(V, V, sag + h0_run)) |
| free-displacement, displacement_m | foot stroke high dwell - low dwell | free_foot_height(V, 0) - free_foot_height(V, V) |
| static, force_N | mean force over the hold, undriven | max(0, foot_force_N(0, 0, sag + h0_run)) |

- Zero sag is where the contact search stopped: the force fell below its release threshold (a fraction of a mN,
  read through sensor noise and quantisation), one fine step after the last reading above it. So the surface may
  still press a little or have backed off into a small gap; which, the recording cannot say (a gap reads 0). Each
  run with a contact search therefore gets its own offset, a nuisance parameter of the fit: for the leg the foot
  height at nominal zero sag, h0_run (the surface holds the foot at h = sag + h0_run); for the actuator the force
  at the tip's zero, f0_run = -k_act x0 (the tip force is linear in its deflection, so this is exact). The
  preload_N the dataset reports (force over the last contact-search reading) is NOT used: it is biased (a gap
  reads as zero) and noisier than what the driven data say about the offset.
- The sensor cannot pull: a negative model force (the leg would lift off) is measured as 0.
- The low dwell of the free-displacement drive is V_drive = 0 with the bias held at V, which LIFTS the foot: the
  camera's stroke is peak-to-peak, about twice the model's one-sided `free_displacement_m(V)`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from hamr_bench.model import ActuatorParams, DesignParams, Powertrain
from hamr_bench.model import actuator as act


def actuator_prediction(a: ActuatorParams, mode: np.ndarray, voltage_V: np.ndarray, offset_N: np.ndarray,
                        push_m: np.ndarray | None = None) -> np.ndarray:
    """Predicted actuator-protocol observation per row (force for 'blocked', stroke for 'free', undriven force for
    'stiffness' at `push_m` past contact: k_act = c / s, the tip's stiffness); `offset_N` is the run's f0 (force
    at the tip's zero) per row. Any other mode is nan (never silently taken for 'free')."""
    c = act.force_per_volt(a)
    s = act.displacement_per_volt(a)
    v = np.asarray(voltage_V, float)
    mode = np.asarray(mode)
    offset = np.asarray(offset_N, float)
    blocked = np.maximum(c * v + offset, 0.0)
    free = 2.0 * s * v
    out = np.where(mode == "blocked", blocked, np.where(mode == "free", free, np.nan))
    if push_m is not None:
        stiff = np.maximum(c / s * np.asarray(push_m, float) + offset, 0.0)
        out = np.where(mode == "stiffness", stiff, out)
    return out


class LegObservations:
    """Vectorised leg-protocol predictions for a fixed set of observation rows (built once, evaluated per fit step).
    `offset_m(...)` per row is the run's h0 (foot height at nominal zero sag)."""

    def __init__(self, protocol: ArrayLike, voltage_V: ArrayLike, sag_m: ArrayLike) -> None:
        self.protocol = np.asarray(protocol)
        self.voltage_V = np.asarray(voltage_V, float)
        self.sag_m = np.asarray(sag_m, float)
        self.is_force_driven = np.isin(self.protocol, ("blocked-force", "sag-sweep"))
        self.is_free = self.protocol == "free-displacement"
        self.is_static = self.protocol == "static"

    def predict(self, p: Powertrain, offset_m: np.ndarray | float = 0.0) -> np.ndarray:
        out = np.full(self.voltage_V.shape, np.nan)
        h = self.sag_m + np.broadcast_to(np.asarray(offset_m, float), self.sag_m.shape)
        m = self.is_force_driven
        if np.any(m):
            v = self.voltage_V[m]
            out[m] = np.maximum(p.foot_force_N(v, v, h[m]), 0.0)
        m = self.is_static
        if np.any(m):
            out[m] = np.maximum(p.foot_force_N(0.0, 0.0, h[m]), 0.0)
        m = self.is_free
        if np.any(m):
            v = self.voltage_V[m]
            n = v.size
            heights = p.free_foot_height_m(np.r_[v, v], np.r_[np.zeros(n), v])
            out[m] = heights[:n] - heights[n:]
        return out


def leg_prediction(a: ActuatorParams, d: DesignParams, protocol: Sequence[str], voltage_V: Sequence[float],
                   sag_m: Sequence[float], offset_m: np.ndarray | float = 0.0) -> np.ndarray:
    """Convenience: predictions for leg-protocol rows with actuator `a` and design `d` (no effects)."""
    return LegObservations(protocol, voltage_V, sag_m).predict(Powertrain(a, d), offset_m)


def fit_zero_sag_offset_m(p: Powertrain, obs: LegObservations, y: np.ndarray, bound_m: float = 0.5e-3) -> float:
    """The one h0 that best fits rows `y` of one run with the transmission held fixed (held-out checks)."""
    from scipy.optimize import minimize_scalar

    def cost(h: float) -> float:
        r = obs.predict(p, h) - y
        return float(np.nansum(r * r)) if np.isfinite(r).any() else 1e9

    return float(minimize_scalar(cost, bounds=(-bound_m, bound_m), method="bounded",
                                 options={"xatol": 1e-8}).x)
