"""What the seed paper does not publish, as bands, and the model one choice of those quantities implies.

`Unpublished` holds one value of each; `Unpublished()` is the nominal model (the presets everything else uses).

| quantity | nominal | band | why it is uncertain |
|---|---|---|---|
| carbon-fibre modulus E_c | 340 GPa | 200-340 GPa | high- vs standard-modulus prepreg; the paper gives none |
| actuator length ratio l_r | 0.0063 | 0.0063-0.1 | Table I prints 0.0063; Wood et al.'s optimal designs use ~0.1 |
| link geometry | designs.GEOMETRIES | each +-1 % (robustness.perturbation_steps) | unpublished; fabrication |
| foot friction mu | 0 (frictionless) | 0.2-0.3 | contact.FOOT_FRICTION_MU_BAND; not in the paper's model |
| flexure planform w, L | 1.75 mm, 150 um | 1.5-2 mm, 100-200 um | flexures.py; sets the strips' Euler load |

Friction and the fit: the paper fitted Table III with a frictionless model to readings taken with whatever friction
its rig had, so a friction that scaled every reading of a design alike is already inside k_ser. With
`friction_absorbed` (the default), a reading is therefore the frictionless force times the friction ratio at that
design's zero-sag contact over the ratio at its own contact: friction changes how the reading varies with sag (the
leg angle changes), not its level at the fit's anchor. `friction_absorbed=False` applies the ratio outright (the
reading the model would predict if Table III had been fitted without friction in the data); `hamr-bench paper`
shows both. The foot slides `PRESSING` in the paper's tests (each reading follows a drive ramp against a fixed
sensor; contact.py).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from hamr_bench.errors import ModelError
from hamr_bench.model.actuator import E_CF_PA, TABLE_I, ActuatorParams, actuator_preset
from hamr_bench.model.contact import FOOT_FRICTION_MU_BAND, PRESSING, friction_reading_ratio
from hamr_bench.model.designs import DEFAULT_KAPPA_UNITS, GEOMETRIES, design_preset
from hamr_bench.model.flexures import (FLEXURE_LENGTH_BAND_M, FLEXURE_WIDTH_BAND_M, NOMINAL_FLEXURE_LENGTH_M,
                                       NOMINAL_FLEXURE_WIDTH_M)
from hamr_bench.model.powertrain import Powertrain
from hamr_bench.model.robustness import GEOMETRY_KEYS, perturbation_steps
from hamr_bench.model.transmission import SliderCrankGeometry

E_C_BAND_PA = (200e9, 340e9)
LENGTH_RATIO_BAND = (float(TABLE_I["effective"]["length_ratio"]), 0.1)
GEOMETRY_TOLERANCE = 0.01

# name -> (field, low, high, unit label, scale for display): the one-at-a-time sweeps and the Monte-Carlo ranges
SOURCES: dict[str, tuple[str, float, float, str, float]] = {
    "E_c": ("cf_modulus_Pa", *E_C_BAND_PA, "GPa", 1e-9),
    "l_r": ("length_ratio", *LENGTH_RATIO_BAND, "", 1.0),
    "mu": ("friction_mu", *FOOT_FRICTION_MU_BAND, "", 1.0),
    "flexure L": ("flexure_length_m", *FLEXURE_LENGTH_BAND_M, "um", 1e6),
    "flexure w": ("flexure_width_m", *FLEXURE_WIDTH_BAND_M, "mm", 1e3),
}


@dataclass(frozen=True)
class Unpublished:
    """One choice of every unpublished quantity. Defaults = the nominal model."""

    kappa_units: str = DEFAULT_KAPPA_UNITS
    cf_modulus_Pa: float = E_CF_PA
    length_ratio: float = LENGTH_RATIO_BAND[0]
    geometry: SliderCrankGeometry | None = None        # None: the reading's searched geometry
    friction_mu: float = 0.0
    foot_sliding: int = PRESSING
    friction_absorbed: bool = True
    flexure_width_m: float = NOMINAL_FLEXURE_WIDTH_M
    flexure_length_m: float = NOMINAL_FLEXURE_LENGTH_M
    coupler_buckling: bool = True
    unbuildable: str = ""                               # why a drawn geometry cannot be assembled (else "")

    @property
    def link_geometry(self) -> SliderCrankGeometry:
        return GEOMETRIES[self.kappa_units] if self.geometry is None else self.geometry

    def actuator(self, layers: int) -> ActuatorParams:
        a = actuator_preset(layers, "effective")
        if self.cf_modulus_Pa == a.cf_modulus_Pa and self.length_ratio == a.length_ratio:
            return a
        return replace(a, cf_modulus_Pa=self.cf_modulus_Pa, length_ratio=self.length_ratio)

    def design(self, design: int, **changes):
        return design_preset(design, self.kappa_units, self.link_geometry, flexure_width_m=self.flexure_width_m,
                             flexure_length_m=self.flexure_length_m, coupler_buckling=self.coupler_buckling,
                             **changes)

    @cached_property
    def powertrains(self) -> dict[int, Powertrain]:
        """Designs 1..5 on the 2-layer actuator (the paper's choice for the transmission tests)."""
        a = self.actuator(2)
        return {d: Powertrain(a, self.design(d)) for d in range(1, 6)}

    def reading_N(self, p: Powertrain, voltage_V: ArrayLike, sag_m: ArrayLike) -> np.ndarray:
        """What the sensor reads in the blocked-force test (frictionless when mu = 0)."""
        f = p.blocked_force_N(voltage_V, sag_m)
        if self.friction_mu == 0:
            return f
        ratio = friction_reading_ratio(p.leg_angle_rad(p.theta_at_height(sag_m)), self.friction_mu, self.foot_sliding)
        if self.friction_absorbed:
            ratio = ratio / friction_reading_ratio(p.leg_angle_rad(p.theta_neutral_rad), self.friction_mu,
                                                   self.foot_sliding)
        return f * ratio


def draw(n: int, seed: int = 0, base: Unpublished | None = None) -> list[Unpublished]:
    """n joint Monte-Carlo draws: every source uniform over its band, each geometric parameter uniform +-1 %."""
    base = base or Unpublished()
    rng = np.random.default_rng(seed)
    g0 = base.link_geometry
    steps = perturbation_steps(g0, GEOMETRY_TOLERANCE)
    out = []
    for _ in range(n):
        values: dict[str, Any] = {field: rng.uniform(lo, hi) for field, lo, hi, _, _ in SOURCES.values()}
        geometry = {k: getattr(g0, k) + steps[k] * rng.uniform(-1.0, 1.0) for k in GEOMETRY_KEYS}
        try:
            out.append(replace(base, geometry=SliderCrankGeometry(**geometry), **values))
        except ModelError as exc:       # kept, and counted as failing every transmission claim
            out.append(replace(base, unbuildable=str(exc), **values))
    return out
