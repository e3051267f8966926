"""Lift transmission kinematics: an offset slider-crank (four-bar with the actuator tip as the slider) whose crank
drives the leg, with three flexure joints. Pure, vectorised functions of the crank angle theta.

Coordinates (SI): the crank pivots about the hip axis at the origin; crank radius r; the actuator tip (slider)
moves along the line y = e (offset) at x(theta); the coupler ("input link", the part the bias lengthens) has
length l. theta is the crank angle from the +x axis (the slider side).

    s(theta)      = r sin(theta) - e
    x(theta)      = r cos(theta) + sqrt(l^2 - s^2)           slider position
    psi(theta)    = -asin(s / l)                              coupler angle
    delta_tra     = x_ref - x(theta)                          transmission input, positive toward the hip, which is
                                                              the direction the actuator pushes when V_drive = V_bias
    Phi_1 = psi - psi_fab                 joint 1: coupler / actuator tip (the tip does not rotate)
    Phi_2 = (theta - theta_fab) - Phi_1   joint 2: crank / coupler (relative rotation)
    Phi_3 = theta - theta_fab             joint 3: crank / ground (hip)

The flexures are straight (Phi = 0) in the fabricated configuration: crank at theta_fab and the coupler at the
angle it has there. The leg is rigid with the crank (the spherical five-bar's lift output is taken as a unit
rotation of the lift hip link); the foot is at distance L from the lift axis and its height is

    h(theta) = L [sin(alpha_0) - sin(alpha_0 + theta - theta_fab)]     (positive UP; theta increasing = foot down)

R_tra = d delta_leg / d delta_tra with delta_leg = -h (downward leg travel), so R_tra > 0 in the operating range.
Every derivative is analytic; tests check them against finite differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from hamr_bench.errors import ModelError


@dataclass(frozen=True)
class SliderCrankGeometry:
    """The lift transmission geometry shared by all designs (the bias changes only the coupler length)."""

    crank_m: float            # r
    coupler_m: float          # l, unbiased input link
    offset_m: float           # e, slider line offset from the hip axis
    theta_fab_rad: float      # crank angle in the fabricated (flat-flexure) configuration
    leg_length_m: float       # L, foot distance from the lift axis
    leg_angle0_rad: float = 0.0  # leg angle from horizontal at theta_fab (0: sine mapping about horizontal)

    def __post_init__(self) -> None:
        for name in ("crank_m", "coupler_m", "leg_length_m"):
            v = getattr(self, name)
            if not np.isfinite(v) or v <= 0:
                raise ModelError(f"transmission geometry {name} must be positive, got {v!r}")
        check_closes(self, self.coupler_m, self.theta_fab_rad)


def check_closes(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> None:
    """Raise ModelError if the linkage cannot be assembled (|r sin(theta) - e| >= l) at any given angle."""
    th = np.atleast_1d(np.asarray(theta_rad, dtype=float))
    s = g.crank_m * np.sin(th) - g.offset_m
    if coupler_m <= 0 or np.any(np.abs(s) >= coupler_m):
        i = int(np.argmax(np.abs(s)))
        raise ModelError(
            f"transmission geometry cannot close: coupler_m={coupler_m:.6g} <= |crank_m sin(theta) - offset_m|="
            f"{abs(float(s[i])):.6g} at theta={float(th[i]):.4g} rad")


def _sq(g: SliderCrankGeometry, coupler_m: float, theta: np.ndarray):
    s = g.crank_m * np.sin(theta) - g.offset_m
    arg = coupler_m**2 - s**2
    q = np.sqrt(np.where(arg > 0, arg, np.nan))
    return s, q


def slider_x_m(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    th = np.asarray(theta_rad, dtype=float)
    _, q = _sq(g, coupler_m, th)
    return g.crank_m * np.cos(th) + q


def slider_dx_dtheta(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    th = np.asarray(theta_rad, dtype=float)
    s, q = _sq(g, coupler_m, th)
    return -g.crank_m * np.sin(th) - s * g.crank_m * np.cos(th) / q


def coupler_angle_rad(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    th = np.asarray(theta_rad, dtype=float)
    s = g.crank_m * np.sin(th) - g.offset_m
    return -np.arcsin(s / coupler_m)


def coupler_dangle_dtheta(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    th = np.asarray(theta_rad, dtype=float)
    _, q = _sq(g, coupler_m, th)
    return -g.crank_m * np.cos(th) / q


def reference_slider_x_m(g: SliderCrankGeometry) -> float:
    """Where the undeflected actuator tip sits: the slider position of the fabricated, unbiased linkage."""
    return float(slider_x_m(g, g.coupler_m, g.theta_fab_rad))


def delta_tra_m(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    """Transmission input displacement from the undeflected actuator tip (positive toward the hip)."""
    return reference_slider_x_m(g) - slider_x_m(g, coupler_m, theta_rad)


def ddelta_tra_dtheta(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    return -slider_dx_dtheta(g, coupler_m, theta_rad)


def joint_angles_rad(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    """Phi_1..3 (leading axis of length 3), zero in the fabricated configuration of this coupler."""
    th = np.asarray(theta_rad, dtype=float)
    psi_fab = coupler_angle_rad(g, coupler_m, g.theta_fab_rad)
    phi1 = coupler_angle_rad(g, coupler_m, th) - psi_fab
    phi3 = th - g.theta_fab_rad
    phi2 = phi3 - phi1
    return np.stack([phi1, phi2, phi3])


def joint_dangles_dtheta(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    th = np.asarray(theta_rad, dtype=float)
    d1 = coupler_dangle_dtheta(g, coupler_m, th)
    d3 = np.ones_like(th)
    return np.stack([d1, d3 - d1, d3])


def foot_height_fab_m(g: SliderCrankGeometry, theta_rad: ArrayLike) -> np.ndarray:
    """Foot height relative to the fabricated configuration, positive up."""
    th = np.asarray(theta_rad, dtype=float)
    a0 = g.leg_angle0_rad
    return g.leg_length_m * (np.sin(a0) - np.sin(a0 + th - g.theta_fab_rad))


def dfoot_height_dtheta(g: SliderCrankGeometry, theta_rad: ArrayLike) -> np.ndarray:
    th = np.asarray(theta_rad, dtype=float)
    return -g.leg_length_m * np.cos(g.leg_angle0_rad + th - g.theta_fab_rad)


def theta_from_foot_height(g: SliderCrankGeometry, h_fab_m: ArrayLike) -> np.ndarray:
    """Inverse of foot_height_fab_m on the branch |alpha_0 + theta - theta_fab| < pi/2."""
    h = np.asarray(h_fab_m, dtype=float)
    arg = np.sin(g.leg_angle0_rad) - h / g.leg_length_m
    if np.any(np.abs(arg) > 1):
        raise ModelError(f"foot height {float(np.max(np.abs(h))):.4g} m is beyond the leg length "
                         f"{g.leg_length_m:.4g} m")
    return np.arcsin(arg) - g.leg_angle0_rad + g.theta_fab_rad


def transmission_ratio(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    """R_tra = d delta_leg / d delta_tra (delta_leg downward), dimensionless."""
    return -dfoot_height_dtheta(g, theta_rad) / ddelta_tra_dtheta(g, coupler_m, theta_rad)


def joint_dangles_ddelta_tra(g: SliderCrankGeometry, coupler_m: float, theta_rad: ArrayLike) -> np.ndarray:
    """dPhi_i / d delta_tra (1/m), shape (3, ...)."""
    return joint_dangles_dtheta(g, coupler_m, theta_rad) / ddelta_tra_dtheta(g, coupler_m, theta_rad)
