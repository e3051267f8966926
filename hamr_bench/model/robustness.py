"""How robust a geometry's fitted transmission claims are to fabrication tolerance: every geometric parameter
perturbed by 1 %, one at a time (each up and down) and jointly (Monte-Carlo).

"1 % of a parameter" is 1 % of its magnitude, with a floor where the magnitude is not a length scale of its own:
the slider offset e (which can sit near 0) moves by 1 % of the crank, and the two angles by at least 1 % of a
radian (0.57 deg, the order of a PC-MEMS fold tolerance). Without the floors an offset of 20 um would be "perturbed"
by 0.2 um and the check would say nothing about it.

Margins are the project's own (claims.transmission_margins): > 0 holds; a linkage that cannot be assembled or has
no stable neutral counts as -1.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from hamr_bench.errors import ModelError
from hamr_bench.model.transmission import SliderCrankGeometry

GEOMETRY_KEYS = ("crank_m", "coupler_m", "offset_m", "theta_fab_rad", "leg_length_m", "leg_angle0_rad")
ANGLE_FLOOR_RAD = 1.0


def perturbation_steps(g: SliderCrankGeometry, rel: float = 0.01) -> dict[str, float]:
    """The size of a `rel` perturbation of each geometric parameter (see the module docstring for the floors)."""
    return {
        "crank_m": rel * g.crank_m,
        "coupler_m": rel * g.coupler_m,
        "offset_m": rel * max(abs(g.offset_m), g.crank_m),
        "theta_fab_rad": rel * max(abs(g.theta_fab_rad), ANGLE_FLOOR_RAD),
        "leg_length_m": rel * g.leg_length_m,
        "leg_angle0_rad": rel * max(abs(g.leg_angle0_rad), ANGLE_FLOOR_RAD),
    }


def worst_margin(g: SliderCrankGeometry, kappa_units: str, **design_changes) -> tuple[float, str]:
    """(worst fitted-claim margin, which claim) of one geometry; (-1, reason) if it cannot be built."""
    from hamr_bench.model.claims import powertrains, transmission_figures, transmission_margins

    try:
        with np.errstate(all="ignore"):
            m = transmission_margins(transmission_figures(powertrains(g, kappa_units, **design_changes)))
    except ModelError as exc:
        return -1.0, f"cannot be built ({str(exc).split(':')[0]})"
    key = min(m, key=lambda k: m[k])
    return m[key], key


@dataclass(frozen=True)
class OneAtATime:
    worst: float
    where: str                           # "crank_m +1% -> static_d1"
    margins: dict[str, float]            # "crank_m +1%" -> worst margin with that change


def one_at_a_time(g: SliderCrankGeometry, kappa_units: str, rel: float = 0.01, **design_changes) -> OneAtATime:
    steps = perturbation_steps(g, rel)
    margins: dict[str, float] = {}
    worst, where = np.inf, ""
    for key in GEOMETRY_KEYS:
        for sign in (+1, -1):
            label = f"{key} {'+' if sign > 0 else '-'}{100 * rel:g}%"
            try:
                gp = replace(g, **{key: getattr(g, key) + sign * steps[key]})
            except ModelError:
                m, claim = -1.0, "cannot be assembled"
            else:
                m, claim = worst_margin(gp, kappa_units, **design_changes)
            margins[label] = m
            if m < worst:
                worst, where = m, f"{label} -> {claim}"
    return OneAtATime(float(worst), where, margins)


@dataclass(frozen=True)
class JointMonteCarlo:
    samples: int
    worst: float                         # lowest worst-margin over the samples
    p05: float                           # 5th percentile of the worst margin
    median: float
    fraction_holding: float              # share of samples with every fitted claim holding


def joint_monte_carlo(g: SliderCrankGeometry, kappa_units: str, n: int = 200, rel: float = 0.01, seed: int = 0,
                      **design_changes) -> JointMonteCarlo:
    """Every parameter moved at once, each uniformly within +-rel (its step), n samples."""
    steps = perturbation_steps(g, rel)
    rng = np.random.default_rng(seed)
    out = np.empty(n)
    for i in range(n):
        kw = {k: getattr(g, k) + steps[k] * rng.uniform(-1.0, 1.0) for k in GEOMETRY_KEYS}
        try:
            gp = SliderCrankGeometry(**kw)
        except ModelError:
            out[i] = -1.0
            continue
        out[i] = worst_margin(gp, kappa_units, **design_changes)[0]
    return JointMonteCarlo(n, float(out.min()), float(np.percentile(out, 5)), float(np.median(out)),
                           float(np.mean(out > 0)))
