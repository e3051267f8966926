"""The blocked-force contact: the actuator's tip (free deflection minus its own compliance times the contact
force) against the force sensor, through whatever series springs the rig has, solved exactly for the force.

Series springs, each a deflection as a function of force (forms in neither column of the project's table):
- base compliance: a hyperbolic-sine hardening spring, F = k0 u0 sinh(u / u0) (soft at small load,
  stiffening), or a push/pull-asymmetric spring whose compliance blends between its push and pull values
  through tanh(F / F0);
- sensor compliance: the sensor's own linear spring in series with a Hertzian contact of the tip on the sensor
  button (deflection (F / K_H)^(2/3) while pushing: compliant at light load, stiffer at heavy).
Imperfect grounding is not here: it is the compliant clamp of the cantilever itself (physics.py).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

Deflection = Callable[[np.ndarray], np.ndarray]
NANO17_STIFFNESS_N_PER_M = 1.8e7   # ATI Nano17, Fz (data sheet order of magnitude): negligible beside ~2 kN/m


@dataclass(frozen=True)
class SinhBaseSpring:
    stiffness0_N_per_m: float
    hardening_m: float

    def deflection(self, force_N: np.ndarray) -> np.ndarray:
        return self.hardening_m * np.arcsinh(force_N / (self.stiffness0_N_per_m * self.hardening_m))


@dataclass(frozen=True)
class AsymmetricBaseSpring:
    push_N_per_m: float
    pull_N_per_m: float
    blend_N: float

    def deflection(self, force_N: np.ndarray) -> np.ndarray:
        s = 0.5 * (1.0 + np.tanh(force_N / self.blend_N))
        return force_N * (s / self.push_N_per_m + (1.0 - s) / self.pull_N_per_m)


@dataclass(frozen=True)
class SensorContact:
    """The sensor's spring, plus a Hertzian contact while the tip pushes on the button (None: a flat, bonded
    contact)."""

    stiffness_N_per_m: float = NANO17_STIFFNESS_N_PER_M
    hertz_N_per_m15: float | None = None

    def deflection(self, force_N: np.ndarray) -> np.ndarray:
        u = force_N / self.stiffness_N_per_m
        if self.hertz_N_per_m15 is not None:
            u = u + (np.clip(force_N, 0.0, None) / self.hertz_N_per_m15) ** (2.0 / 3.0)
        return u


def contact_force(free_m: np.ndarray, compliance_m_per_N: np.ndarray | float, gap_m: float,
                  series: Sequence[Deflection], push_only: bool) -> np.ndarray:
    """Force the tip exerts on the sensor: the F solving free - gap = F C + sum(u_j(F)), every term increasing
    in F, so the root lies between 0 and the rigid-support force (free - gap) / C; found by bisection
    (vectorised). A push-only sensor (the tip merely rests on it) reads 0 where the tip would pull away."""
    reach = free_m - gap_m
    c = np.broadcast_to(np.asarray(compliance_m_per_N, float), reach.shape)
    rigid = reach / c
    if not series:
        force = rigid
    else:
        lo, hi = np.minimum(rigid, 0.0), np.maximum(rigid, 0.0)
        for _ in range(48):
            mid = 0.5 * (lo + hi)
            excess = mid * c + sum(u(mid) for u in series) - reach
            lo = np.where(excess < 0.0, mid, lo)
            hi = np.where(excess < 0.0, hi, mid)
        force = 0.5 * (lo + hi)
    return np.clip(force, 0.0, None) if push_only else force
