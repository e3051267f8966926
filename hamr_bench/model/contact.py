"""Foot contact with Coulomb friction: what a vertical-axis force sensor reads when the foot presses on it.

The leg rotates about the lift hip axis, so the foot moves on an arc: with the hip-to-foot line beta below
horizontal, a small rotation moves the foot vertically by L cos(beta) and sideways by L sin(beta). A flat
horizontal load button holding the foot at a height therefore also stops (or resists) that sideways motion. With
the leg's generalised force Q (torque about the hip) balanced by the contact's normal force N (vertical, what the
sensor reads) and friction T (horizontal, |T| <= mu N, opposing the slide), virtual work gives

    Q = N L cos(beta) + s mu N L sin(beta)    ->    N / N0 = 1 / (1 + s mu tan(beta))

with N0 = Q / (L cos(beta)) the frictionless reading (the model's foot_force_N) and s the slide direction:

    s = +1   the foot slides the way it moves when the leg presses DOWN into the support (the drive ramping up
             against a fixed sensor, the sensor retreating): friction helps hold the leg, the sensor reads LESS;
    s = -1   the support pushes the foot UP (the stage raising the sensor into the foot): friction resists the
             leg's upward rotation, the sensor reads MORE;
    s = 0    no tangential force (frictionless, or a stuck contact carrying no tangential load).

Where 1 + s mu tan(beta) <= 0 the foot wedges (no finite support force moves it): nan. Which way the leg points
(toward or away from the hip's side) does not matter: only |tan(beta)| enters.

Coefficient band (`FOOT_FRICTION_MU_BAND`): the foot is the tip of the carbon-fibre/epoxy leg laminate (with its
Kapton and FR-4 layers) on a metal load button. Dry polymer-composite on steel: carbon-fibre reinforced polymers
0.25-0.35 (Giltrow & Lancaster, "Carbon-fibre reinforced polymers as self-lubricating materials", Proc. IMechE
1967-68, paper 18); polyimide film on steel is of the same order. 0.2-0.3 is taken as the band (issue 17); the pair
was not measured in the paper. The nominal model stays frictionless (mu = 0): the paper's model has no friction
and its Table III fit absorbed whatever its rig had.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from hamr_bench.errors import ModelError

FOOT_FRICTION_MU_BAND = (0.2, 0.3)
PRESSING = 1      # foot slides the way the leg pushes it (down into the support)
LIFTED = -1       # the support pushes the foot up


def friction_reading_ratio(leg_angle_rad: ArrayLike, mu: ArrayLike, foot_sliding: ArrayLike) -> np.ndarray:
    """N / N0: the vertical reading with Coulomb friction over the frictionless one (vectorised; nan = wedged).

    leg_angle_rad: hip-to-foot line below horizontal; mu >= 0; foot_sliding: +1 pressing, -1 lifted, 0 none.
    """
    beta = np.asarray(leg_angle_rad, dtype=float)
    mu = np.asarray(mu, dtype=float)
    s = np.asarray(foot_sliding, dtype=float)
    if np.any(mu < 0):
        raise ModelError(f"friction coefficient mu must be >= 0, got {float(np.min(mu))!r}")
    denom = 1.0 + s * mu * np.abs(np.tan(beta))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(denom > 0, 1.0 / np.where(denom > 0, denom, 1.0), np.nan)
