"""The piezoelectric bimorph actuator: parameters (paper Table I), presets, and its quasi-static outputs.

Model variant: the plain beam-bending closed form of the optimal-energy-density bimorph (Wood, Steltz & Fearing
2005), NOT full classical lamination theory. Uniaxial stress (no plane-strain factor); the paper's "effective"
d31 and E_p were fitted with a model of this family, and they absorb the difference. Both the tapered width
(width ratio w_r) and the rigid tip extension (length ratio l_r) enter through the geometric factors G_F, G_D.

Per unit width bending rigidity (two PZT plates of thickness t_p around a central carbon-fibre layer t_c):

    D     = (E_p t_p / 3)(1.5 t_c^2 + 3 t_c t_p + 2 t_p^2) + E_c t_c^3 / 12
    F_b   = (3/4) d31 E_p w_nom (t_p + t_c) V G_F / l        blocked tip force, one plate driven at V
    delta = (1/4) d31 E_p (t_p + t_c) l^2 V G_D / D          free tip deflection
    k_act = F_b / delta                                       tip stiffness (independent of V)

Bias-drive-ground: top plate sees V_bias - V_drive, bottom plate sees V_drive; each plate's contribution to the
tip force is proportional to its own voltage term, so the piezo force is  c (g(V_drive) - g(V_bias - V_drive))
with g(V) = V nominally (c = F_b / V): zero at V_drive = V_bias / 2 and +F_b(V_bias) at V_drive = V_bias.
Positive tip force/deflection is the direction V_drive = V_bias pushes (toward the sensor / "down" for the leg).
The per-plate voltage map g is the hook through which field-dependent effects (d31(E)) enter.

Units SI throughout: m, N, V, kg, Pa, m/V.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from hamr_bench.errors import ModelError

# Material densities (kg/m^3) used for the actuator mass; only PZT matters at the 1 % level.
RHO_PZT_KG_PER_M3 = 7800.0   # PZT-5H (Piezo Systems T105-H4E-602 data sheet: 7800)
RHO_CF_KG_PER_M3 = 1600.0    # cured carbon-fibre prepreg
RHO_FR4_KG_PER_M3 = 1850.0   # FR-4
E_CF_PA = 340e9              # high-modulus carbon fibre along the fibre (physics.md; 260 GPa changes < 3 %)

VoltageMap = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class ActuatorParams:
    """One bimorph. Lengths in m, moduli in Pa, d31 in m/V (magnitude)."""

    layers: int
    cf_thickness_m: float        # central carbon-fibre layer, total (layers x per-layer thickness)
    pzt_thickness_m: float       # one PZT plate
    fr4_thickness_m: float
    length_m: float              # active length l
    width_nom_m: float           # mean width w_nom
    length_ratio: float          # l_r = l_ext / l
    width_ratio: float           # w_r = w_base / w_nom
    d31_m_per_V: float
    pzt_modulus_Pa: float
    cf_modulus_Pa: float = E_CF_PA
    label: str = ""

    def __post_init__(self) -> None:
        validate_actuator(self)

    # Convenience methods mirror the module functions (the functions are the vectorised primitives).
    @property
    def stiffness_N_per_m(self) -> float:
        return stiffness_N_per_m(self)

    @property
    def mass_kg(self) -> float:
        return mass_kg(self)

    def blocked_force_N(self, voltage_V: ArrayLike) -> np.ndarray:
        return blocked_force_N(self, voltage_V)

    def free_displacement_m(self, voltage_V: ArrayLike) -> np.ndarray:
        return free_displacement_m(self, voltage_V)

    def energy_J(self, voltage_V: ArrayLike) -> np.ndarray:
        return energy_J(self, voltage_V)

    def energy_density_J_per_kg(self, voltage_V: ArrayLike) -> np.ndarray:
        return energy_density_J_per_kg(self, voltage_V)

    def tip_force_N(self, v_bias_V: ArrayLike, v_drive_V: ArrayLike, tip_deflection_m: ArrayLike) -> np.ndarray:
        return tip_force_N(self, v_bias_V, v_drive_V, tip_deflection_m)

    def free_tip_deflection_m(self, v_bias_V: ArrayLike, v_drive_V: ArrayLike) -> np.ndarray:
        return free_tip_deflection_m(self, v_bias_V, v_drive_V)


def validate_actuator(p: ActuatorParams) -> None:
    """Raise ModelError naming the first physically impossible field."""
    positive = ("cf_thickness_m", "pzt_thickness_m", "length_m", "width_nom_m", "d31_m_per_V",
                "pzt_modulus_Pa", "cf_modulus_Pa")
    for name in positive:
        value = getattr(p, name)
        if not np.isfinite(value) or value <= 0:
            raise ModelError(f"actuator parameter {name} must be positive and finite, got {value!r}")
    if not np.isfinite(p.fr4_thickness_m) or p.fr4_thickness_m < 0:
        raise ModelError(f"actuator parameter fr4_thickness_m must be >= 0, got {p.fr4_thickness_m!r}")
    if not np.isfinite(p.length_ratio) or p.length_ratio < 0:
        raise ModelError(f"actuator parameter length_ratio must be >= 0, got {p.length_ratio!r}")
    # The linear taper must keep a positive tip width: w_tip = (2 - w_r) w_nom.
    if not (0 < p.width_ratio < 2):
        raise ModelError(f"actuator parameter width_ratio must be in (0, 2) (positive tip width), "
                         f"got {p.width_ratio!r}")
    if p.layers not in (1, 2, 3):
        raise ModelError(f"actuator parameter layers must be 1, 2 or 3, got {p.layers!r}")


# --- Table I -------------------------------------------------------------------------------------------------
# Per-layer carbon-fibre thickness: "60 (uncured)" reported, "30 (cured)" effective. Everything else is per
# actuator. The 1x/2x/3x actuators differ only in the number of central layers.
TABLE_I = {
    "reported": dict(cf_layer_m=60e-6, pzt_thickness_m=127e-6, fr4_thickness_m=127e-6, length_m=8.8e-3,
                     width_nom_m=4.2e-3, length_ratio=0.0063, width_ratio=1.5, d31_m_per_V=0.35e-9,
                     pzt_modulus_Pa=42e9),
    "effective": dict(cf_layer_m=30e-6, pzt_thickness_m=155e-6, fr4_thickness_m=127e-6, length_m=9.6e-3,
                      width_nom_m=3.4e-3, length_ratio=0.0063, width_ratio=1.5, d31_m_per_V=0.36e-9,
                      pzt_modulus_Pa=34e9),
}


def actuator_preset(layers: int, params: str = "effective") -> ActuatorParams:
    """Actuator with `layers` central carbon-fibre layers and Table I's "reported" or "effective" values."""
    if params not in TABLE_I:
        raise ModelError(f"actuator params must be 'reported' or 'effective', got {params!r}")
    if layers not in (1, 2, 3):
        raise ModelError(f"actuator layers must be 1, 2 or 3, got {layers!r}")
    t = dict(TABLE_I[params])
    cf_layer = t.pop("cf_layer_m")
    return ActuatorParams(layers=layers, cf_thickness_m=layers * cf_layer, label=f"{layers}x {params}", **t)


