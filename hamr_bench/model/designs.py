"""The five transmission designs (paper Table II), their fitted parameters (Table III), the three readings of
Table III's kappa units, and the lift-transmission geometry each reading uses (link lengths are unpublished; see
docs/model.md, "Kappa units and geometry").

Kappa readings (`kappa_units`): Table III prints "N m/rad". Read literally ("printed"), kappa_1 = 0.019-0.023 is
hundreds of times a Kapton flexure's pseudo-rigid-body stiffness; "nmm" reads every entry as N mm/rad (x 1e-3);
"mixed" reads kappa_1 as N mm/rad and kappa_2, kappa_3 as printed, which puts all six fitted values within a few
times the pseudo-rigid-body estimate. The geometry search was run under each reading; each reading has its own
geometry (GEOMETRIES). `hamr-bench paper` re-evaluates all three at run time.

Table III entries printed "< 1e-6" are taken as 0 (an upper bound far below every other term).
Design 5 has no Table III column: it uses design 4's values plus the swing-chain coupling below.
Every design's coupler carries its load through two Kapton strips of its own thickness (flexures.FlexureStrip),
which buckle past their Euler load (`coupler_buckling`, on by default).
"""

from __future__ import annotations

from typing import Any

from dataclasses import dataclass, field, replace

import numpy as np

from hamr_bench.errors import ModelError
from hamr_bench.model.flexures import NOMINAL_FLEXURE_LENGTH_M, NOMINAL_FLEXURE_WIDTH_M, FlexureStrip
from hamr_bench.model.transmission import SliderCrankGeometry

# Table III kappa value x factor = N m/rad, per joint (kappa_1, kappa_2, kappa_3), for each reading of its units.
KAPPA_READINGS: dict[str, tuple[float, float, float]] = {
    "printed": (1.0, 1.0, 1.0),       # as printed: N m/rad
    "nmm": (1e-3, 1e-3, 1e-3),        # every entry in N mm/rad
    "mixed": (1e-3, 1.0, 1.0),        # kappa_1 in N mm/rad, kappa_2 and kappa_3 as printed
}
# mixed is the one reading that is both physical (every fitted kappa within 0.1-10x the Kapton pseudo-rigid-body
# estimate) and robust (every fitted claim survives a 1 % change of any geometric parameter): docs/model.md
DEFAULT_KAPPA_UNITS = "mixed"

# The geometry each reading uses, found by `geometry_search.py` under that reading (see docs/model.md for the
# command, its cost and the margins). Bounds: PC-MEMS link scale 0.3-3 mm, HAMR-VI URDF crank 0.592 mm / coupler
# 1.945 mm / foot 7.6 mm as the scale leads, leg 4-12 mm; rounded to 1 um / 1 mrad.
GEOMETRIES: dict[str, SliderCrankGeometry] = {
    "nmm": SliderCrankGeometry(crank_m=0.347e-3, coupler_m=0.566e-3, offset_m=0.021e-3, theta_fab_rad=1.070,
                               leg_length_m=7.01e-3, leg_angle0_rad=0.555),
    "printed": SliderCrankGeometry(crank_m=0.475e-3, coupler_m=1.719e-3, offset_m=0.997e-3, theta_fab_rad=1.350,
                                   leg_length_m=10.51e-3, leg_angle0_rad=0.885),
    "mixed": SliderCrankGeometry(crank_m=0.600e-3, coupler_m=0.601e-3, offset_m=0.385e-3, theta_fab_rad=2.863,
                                 leg_length_m=8.935e-3, leg_angle0_rad=0.770),
}
GEOMETRY = GEOMETRIES[DEFAULT_KAPPA_UNITS]


def check_kappa_units(kappa_units: str) -> str:
    if kappa_units not in KAPPA_READINGS:
        raise ModelError(f"kappa_units must be one of {', '.join(KAPPA_READINGS)}, got {kappa_units!r}")
    return kappa_units


# Swing DOF (design 5): the spherical five-bar couples the swing chain into the lift rotation by a small ratio
# epsilon = d theta_swing / d theta_lift, set by fold/assembly misalignment of the two (nominally orthogonal)
# axes. 0.05 ~ a 3 degree misalignment (PC-MEMS fold tolerance). The swing chain (undriven, unbiased, design-4
# flexures and k_ser) then adds epsilon^2 times its rotational stiffness to the lift crank.
SWING_COUPLING = 0.05


