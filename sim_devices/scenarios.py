"""Hidden trial scenarios for the gap diagnosis's self-check (issue 16 item 4, the bench side): from a seed, one
case as a real rig would present it, and the truth to score against.

A case holds 0-3 simultaneous effects in their GENERATOR forms (sim_devices.bench_effects) at realistic strengths,
with each form's shape parameters drawn too; decoys (effects outside the diagnosis's library) and nulls in the
proportions asked; and several specimens, each with its own parameters drawn within fabrication tolerances
(sim_devices.specimens), so the nominal model the diagnosis starts from (the presets) is off from the bench's truth
as it is on a real rig. The truth names every effect, its strength in the generator's unit and, where the two
units mean the same physical quantity, in the library candidate's unit, plus observables that compare across
forms (e.g. the blocked-force change of the 2-layer actuator at 250 V).

    sc = draw_scenario(seed)                 # proportions and sizes as arguments
    path = sc.rig_file(tmp / "rig.toml", specimen=0)   # a sim rig file holding this case for one specimen
    run_protocol(RunRequest(protocol="actuator", out=..., rig_path=path, layers=sc.layers, design=sc.design))

Draw ranges and their reasons are in docs/model.md ("The simulated bench", trial scenarios).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.model import actuator as act
from hamr_bench.model import actuator_preset, design_preset
from sim_devices.bench import BenchSettings, apply_model_overrides
from sim_devices.bench_effects import EFFECTS, model_effects
from sim_devices.sim_rig_file import write_sim_rig
from sim_devices.specimens import draw_specimen

# strength draws: (low, high, log-uniform?, random sign?)
STRENGTH_DRAWS: dict[str, tuple[float, float, bool, bool]] = {
    "hysteresis": (0.06, 0.16, False, False),
    "creep": (0.008, 0.025, False, False),
    "field_dependent_d31": (0.25, 1.0, False, True),        # negative side: -s / (1 + s), i.e. up to ~2x down
    "base_compliance": (0.1, 0.3, False, False),
    "grounding_lengthening": (0.04, 0.12, False, False),
    "sensor_compliance": (1 / 40000.0, 1 / 8000.0, True, False),
    "width_loss": (0.08, 0.22, False, False),
    "pzt_thickness": (0.08, 0.3, False, False),
    "pzt_modulus": (0.08, 0.3, False, True),
    "bias_error": (15e-6, 45e-6, False, True),
    "stage_backlash": (3e-6, 30e-6, True, False),
    "sensor_drift": (1e-5, 3e-5, False, False),
    "amplifier_gain_error": (0.05, 0.12, False, False),
    "flexure_softening": (0.2, 0.4, False, False),
    "mount_thermal_drift": (5e-10, 3e-9, True, False),
}
LIBRARY_EFFECTS = tuple(n for n, s in EFFECTS.items() if s.kind == "library")
DECOY_EFFECTS = tuple(n for n, s in EFFECTS.items() if s.kind == "decoy")
# the leg fixture alone shows these: an actuator-only trial set cannot see them
LEG_ONLY = ("bias_error", "foot_friction", "flexure_softening")
# effects whose strength unit is the library candidate's unit (same physical quantity; forms.md)
SAME_UNIT = ("hysteresis", "base_compliance", "grounding_lengthening", "sensor_compliance", "width_loss",
             "pzt_thickness", "pzt_modulus", "bias_error", "stage_backlash", "sensor_drift")


@dataclass(frozen=True)
class EffectTruth:
    name: str                      # generator effect name (stable string)
    strength: float                # in the generator's unit (EFFECTS[name].unit)
    shape: dict[str, float]        # the generator form's drawn shape parameters
    decoy: bool                    # outside the diagnosis's candidate library
    library_name: str | None       # the candidate it corresponds to (None for a decoy)
    library_strength: float | None  # its size in the candidate's unit where the units coincide
    observable: dict[str, float] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "strength": self.strength, "unit": EFFECTS[self.name].unit,
                "shape": dict(self.shape), "decoy": self.decoy, "library_name": self.library_name,
                "library_strength": self.library_strength, "observable": dict(self.observable)}


@dataclass(frozen=True)
class SpecimenTruth:
    label: str
    seed: int
    actuator: dict[str, float]
    design: dict[str, Any]
    layers: int = 2

    def to_json(self) -> dict[str, Any]:
        return {"label": self.label, "seed": self.seed, "layers": self.layers, "actuator": dict(self.actuator),
                "design": dict(self.design)}


@dataclass(frozen=True)
class Scenario:
    seed: int
    kind: str                       # null | single | multi | decoy
    effects: tuple[EffectTruth, ...]
    specimens: tuple[SpecimenTruth, ...]
    design: int = 4
    layers: int = 2
    params_set: str = "effective"

    @property
    def layer_counts(self) -> tuple[int, ...]:
        """The layer counts of the case's specimens, in order."""
        return tuple(sorted({s.layers for s in self.specimens})) or (self.layers,)

    def effects_argument(self) -> dict[str, float]:
        return {e.name: e.strength for e in self.effects}

    def shapes_argument(self) -> dict[str, dict[str, float]]:
        return {e.name: dict(e.shape) for e in self.effects if e.shape}

    def sim_keys(self, specimen: int = 0) -> dict[str, Any]:
        """The `[sim]` keys of this case for one specimen."""
        return {"design": self.design, "layers": self.specimens[specimen].layers, "params": self.params_set,
                "effects": self.effects_argument(), "effect_shapes": self.shapes_argument(),
                "specimen_seed": self.specimens[specimen].seed}

    def bench_settings(self, fixture: str, specimen: int = 0, seed: int = 0) -> BenchSettings:
        return BenchSettings(fixture=fixture, design=self.design, layers=self.specimens[specimen].layers,
                             params_set=self.params_set,
                             effects=self.effects_argument(), effect_shapes=self.shapes_argument(), seed=seed,
                             specimen_seed=self.specimens[specimen].seed)

    def rig_file(self, path: Path | str, specimen: int = 0) -> Path:
        """A simulated rig file (`rigs/sim.toml` with this case's `[sim]` keys) for one specimen."""
        return write_sim_rig(Path(path), self.sim_keys(specimen))

    def to_json(self) -> dict[str, Any]:
        return {"seed": self.seed, "kind": self.kind, "design": self.design, "layers": self.layers,
                "params_set": self.params_set, "effects": [e.to_json() for e in self.effects],
                "specimens": [s.to_json() for s in self.specimens]}


