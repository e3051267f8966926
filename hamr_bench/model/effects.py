"""Unmodelled effects as composable add-on terms with a strength; strength 0 gives back the nominal model exactly.

An effect is an object with a `name`, a `strength` and any of the hook methods below. The powertrain runs its
pipeline through named hook points and, at each point, passes the value through every effect (in the order given)
whose strength is non-zero. An effect with strength 0 is never called, so the nominal model is recovered
bit-for-bit whatever the effect's code does; the core equations are never edited to add an effect.

Hook points, in pipeline order (each receives the value and returns a replacement of the same kind):

    voltage_series(time_s, v_bias_V, v_drive_V) -> (v_bias_V, v_drive_V)
        memory effects (hysteresis, creep, amplifier dynamics) acting on whole time series before the
        quasi-static model; call `Powertrain.apply_voltage_series` (or `apply_voltage_series` here).
    actuator_params(params: ActuatorParams) -> ActuatorParams
        edge loss, PZT thickness, depolarisation ...
    plate_voltage(v_plate_V: ndarray, actuator: ActuatorParams) -> ndarray
        per-plate electric-field stage: effective voltage whose product with the nominal d31 gives the strain
        (field-dependent d31); must be odd in v for a symmetric material.
    serial_stiffness(k_ser_N_per_m: float, actuator: ActuatorParams) -> float
        compliance in series with the actuator (base/mounting compliance).
    design_params(design: DesignParams) -> DesignParams
        bias error, flexure stiffness drift (temperature) ...
    foot_force(force_N: ndarray) -> ndarray
        the force the support sees, after the model (e.g. a sensor-side nonlinearity).

Effects defined outside `hamr_bench.model` only need to subclass `Effect` (or duck-type it) and override hooks.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from hamr_bench.errors import ModelError

HOOKS = ("voltage_series", "actuator_params", "plate_voltage", "serial_stiffness", "design_params", "foot_force")


@dataclass(frozen=True)
class Effect:
    """Base class: every hook is the identity. Subclasses override the hooks they need."""

    strength: float = 0.0
    name: str = "effect"

    def __post_init__(self) -> None:
        if not np.isfinite(self.strength):
            raise ModelError(f"effect {self.name} strength must be finite, got {self.strength!r}")

    def voltage_series(self, time_s, v_bias_V, v_drive_V):
        return v_bias_V, v_drive_V

    def actuator_params(self, params):
        return params

    def plate_voltage(self, v_plate_V, actuator):
        return v_plate_V

    def serial_stiffness(self, k_ser_N_per_m, actuator):
        return k_ser_N_per_m

    def design_params(self, design):
        return design

    def foot_force(self, force_N):
        return force_N


def active(effects: Iterable[Effect], hook: str) -> list:
    """The effects that take part at `hook`: non-zero strength and the hook overridden (or duck-typed)."""
    out = []
    for e in effects:
        if getattr(e, "strength", 0.0) == 0:
            continue
        fn = getattr(e, hook, None)
        if fn is None:
            continue
        base = getattr(Effect, hook)
        if getattr(fn, "__func__", None) is base:
            continue
        out.append(e)
    return out


def apply_voltage_series(effects: Sequence[Effect], time_s, v_bias_V, v_drive_V):
    """Run the memory effects over a (t, v_bias, v_drive) series; nominal (no active effect) returns the inputs."""
    vb, vd = v_bias_V, v_drive_V
    for e in active(effects, "voltage_series"):
        vb, vd = e.voltage_series(time_s, vb, vd)
    return vb, vd


# --- Static effects implemented here ----------------------------------------------------------------------------
@dataclass(frozen=True)
class BaseCompliance(Effect):
    """Imperfect actuator grounding: a spring in series with the actuator at its base.

    strength = k_act / k_base (dimensionless; 0 = rigid base). 1/k_ser' = 1/k_ser + strength / k_act.
    Lowers the blocked force at the leg; the free displacement with nothing touching is unchanged.
    """

    name: str = "base_compliance"

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.strength < 0:
            raise ModelError(f"effect {self.name} strength must be >= 0 (a compliance), got {self.strength!r}")

    def serial_stiffness(self, k_ser_N_per_m, actuator):
        from hamr_bench.model.actuator import stiffness_N_per_m
        return 1.0 / (1.0 / k_ser_N_per_m + self.strength / stiffness_N_per_m(actuator))


@dataclass(frozen=True)
class FieldDependentD31(Effect):
    """d31 rising with field: d31(E) = d31_0 (1 + strength |E| / E_ref), E = V_plate / t_p, E_ref = 1 V/um.

    Applied per plate, so the bias-drive-ground law stays odd and the neutral at V_drive = V_bias / 2 is kept.
    Makes force and displacement convex in voltage (physics notes: slope roughly doubles above ~0.5 V/um).
    """

    name: str = "field_dependent_d31"
    field_ref_V_per_m: float = 1e6

    def plate_voltage(self, v_plate_V, actuator):
        v = np.asarray(v_plate_V, dtype=float)
        field = np.abs(v) / actuator.pzt_thickness_m
        return v * (1.0 + self.strength * field / self.field_ref_V_per_m)


@dataclass(frozen=True)
class PlayHysteresis(Effect):
    """Memory effect on the drive voltage: a play (backlash) operator of half-width strength x V_bias / 2.

    Acts on time series (hook `voltage_series`), before the quasi-static model. The operator output stays within
    half-width of the input and only moves when the input pushes it, so up- and down-sweeps differ.
    """

    name: str = "play_hysteresis"

    def voltage_series(self, time_s, v_bias_V, v_drive_V):
        vd = np.asarray(v_drive_V, dtype=float)
        vb = np.broadcast_to(np.asarray(v_bias_V, dtype=float), vd.shape)
        half = 0.5 * abs(self.strength) * vb
        out = np.empty_like(vd)
        # Start centred on the first sample: no remembered history before the series begins.
        y = vd.flat[0] if vd.size else 0.0
        for i in range(vd.size):
            x = vd.flat[i]
            w = half.flat[i]
            y = min(max(y, x - w), x + w)
            out.flat[i] = y
        return v_bias_V, out