@dataclass(frozen=True)
class DesignParams:
    design: int
    name: str
    kapton_thickness_m: float
    bias_designed_m: float
    k_ser_N_per_m: float
    kappa_N_m_per_rad: tuple[float, float, float]
    bias_m: float                      # fitted (actual) coupler lengthening, Table III
    swing: bool = False
    swing_coupling: float = 0.0
    geometry: SliderCrankGeometry = field(default=GEOMETRY)
    kappa_units: str = DEFAULT_KAPPA_UNITS     # the reading the kappa values came from (provenance)
    flexure_width_m: float = NOMINAL_FLEXURE_WIDTH_M
    flexure_length_m: float = NOMINAL_FLEXURE_LENGTH_M
    coupler_buckling: bool = True              # the coupler's two strips buckle past their Euler load

    def __post_init__(self) -> None:
        if not np.isfinite(self.k_ser_N_per_m) or self.k_ser_N_per_m <= 0:
            raise ModelError(f"design {self.design} k_ser_N_per_m must be positive, got {self.k_ser_N_per_m!r}")
        if self.kapton_thickness_m <= 0:
            raise ModelError(f"design {self.design} kapton_thickness_m must be positive, got {self.kapton_thickness_m!r}")
        for i, k in enumerate(self.kappa_N_m_per_rad, start=1):
            if not np.isfinite(k) or k < 0:
                raise ModelError(f"design {self.design} kappa_{i} must be >= 0, got {k!r}")
        if len(self.kappa_N_m_per_rad) != 3:
            raise ModelError(f"design {self.design} needs three kappa values, got {len(self.kappa_N_m_per_rad)}")

    @property
    def coupler_m(self) -> float:
        return self.geometry.coupler_m + self.bias_m

    @property
    def flexure_strip(self) -> FlexureStrip:
        """The Kapton strip of this design's joints (its own film thickness, the nominal planform)."""
        return FlexureStrip(self.kapton_thickness_m, self.flexure_width_m, self.flexure_length_m)


# Table II + Table III (raw printed numbers; kappa converted per reading with KAPPA_READINGS).
_TABLE: dict[int, dict[str, Any]] = {
    1: dict(name="baseline", kapton_thickness_m=12.5e-6, bias_designed_m=0.0, k_ser_N_per_m=800.0,
            kappa=(0.0, 2.41e-5, 0.0), bias_m=-10e-6),
    2: dict(name="double thick Kapton", kapton_thickness_m=25e-6, bias_designed_m=0.0, k_ser_N_per_m=810.0,
            kappa=(0.019, 5.93e-5, 8.11e-5), bias_m=-19e-6),
    3: dict(name="biased", kapton_thickness_m=12.5e-6, bias_designed_m=200e-6, k_ser_N_per_m=2600.0,
            kappa=(0.0, 0.0, 0.0), bias_m=146e-6),
    4: dict(name="biased with double thick Kapton", kapton_thickness_m=25e-6, bias_designed_m=200e-6,
            k_ser_N_per_m=850.0, kappa=(0.023, 8.21e-5, 0.0), bias_m=183e-6),
}


def design_preset(design: int, kappa_units: str = DEFAULT_KAPPA_UNITS,
                  geometry: SliderCrankGeometry | None = None, **changes) -> DesignParams:
    """Design 1..5 (Table II) with its Table III parameters under a kappa reading; design 5 = design 4 + swing DOF.

    `geometry` defaults to the one searched for that reading (GEOMETRIES); `changes` replace other fields
    (e.g. flexure_length_m, coupler_buckling=False).
    """
    if design not in (1, 2, 3, 4, 5):
        raise ModelError(f"design must be 1..5, got {design!r}")
    check_kappa_units(kappa_units)
    geometry = GEOMETRIES[kappa_units] if geometry is None else geometry
    if design == 5:
        base = design_preset(4, kappa_units, geometry, **changes)
        return replace(base, design=5, name="biased with double thick Kapton - 2 DOF", swing=True,
                       swing_coupling=SWING_COUPLING)
    t = dict(_TABLE[design])
    k1, k2, k3 = (float(k) * f for k, f in zip(t.pop("kappa"), KAPPA_READINGS[kappa_units], strict=True))
    kappa = (k1, k2, k3)
    d = DesignParams(design=design, kappa_N_m_per_rad=kappa, geometry=geometry, kappa_units=kappa_units, **t)
    return replace(d, **changes) if changes else d