# ------------------------------------------------------------------ drawing
def draw_scenario(seed: int, *, null_fraction: float = 0.15, decoy_fraction: float = 0.10,
                  multi_fraction: float = 0.35, max_effects: int = 3, n_specimens: int = 3, design: int = 4,
                  layers: int = 2, fixtures: tuple[str, ...] = ("actuator", "leg"),
                  pool: tuple[str, ...] | None = None, layer_counts: tuple[int, ...] | None = None) -> Scenario:
    """One hidden case. `fixtures`: which fixtures the trial records (effects only a leg shows are left out of an
    actuator-only draw); `pool`: library effects to draw from (default: all a trial of these fixtures can see);
    `layer_counts`: build `n_specimens` of each (default: of `layers` alone, which they must include; the effects'
    strengths refer to the `layers` actuator, and its specimens are drawn as without the others)."""
    for name, value in (("null_fraction", null_fraction), ("decoy_fraction", decoy_fraction),
                        ("multi_fraction", multi_fraction)):
        if not 0 <= value <= 1:
            raise ValueError(f"{name} must be in [0, 1], got {value!r}")
    if null_fraction + decoy_fraction > 1:
        raise ValueError("null_fraction + decoy_fraction must not exceed 1")
    if not 1 <= max_effects <= 3 or n_specimens < 1:
        raise ValueError("max_effects must be 1-3 and n_specimens >= 1")
    counts = tuple(layer_counts or (layers,))
    if layers not in counts or len(set(counts)) != len(counts) or min(counts) < 1:
        raise ValueError(f"layer_counts {counts} must be distinct positive layer counts including layers={layers}")
    rng = np.random.default_rng([int(seed), 0x5CE7A])
    leg = "leg" in fixtures
    library = tuple(n for n in (pool or LIBRARY_EFFECTS) if leg or n not in LEG_ONLY)
    decoys = tuple(n for n in DECOY_EFFECTS if leg or n not in LEG_ONLY)
    u = rng.random()
    names: list[str] = []
    if u < null_fraction:
        kind = "null"
    elif u < null_fraction + decoy_fraction:
        kind = "decoy"
        names.append(str(rng.choice(decoys)))
        if max_effects > 1 and rng.random() < multi_fraction:   # a decoy may come with a library effect
            names.append(str(rng.choice(library)))
    else:
        count = 1
        if max_effects > 1 and rng.random() < multi_fraction:
            count = int(rng.integers(2, max_effects + 1))
        kind = "single" if count == 1 else "multi"
        names.extend(str(n) for n in rng.choice(library, size=count, replace=False))
    specimens = tuple(_specimen(str(k + 1), int(rng.integers(2 ** 31)), design, layers)
                      for k in range(n_specimens))
    effects = tuple(_effect(name, rng, layers) for name in names)
    specimens += _other_layer_counts(seed, counts, layers, n_specimens, design)
    return Scenario(seed=int(seed), kind=kind, effects=effects, specimens=specimens, design=design, layers=layers)


