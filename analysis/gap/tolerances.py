"""Fabrication tolerances and the specimens' scatter: the prior under which each specimen's nominal parameters are
fitted BEFORE any effect is looked for (a random effect), and the parameter maps of the fabrication candidates.

A specimen's deviation from the presets enters as two log gains on its actuator, (a, b): d31 x e^a (the free
stroke and the blocked force together) and width x e^b (the blocked force, i.e. the stiffness, alone). Any small
change of the fabrication parameters moves (log stroke, log stiffness) along these two directions, so the prior of
(a, b) is the tolerances pushed through the closed form's Jacobian: Sigma = J diag(tol^2) J^T. A shift within the
tolerances then costs little; one far beyond them is what an effect is.

The 1-sigma tolerances (fractions), chosen from fabrication practice (docs/gap.md, "Tolerances"):
laser-cut width 2 %, PZT plate thickness 4 % (127 um sheet, +-5 um), effective PZT modulus 5 %, effective d31
8 % (ceramic batches), active length 2 % (clamp alignment), cured carbon-fibre layer 10 %."""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from hamr_bench.model import ActuatorParams
from hamr_bench.model import actuator as act

TOLERANCE: dict[str, float] = {"width": 0.02, "pzt_thickness": 0.04, "pzt_modulus": 0.05, "d31": 0.08,
                               "length": 0.02, "cf_thickness": 0.10}
BAND_SIGMAS = 2.0   # a fabrication shift is an effect only when its interval lies beyond +-2 sigma of tolerance


def scaled(a: ActuatorParams, name: str, s: float) -> ActuatorParams:
    """The actuator with fabrication parameter `name` changed by the fraction s (width: a kerf, see below)."""
    if name in ("width", "width_loss"):
        # constant kerf per cut edge along the tapered plate: the mean width drops by s w, the taper stays
        # (base and tip lose the same); strength s = fraction of the nominal mean width lost
        loss = s * a.width_nom_m
        w = a.width_nom_m - loss
        return act.with_changes(a, width_nom_m=w, width_ratio=(a.width_ratio * a.width_nom_m - loss) / w)
    if name == "pzt_thickness":
        return act.with_changes(a, pzt_thickness_m=a.pzt_thickness_m * (1.0 + s))
    if name == "pzt_modulus":
        return act.with_changes(a, pzt_modulus_Pa=a.pzt_modulus_Pa * (1.0 + s))
    if name in ("length", "grounding_lengthening"):
        # the clamp line moved: the active length changes, the rigid extension (l_r l) keeps its length
        length = a.length_m * (1.0 + s)
        return act.with_changes(a, length_m=length, length_ratio=a.length_ratio * a.length_m / length)
    if name == "cf_thickness":
        return act.with_changes(a, cf_thickness_m=a.cf_thickness_m * (1.0 + s))
    if name == "d31":
        return act.with_changes(a, d31_m_per_V=a.d31_m_per_V * (1.0 + s))
    raise KeyError(name)


def with_gains(a: ActuatorParams, log_d31: float, log_width: float) -> ActuatorParams:
    """A specimen's actuator: d31 x e^a, width x e^b (the two directions every small fabrication change moves)."""
    if log_d31 == 0 and log_width == 0:
        return a
    return dataclasses.replace(a, d31_m_per_V=a.d31_m_per_V * math.exp(log_d31),
                               width_nom_m=a.width_nom_m * math.exp(log_width))


def log_outputs(a: ActuatorParams) -> np.ndarray:
    """(log free stroke per volt, log tip stiffness)."""
    return np.array([math.log(act.displacement_per_volt(a)), math.log(act.stiffness_N_per_m(a))])


def direction(a: ActuatorParams, name: str, step: float = 1e-3) -> np.ndarray:
    """d(log stroke, log stiffness) / d(fractional change of `name`) about `a`."""
    return (log_outputs(scaled(a, name, step)) - log_outputs(scaled(a, name, -step))) / (2 * step)


def gain_prior_cov(a: ActuatorParams) -> np.ndarray:
    """Covariance of the specimen gains (a, b) implied by the tolerances: the gains' own coordinates are (log
    stroke, log stiffness) = (a, b) (d31 moves the stroke alone at fixed stiffness, width the stiffness alone),
    so Sigma = J diag(tol^2) J^T with J the tolerances' directions; a small floor keeps it invertible."""
    j = np.array([direction(a, n) for n in TOLERANCE]).T
    cov = j @ np.diag([t * t for t in TOLERANCE.values()]) @ j.T
    return cov + np.eye(2) * 1e-6


def whitening(a: ActuatorParams) -> np.ndarray:
    """L^-1 with L L^T = Sigma: prior residual rows = L^-1 (a, b)."""
    return np.linalg.inv(np.linalg.cholesky(gain_prior_cov(a)))


def common_shift_sigmas(a: ActuatorParams, whitening: np.ndarray, n_specimens: int, name: str, s: float) -> float:
    """How far a change s of fabrication parameter `name`, common to n specimens, moves their mean gains, in units
    of the tolerance prior's spread of that mean: sqrt(n) x the Mahalanobis length of its (log stroke, log
    stiffness) change (`whitening`: this actuator's, `whitening(a)`)."""
    change = log_outputs(scaled(a, name, s)) - log_outputs(a)
    return math.sqrt(n_specimens) * float(np.linalg.norm(whitening @ change))


def band(name: str, tolerance: float) -> float:
    """Half-width of the tolerance band of a fabrication candidate's strength."""
    return BAND_SIGMAS * tolerance
