"""Kapton flexure strips of the lift transmission: pseudo-rigid-body stiffness, Euler buckling and the post-buckled
(elastica) load-shortening law, and the serial chain that carries the coupler load through the buckled strips.

A PC-MEMS flexure joint is the exposed gap of the polyimide layer between two rigid carbon-fibre links: a strip of
thickness t (the Kapton film, 12.5 or 25 um), width w (across the joint) and free length L (the gap). Its rotational
stiffness in the pseudo-rigid-body approximation (Howell, "Compliant Mechanisms", small-length flexural pivot) is

    kappa = E I / L,   I = w t^3 / 12

The coupler (the input link the bias lengthens) carries the actuator's push as an axial compression through the
strips of joints 1 and 2. A strip under compression P buckles at the Euler load

    P_cr = pi^2 E I / (K L)^2

with K = 1 for the guided (S-shaped) mode: both ends stay clamped to their links, which may shift sideways relative
to each other (the lowest mode a strip between two rigid links can take; clamped-clamped without sway is K = 0.5,
four times the load). Past P_cr the strip follows the elastica (Timoshenko & Gere, Theory of Elastic Stability,
sec. 2.7; modulus m = sin^2(alpha/2) of the end slope alpha):

    P / P_cr = (2 K(m) / pi)^2,   shortening / L = 2 (1 - E(m) / K(m))

(complete elliptic integrals K, E; this holds per unit length for any number of half-waves, so K enters only
through P_cr). For small post-buckling, P ~ P_cr (1 + shortening / 2L): a plateau with a finite slope.

Everything here is SI (m, N, Pa, N m/rad). Material: Kapton HN, E = 2.5 GPa at 23 C (DuPont Kapton HN data sheet,
tensile modulus 2.5 GPa; 2.0 GPa at 200 C).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike
from scipy.special import ellipe, ellipk

from hamr_bench.errors import ModelError

KAPTON_MODULUS_PA = 2.5e9
# The flexures' planform is not published. The band every estimate uses (issue 17; HAMR PC-MEMS joints): width
# 1.5-2 mm, free length 100-200 um. The nominal strip is the middle of that band.
FLEXURE_WIDTH_BAND_M = (1.5e-3, 2.0e-3)
FLEXURE_LENGTH_BAND_M = (100e-6, 200e-6)
NOMINAL_FLEXURE_WIDTH_M = 1.75e-3
NOMINAL_FLEXURE_LENGTH_M = 150e-6
GUIDED_END_FACTOR = 1.0          # K of the S-shaped (guided) mode
COUPLER_STRIPS = 2               # joints 1 and 2 carry the coupler load in series

# Elastica table: modulus m from 0 (onset) to 0.995 (end slope ~170 deg: the strip folded onto itself). Nodes are
# denser near the onset, where the load-shortening curve bends most.
_M = np.concatenate([np.linspace(0.0, 0.05, 60, endpoint=False), np.linspace(0.05, 0.995, 140)])
_LOAD_RATIO = (2.0 * ellipk(_M) / np.pi) ** 2                 # P / P_cr
_SHORTENING_RATIO = 2.0 * (1.0 - ellipe(_M) / ellipk(_M))      # shortening / L


@dataclass(frozen=True)
class FlexureStrip:
    """One Kapton flexure strip. Lengths in m, modulus in Pa."""

    thickness_m: float
    width_m: float = NOMINAL_FLEXURE_WIDTH_M
    length_m: float = NOMINAL_FLEXURE_LENGTH_M
    modulus_Pa: float = KAPTON_MODULUS_PA
    end_factor: float = GUIDED_END_FACTOR

    def __post_init__(self) -> None:
        for name in ("thickness_m", "width_m", "length_m", "modulus_Pa", "end_factor"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ModelError(f"flexure strip {name} must be positive and finite, got {v!r}")

    @property
    def second_moment_m4(self) -> float:
        return self.width_m * self.thickness_m**3 / 12.0

    @property
    def prb_stiffness_N_m_per_rad(self) -> float:
        """Pseudo-rigid-body rotational stiffness E I / L."""
        return self.modulus_Pa * self.second_moment_m4 / self.length_m

    @property
    def euler_load_N(self) -> float:
        return float(np.pi**2 * self.modulus_Pa * self.second_moment_m4 / (self.end_factor * self.length_m) ** 2)

    def post_buckling_load_N(self, shortening_m: ArrayLike) -> np.ndarray:
        """Axial compression of the buckled strip at a given end shortening (elastica; P_cr at 0)."""
        s = np.asarray(shortening_m, dtype=float) / self.length_m
        return self.euler_load_N * _interp_extrapolated(s, _SHORTENING_RATIO, _LOAD_RATIO)

    def shortening_m(self, load_N: ArrayLike) -> np.ndarray:
        """End shortening under compression `load_N` (0 below the Euler load; the strip's axial strain, ~1e-4 of
        L at these loads, is neglected)."""
        r = np.asarray(load_N, dtype=float) / self.euler_load_N
        return self.length_m * np.where(r <= 1.0, 0.0, _interp_extrapolated(r, _LOAD_RATIO, _SHORTENING_RATIO))


def _interp_extrapolated(x: np.ndarray, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """np.interp with linear extrapolation past the last node (the table ends before the strip self-contacts)."""
    slope = (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
    return np.where(x <= xs[-1], np.interp(x, xs, ys), ys[-1] + slope * (x - xs[-1]))


def prb_band_N_m_per_rad(thickness_m: float, modulus_Pa: float = KAPTON_MODULUS_PA) -> tuple[float, float]:
    """(lowest, highest) pseudo-rigid-body stiffness over the width and length band (narrow-long, wide-short)."""
    lo = FlexureStrip(thickness_m, FLEXURE_WIDTH_BAND_M[0], FLEXURE_LENGTH_BAND_M[1], modulus_Pa)
    hi = FlexureStrip(thickness_m, FLEXURE_WIDTH_BAND_M[1], FLEXURE_LENGTH_BAND_M[0], modulus_Pa)
    return lo.prb_stiffness_N_m_per_rad, hi.prb_stiffness_N_m_per_rad


class SerialChain:
    """The load path from the actuator's free tip to the transmission input: actuator spring and the linear serial
    compliance (k_eff = A k_act, paper eq. 3) in series with `n_strips` identical strips that buckle in compression.

    `gap` = u - delta_tra (the overlap the chain must absorb; > 0 = the actuator pushes, the coupler is compressed).
    force_N(gap) is the chain force, energy_J(gap) its stored energy (the exact integral of force_N, so that the
    model stays a potential). Below the strips' Euler load it is k_eff gap exactly; in tension the strips are
    rigid. Past the Euler load the gap is gap = F / k_eff + n shortening(F); the curve is tabulated on the elastica
    nodes and interpolated linearly in gap (energy piecewise quadratic).
    """

    def __init__(self, k_eff_N_per_m: float, strip: FlexureStrip, n_strips: int = COUPLER_STRIPS) -> None:
        self.k_eff_N_per_m = float(k_eff_N_per_m)
        self.strip = strip
        self.n_strips = int(n_strips)
        self.buckling_load_N = strip.euler_load_N
        self.buckling_gap_m = self.buckling_load_N / self.k_eff_N_per_m
        force = self.buckling_load_N * _LOAD_RATIO
        gap = force / self.k_eff_N_per_m + self.n_strips * strip.length_m * _SHORTENING_RATIO
        # one far node on the last slope so interpolation never clamps
        slope = (force[-1] - force[-2]) / (gap[-1] - gap[-2])
        far = gap[-1] + 10.0 * gap[-1]
        self._gap = np.append(gap, far)
        self._force = np.append(force, force[-1] + slope * (far - gap[-1]))
        seg = 0.5 * (self._force[1:] + self._force[:-1]) * np.diff(self._gap)
        self._energy = 0.5 * self.k_eff_N_per_m * self.buckling_gap_m**2 + np.concatenate([[0.0], np.cumsum(seg)])
        self._slope = np.diff(self._force) / np.diff(self._gap)

    def force_N(self, gap_m: ArrayLike) -> np.ndarray:
        g = np.asarray(gap_m, dtype=float)
        f = self.k_eff_N_per_m * g
        # on the hot path most conditions stay below the Euler load: interpolate only the buckled ones
        buckled = g > self.buckling_gap_m
        if buckled.any():
            f = np.where(buckled, np.interp(g, self._gap, self._force), f)
        return f

    def energy_J(self, gap_m: ArrayLike) -> np.ndarray:
        g = np.asarray(gap_m, dtype=float)
        i = np.clip(np.searchsorted(self._gap, g, side="right") - 1, 0, self._gap.size - 2)
        dg = g - self._gap[i]
        buckled = self._energy[i] + self._force[i] * dg + 0.5 * self._slope[i] * dg * dg
        return np.where(g <= self.buckling_gap_m, 0.5 * self.k_eff_N_per_m * g * g, buckled)

    @cached_property
    def post_buckling_slope_N_per_m(self) -> float:
        """Chain stiffness just past the onset (P_cr / 2L per strip in series with k_eff)."""
        return float(self._slope[0])