def _other_layer_counts(seed: int, counts: tuple[int, ...], layers: int, n_specimens: int,
                        design: int) -> tuple[SpecimenTruth, ...]:
    """The specimens of the layer counts besides `layers`, each count from its own stream (so the rest of the
    draw is the same with them as without), labelled `<layers>L<k>`."""
    out: list[SpecimenTruth] = []
    for n in counts:
        if n != layers:
            rng = np.random.default_rng([int(seed), 0x5CE7A, n])
            out += [_specimen(f"{n}L{k + 1}", int(rng.integers(2 ** 31)), design, n) for k in range(n_specimens)]
    return tuple(out)


def _specimen(label: str, seed: int, design: int, layers: int) -> SpecimenTruth:
    a, d = actuator_preset(layers, "effective"), design_preset(design)
    drawn = draw_specimen(seed, a.__dict__, d.__dict__)
    a2, d2 = apply_model_overrides(a, d, drawn)
    return SpecimenTruth(label, seed, {k: float(getattr(a2, k)) for k in drawn["actuator"]},
                         {"k_ser_N_per_m": d2.k_ser_N_per_m, "kappa_N_m_per_rad": list(d2.kappa_N_m_per_rad),
                          "bias_m": d2.bias_m}, layers)


def draw_strength(name: str, rng: np.random.Generator) -> float:
    low, high, log, signed = STRENGTH_DRAWS[name]
    s = float(math.exp(rng.uniform(math.log(low), math.log(high))) if log else rng.uniform(low, high))
    if signed and rng.random() < 0.5:
        # d31 down by the same factor it would go up; a parameter or bias error simply the other sign
        s = -s / (1.0 + s) if name == "field_dependent_d31" else -s
    return s


def draw_shape(name: str, rng: np.random.Generator, strength: float) -> dict[str, float]:
    """The generator form's shape parameters (sim_devices.bench_effects, EFFECTS[name].shape)."""
    if name == "hysteresis":
        return {"r0": float(math.exp(rng.uniform(math.log(0.5), math.log(2.0)))), "kappa": rng.uniform(-0.6, 0.6)}
    if name == "creep":
        n = int(rng.integers(2, 5))
        taus = np.sort(np.exp(rng.uniform(math.log(0.01), math.log(100.0), n)))
        weights = rng.dirichlet(np.ones(n))
        out: dict[str, float] = {}
        for i in range(n):
            out[f"tau{i + 1}_s"] = float(taus[i])
            out[f"weight{i + 1}"] = float(weights[i])
        return out
    if name == "field_dependent_d31":
        if rng.random() < 0.5:
            return {"form": 0.0, "switch_field_V_per_um": rng.uniform(0.3, 1.3),
                    "width_V_per_um": rng.uniform(0.15, 0.5)}
        return {"form": 1.0, "split": rng.uniform(0.3, 0.7), "low_tail": rng.uniform(0.0, 0.3),
                "high_tail": rng.uniform(0.0, 0.2)}
    if name == "base_compliance":
        return {"form": float(rng.random() < 0.5), "hardening": rng.uniform(1.0, 3.0),
                "pull_ratio": float(math.exp(rng.uniform(math.log(0.3), 0.0)))}
    if name == "stage_backlash":
        return {"lag_m": rng.uniform(0.1e-6, 1.0e-6), "stick_ratio": rng.uniform(1.0, 1.5)}
    if name == "sensor_drift":
        return {"warmup_N": float(rng.choice([-1.0, 1.0]) * rng.uniform(0.5, 2.0) * strength * 10.0),
                "warmup_tau_s": rng.uniform(30.0, 300.0),
                "reversion_s": float(math.exp(rng.uniform(math.log(300.0), math.log(3000.0))))}
    if name == "bias_error":
        return {"run_fraction": rng.uniform(0.1, 0.5),
                "tau1_s": float(math.exp(rng.uniform(math.log(10), math.log(100)))),
                "tau2_s": float(math.exp(rng.uniform(math.log(200), math.log(2000)))),
                "weight1": rng.uniform(0.2, 0.8)}
    return {}


