"""The realistic-bench effects: how the simulated bench departs from the nominal model, switched on by name and
strength (rig file `[sim] effects`, `--effects NAME=STRENGTH`) with optional shape parameters (`[sim]
effect_shapes = { NAME = { PARAM = VALUE } }`). Strength 0 (or absent) gives back the bench without that effect
exactly: its stage is skipped.

These are the GENERATOR forms. The gap diagnosis (`analysis`) fits its own candidate families, and the two share
no formula (docs/gap.md lists the pairs side by side). Where each lands:

- drive chain (sim_devices.drive_chain): `hysteresis` (Preisach, sim_devices.preisach), `creep` (Kelvin-Voigt /
  Prony chain), `field_dependent_d31` (monotone knots or logistic in field), `amplifier_gain_error` (decoy);
- model parameters (this module, as `hamr_bench.model` effect hooks): `width_loss`, `pzt_thickness`,
  `pzt_modulus`, `grounding_lengthening` (the clamp line moved back), `flexure_softening` (decoy);
- contact (sim_devices.contact_statics): `base_compliance` (a hardening or push/pull clamp in the mechanics),
  `sensor_compliance` (the mount's spring in series with the sensor), `foot_friction`, `bias_error` (the Kapton's
  relaxation of the bias, time-varying);
- stage and sensor (sim_devices.stage_carriage, sensor_drift): `stage_backlash` (play + stick-slip drive),
  `sensor_drift` (warm-up + Ornstein-Uhlenbeck), `mount_thermal_drift` (decoy).

`describe()` prints the table with units, realistic values and shape parameters (the same table is in
docs/rig-file.md). Sources of the realistic values: docs/model.md, "The simulated bench".
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from hamr_bench.errors import ConfigError
from hamr_bench.model import Effect
from hamr_bench.model import actuator as act


@dataclass(frozen=True)
class EffectSpec:
    unit: str
    meaning: str
    realistic: float
    low: float                      # allowed strength range
    high: float
    kind: str                       # "library" (a candidate family exists), "decoy", "bench" (model parameter)
    shape: tuple[str, ...] = ()     # shape parameter names (defaults in the module that implements the form)


EFFECTS: dict[str, EffectSpec] = {
    "hysteresis": EffectSpec(
        "fraction of span", "Preisach hysteresis per plate; largest rise/fall gap of the net drive at 250 V / span",
        0.12, 0.0, 0.4, "library", ("r0", "kappa")),
    "creep": EffectSpec(
        "per decade", "Kelvin-Voigt (Prony) creep per plate; mean growth per decade of time, 10 ms - 100 s",
        0.015, 0.0, 0.05, "library", ("tau1_s", "weight1", "tau2_s", "weight2", "tau3_s", "weight3", "tau4_s",
                                       "weight4")),
    "field_dependent_d31": EffectSpec(
        "ratio - 1", "d31 vs field (monotone knots or logistic); d31 at 250 V / d31 at 100 V - 1 (either sign)",
        0.5, -0.6, 1.5, "library", ("form", "switch_field_V_per_um", "width_V_per_um", "split", "low_tail",
                                    "high_tail")),
    "base_compliance": EffectSpec(
        "fraction", "nonlinear clamp (hardening or push/pull) in series; bare-actuator blocked-force loss at 250 V",
        0.2, 0.0, 0.8, "library", ("form", "hardening", "pull_ratio")),
    "grounding_lengthening": EffectSpec(
        "fraction", "clamp line moved back: active length x (1 + s), taper and extension ratio follow", 0.08,
        0.0, 0.3, "library"),
    "sensor_compliance": EffectSpec(
        "m/N", "the sensor mount's compliance, in series with the sensor in the contact (dynamics included)",
        1.0 / 20000.0, 0.0, 5e-3, "library"),
    "width_loss": EffectSpec(
        "fraction", "laser-cut width loss: every width x (1 - s)", 0.15, 0.0, 0.5, "library"),
    "pzt_thickness": EffectSpec(
        "fraction", "PZT plates thicker than nominal: t_p x (1 + s)", 0.2, -0.3, 0.5, "library"),
    "pzt_modulus": EffectSpec(
        "fraction", "PZT modulus off: E_p x (1 + s)", -0.19, -0.5, 0.5, "library"),
    "bias_error": EffectSpec(
        "m", "transmission bias off and relaxing (Kapton viscoelasticity); mean offset over the first 300 s",
        -30e-6, -150e-6, 150e-6, "library", ("run_fraction", "tau1_s", "tau2_s", "weight1")),
    "stage_backlash": EffectSpec(
        "m", "stage play (full width) with a compliant stick-slip drive behind it", 10e-6, 0.0, 100e-6, "library",
        ("lag_m", "stick_ratio")),
    "sensor_drift": EffectSpec(
        "N/sqrt(s)", "force-sensor baseline: thermal warm-up + Ornstein-Uhlenbeck wander of this rate", 2e-5, 0.0,
        1e-3, "library", ("warmup_N", "warmup_tau_s", "reversion_s")),
    "foot_friction": EffectSpec(
        "coefficient", "Coulomb friction of the foot on the sensor (leg fixture)", 0.25, 0.0, 1.0, "bench"),
    # decoys for the gap diagnosis's self-check: physical effects OUTSIDE its candidate library
    "amplifier_gain_error": EffectSpec(
        "fraction", "the HV reaching both plates is (1 - s) of the amplifier output (its monitor reads full)", 0.08,
        0.0, 0.5, "decoy"),
    "flexure_softening": EffectSpec(
        "fraction", "warm Kapton: every flexure stiffness kappa_i x (1 - s)", 0.3, 0.0, 0.9, "decoy"),
    "mount_thermal_drift": EffectSpec(
        "m/s", "the sensor's mount creeps toward the plant (thermal expansion of the positioner)", 1e-9, 0.0,
        1e-7, "decoy"),
}
REALISTIC: dict[str, float] = {name: spec.realistic for name, spec in EFFECTS.items()}
DECOYS = tuple(n for n, s in EFFECTS.items() if s.kind == "decoy")


def check_effects(effects: dict[str, float], where: str = "effects") -> dict[str, float]:
    """The effects that are on (strength != 0), each checked against its range; a bad one is one ConfigError line."""
    for name, strength in effects.items():
        if name not in EFFECTS:
            raise ConfigError(f"{where}: unknown effect {name!r} (known: {', '.join(EFFECTS)})")
        if not isinstance(strength, (int, float)) or not math.isfinite(strength):
            raise ConfigError(f"{where}: strength of {name} must be a finite number, got {strength!r}")
        spec = EFFECTS[name]
        if not spec.low <= strength <= spec.high:
            raise ConfigError(f"{where}: strength of {name} must be in [{spec.low:g}, {spec.high:g}] "
                              f"({spec.unit}), got {strength!r}")
    return {k: float(v) for k, v in effects.items() if v != 0}


def check_shapes(shapes: dict[str, dict[str, float]], where: str = "effect_shapes") -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for name, params in shapes.items():
        if name not in EFFECTS:
            raise ConfigError(f"{where}: unknown effect {name!r} (known: {', '.join(EFFECTS)})")
        if not isinstance(params, dict):
            raise ConfigError(f"{where}.{name}: expected a table of shape parameters, got {params!r}")
        known = EFFECTS[name].shape
        for key, value in params.items():
            if key not in known:
                raise ConfigError(f"{where}.{name}: unknown shape parameter {key!r} "
                                  f"(known: {', '.join(known) or 'none'})")
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"{where}.{name}.{key}: expected a finite number, got {value!r}")
        out[name] = {k: float(v) for k, v in params.items()}
    return out


def describe() -> str:
    """The effect table: name, unit of strength, realistic value, kind, meaning, shape parameters."""
    lines = [f"{'effect':24s} {'unit':18s} {'realistic':>10s}  {'kind':8s} meaning [shape parameters]"]
    for name, s in EFFECTS.items():
        shape = f" [{', '.join(s.shape)}]" if s.shape else ""
        lines.append(f"{name:24s} {s.unit:18s} {s.realistic:10.3g}  {s.kind:8s} {s.meaning}{shape}")
    return "\n".join(lines)


# ------------------------------------------------------------------ model-parameter effects (generator forms)
@dataclass(frozen=True)
class UniformWidthLoss(Effect):
    """Laser-cut width loss as a uniform scaling: every width along the plate x (1 - s) (taper ratio kept)."""

    name: str = "width_loss"

    def actuator_params(self, params):
        return act.with_changes(params, width_nom_m=params.width_nom_m * (1.0 - self.strength))


@dataclass(frozen=True)
class PlateThickness(Effect):
    name: str = "pzt_thickness"

    def actuator_params(self, params):
        return act.with_changes(params, pzt_thickness_m=params.pzt_thickness_m * (1.0 + self.strength))


@dataclass(frozen=True)
class PlateModulus(Effect):
    name: str = "pzt_modulus"

    def actuator_params(self, params):
        return act.with_changes(params, pzt_modulus_Pa=params.pzt_modulus_Pa * (1.0 + self.strength))


@dataclass(frozen=True)
class ClampLineMoved(Effect):
    """Imperfect grounding: the clamp line sits s x l further toward the base, so the bending length is l (1 + s).
    The rigid extension keeps its length (l_r = l_ext / l' falls) and the taper continues into the newly free
    part: the base width grows by s l times the taper's slope, so the mean width and the width ratio change."""

    name: str = "grounding_lengthening"

    def actuator_params(self, params):
        s = self.strength
        w_base = params.width_ratio * params.width_nom_m
        w_tip = (2.0 - params.width_ratio) * params.width_nom_m
        slope = (w_base - w_tip) / params.length_m          # width gained per metre toward the base
        length = params.length_m * (1.0 + s)
        new_base = w_base + slope * s * params.length_m
        mean = 0.5 * (new_base + w_tip)
        return act.with_changes(params, length_m=length, width_nom_m=mean, width_ratio=new_base / mean,
                                length_ratio=params.length_ratio / (1.0 + s))


@dataclass(frozen=True)
class FlexureSoftening(Effect):
    """Decoy: every flexure joint softer by the fraction `strength` (Kapton's modulus falls with temperature)."""

    name: str = "flexure_softening"

    def design_params(self, design):
        k = tuple(float(x) * (1.0 - self.strength) for x in design.kappa_N_m_per_rad)
        return dataclasses.replace(design, kappa_N_m_per_rad=k)


MODEL_HOOKS = {"width_loss": UniformWidthLoss, "pzt_thickness": PlateThickness, "pzt_modulus": PlateModulus,
               "grounding_lengthening": ClampLineMoved, "flexure_softening": FlexureSoftening}


def model_effects(effects: dict[str, float]) -> list[Effect]:
    """The model-parameter effects that are on, as `hamr_bench.model` effects (applied to the specimen's
    parameters when the bench builds its powertrain)."""
    return [MODEL_HOOKS[name](strength=s) for name, s in effects.items() if name in MODEL_HOOKS and s != 0]