def with_changes(p: ActuatorParams, **changes: Any) -> ActuatorParams:
    """A copy with some fields changed (validated again)."""
    return replace(p, **changes)


# --- Geometric factors -----------------------------------------------------------------------------------------
def geometric_factor_displacement(length_ratio: float) -> float:
    """G_D = 1 + 2 l_r: a rigid extension of length l_r l adds its rotation lever to the tip deflection."""
    return 1.0 + 2.0 * length_ratio


def geometric_factor_force(width_ratio: float, length_ratio: float) -> float:
    """G_F for a linear taper (base w_r w_nom, tip (2 - w_r) w_nom) with a rigid extension.

    Closed form of the tapered-cantilever integral (physics.md). It is 0/0 at w_r = 1 and loses digits near it,
    so within 0.02 of 1 the defining integral is evaluated by Gauss-Legendre quadrature instead:
    G_F = (2/3) int_0^1 (L' - x) dx / int_0^1 (L' - x)^2 / w(x) dx, L' = 1 + l_r, w(x) = w_r + 2 (1 - w_r) x.
    """
    wr = float(width_ratio)
    lr = float(length_ratio)
    if abs(wr - 1.0) < 0.02:
        x, wq = np.polynomial.legendre.leggauss(32)
        x = 0.5 * (x + 1.0)
        wq = 0.5 * wq
        Lp = 1.0 + lr
        num = float(np.sum(wq * (Lp - x)))
        den = float(np.sum(wq * (Lp - x) ** 2 / (wr + 2.0 * (1.0 - wr) * x)))
        return num / den / 1.5
    num = 8.0 * (1.0 - wr) ** 3 * (1.0 + 2.0 * lr)
    den = (-6.0 * (wr - 1.0) * (-3.0 + 4.0 * lr * (wr - 1.0) + 2.0 * wr)
           + 3.0 * (-2.0 + 2.0 * lr * (wr - 1.0) + wr) ** 2 * np.log((2.0 - wr) / wr))
    return float(num / den)