def _effect(name: str, rng: np.random.Generator, layers: int) -> EffectTruth:
    for _ in range(50):   # a drawn shape that the strength cannot realise (d31 vanishing somewhere) is drawn again
        strength = draw_strength(name, rng)
        shape = {k: float(v) for k, v in draw_shape(name, rng, strength).items()}
        try:
            observable = observables(name, strength, shape, layers)
        except ValueError:
            continue
        decoy = EFFECTS[name].kind == "decoy"
        return EffectTruth(name, strength, shape, decoy, None if decoy else name,
                           library_strength(name, strength, shape), observable)
    raise RuntimeError(f"no realisable shape drawn for {name}")


# The creep candidate's unit (analysis.gap.families): mean growth per decade over these times, as a fraction of
# the response at 1 s. A unit, not a form: the generator's own creep is converted into it below.
LIBRARY_CREEP_SPAN_S = (0.05, 0.4)


def library_strength(name: str, strength: float, shape: dict[str, float]) -> float | None:
    """The effect's size in its library candidate's unit, where the two measure the same quantity (None
    otherwise). Creep is drawn as growth per decade over 10 ms - 100 s, but the candidate's unit spans the ages
    the actuator protocol's dwell observes (50 - 400 ms): the generator's own step response is read there."""
    if name == "creep":
        from sim_devices.drive_chain import PronyCreep, creep_shape

        t0, t1 = LIBRARY_CREEP_SPAN_S
        early, late, at_1s = PronyCreep(strength, **creep_shape(shape)).step_response(np.array([t0, t1, 1.0]))
        return float((late - early) / at_1s / math.log10(t1 / t0))
    return strength if name in SAME_UNIT else None


# ------------------------------------------------------------------ observables comparable across forms
def observables(name: str, strength: float, shape: dict[str, float], layers: int = 2) -> dict[str, float]:
    """What the effect does to quantities any form can be compared on (the nominal `layers` actuator, effective
    values); raises ValueError when the strength and shape cannot be realised."""
    a = actuator_preset(layers, "effective")
    f250 = float(act.blocked_force_N(a, 250.0))
    d250 = float(act.free_displacement_m(a, 250.0))
    if name in ("width_loss", "pzt_thickness", "pzt_modulus", "grounding_lengthening"):
        (effect,) = model_effects({name: strength})
        b = effect.actuator_params(a)
        return {"blocked_force_change_250V": float(act.blocked_force_N(b, 250.0)) / f250 - 1.0,
                "free_displacement_change_250V": float(act.free_displacement_m(b, 250.0)) / d250 - 1.0}
    if name == "field_dependent_d31":
        from sim_devices.drive_chain import FIELD_HIGH_V_PER_M, FIELD_LOW_V_PER_M, FieldGain, gain_shape

        g = FieldGain(strength, **gain_shape(shape))
        return {"blocked_force_change_250V": float(g(FIELD_HIGH_V_PER_M)) - 1.0,
                "blocked_force_change_100V": float(g(FIELD_LOW_V_PER_M)) - 1.0}
    if name == "hysteresis":
        from sim_devices.drive_chain import hysteresis_setup

        hysteresis_setup(strength, shape)
        return {"gap_over_span_250V": strength}
    if name == "creep":
        from sim_devices.drive_chain import PronyCreep, creep_shape

        c = PronyCreep(strength, **creep_shape(shape))
        t = np.logspace(-2, 0, 41)
        slope = float(np.polyfit(np.log10(t), c.step_response(t), 1)[0])
        return {"log_slope_10ms_1s_per_decade": slope}
    if name == "base_compliance":
        from sim_devices.contact_statics import ActuatorStatics, make_clamp

        clamp = make_clamp(strength, a, shape)
        k = act.stiffness_N_per_m(a)
        out = {}
        for v in (100.0, 250.0):
            u = float(act.free_displacement_m(a, v))
            f = float(ActuatorStatics(k, 1e12, clamp).contact_force_N(np.array([u]), np.array([0.0]))[0])
            out[f"blocked_force_loss_{int(v)}V"] = 1.0 - f / (k * u)
        return out
    return {}