def bending_rigidity_per_width(p: ActuatorParams) -> float:
    """D (N m): per-unit-width bending rigidity of the PZT / CF / PZT stack about its mid-plane."""
    tp, tc = p.pzt_thickness_m, p.cf_thickness_m
    return p.pzt_modulus_Pa * tp / 3.0 * (1.5 * tc**2 + 3.0 * tc * tp + 2.0 * tp**2) + p.cf_modulus_Pa * tc**3 / 12.0


def force_per_volt(p: ActuatorParams) -> float:
    """c = F_b / V (N/V), one plate driven."""
    gf = geometric_factor_force(p.width_ratio, p.length_ratio)
    t_sum = p.pzt_thickness_m + p.cf_thickness_m
    return 0.75 * p.d31_m_per_V * p.pzt_modulus_Pa * p.width_nom_m * t_sum * gf / p.length_m


def displacement_per_volt(p: ActuatorParams) -> float:
    """delta / V (m/V), one plate driven."""
    gd = geometric_factor_displacement(p.length_ratio)
    return (0.25 * p.d31_m_per_V * p.pzt_modulus_Pa * (p.pzt_thickness_m + p.cf_thickness_m) * p.length_m**2 * gd
            / bending_rigidity_per_width(p))


def stiffness_N_per_m(p: ActuatorParams) -> float:
    """k_act = F_b / delta (N/m)."""
    return force_per_volt(p) / displacement_per_volt(p)


def mass_kg(p: ActuatorParams) -> float:
    """Active bimorph (two PZT plates + CF, planform l x w_nom) plus the FR-4 tip extension (l_r l at tip width)."""
    area = p.length_m * p.width_nom_m
    stack = (2.0 * p.pzt_thickness_m * RHO_PZT_KG_PER_M3 + p.cf_thickness_m * RHO_CF_KG_PER_M3) * area
    ext = p.fr4_thickness_m * RHO_FR4_KG_PER_M3 * p.length_ratio * p.length_m * (2.0 - p.width_ratio) * p.width_nom_m
    return float(stack + ext)


def blocked_force_N(p: ActuatorParams, voltage_V: ArrayLike) -> np.ndarray:
    """One-sided blocked tip force at V_bias = voltage (V_drive = V_bias)."""
    return force_per_volt(p) * np.asarray(voltage_V, dtype=float)


def free_displacement_m(p: ActuatorParams, voltage_V: ArrayLike) -> np.ndarray:
    """One-sided free tip deflection at V_bias = voltage (V_drive = V_bias)."""
    return displacement_per_volt(p) * np.asarray(voltage_V, dtype=float)


def energy_J(p: ActuatorParams, voltage_V: ArrayLike) -> np.ndarray:
    """Half-cycle energy as the paper defines it: blocked force x free displacement (one-sided)."""
    return blocked_force_N(p, voltage_V) * free_displacement_m(p, voltage_V)


def energy_density_J_per_kg(p: ActuatorParams, voltage_V: ArrayLike) -> np.ndarray:
    return energy_J(p, voltage_V) / mass_kg(p)


def _identity(v: np.ndarray) -> np.ndarray:
    return v


def piezo_force_N(p: ActuatorParams, v_bias_V: ArrayLike, v_drive_V: ArrayLike,
                  voltage_map: VoltageMap = _identity) -> np.ndarray:
    """The actuator's internal (blocked) force for a bias-drive-ground drive: c (g(V_d) - g(V_b - V_d)).

    `voltage_map` g turns one plate's voltage into its effective voltage (identity nominally; field-dependent
    d31 replaces it). Positive = toward the sensor.
    """
    vb = np.asarray(v_bias_V, dtype=float)
    vd = np.asarray(v_drive_V, dtype=float)
    return force_per_volt(p) * (voltage_map(vd) - voltage_map(vb - vd))


def free_tip_deflection_m(p: ActuatorParams, v_bias_V: ArrayLike, v_drive_V: ArrayLike,
                          voltage_map: VoltageMap = _identity) -> np.ndarray:
    """Tip deflection with nothing touching the tip (positive toward the sensor)."""
    return piezo_force_N(p, v_bias_V, v_drive_V, voltage_map) / stiffness_N_per_m(p)


def tip_force_N(p: ActuatorParams, v_bias_V: ArrayLike, v_drive_V: ArrayLike, tip_deflection_m: ArrayLike,
                voltage_map: VoltageMap = _identity) -> np.ndarray:
    """Force the tip exerts on a support holding it at `tip_deflection_m`: F_piezo - k_act x (linear spring)."""
    x = np.asarray(tip_deflection_m, dtype=float)
    return piezo_force_N(p, v_bias_V, v_drive_V, voltage_map) - stiffness_N_per_m(p) * x
