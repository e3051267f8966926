"""Drawing one case of the other lab: what kind it is (null, one effect, several, a decoy), each effect's form
and strength, the build (Table I off by fabrication tolerances) and its specimens, the test plan (layer
counts, bias voltages, the drive timing), the instruments and the session's clock. Everything is drawn from
one seed, so a case is reproducible, and everything is plain data (`Case.to_json`): the manifest records it,
the simulator reads it back.

Strengths are realistic, not tuned to any detector: hysteresis 1-4 % of span at small signal to 4-17 % at full
drive; creep 1-2.5 % per decade; d31 up to x1.9 (or down to x0.55) across the field range; grounding
lengthening 2-8 %; width loss 10-24 %, PZT 10-28 % thicker, modulus 12-28 % lower, length 5-12 % longer (the
paper's Table I shifts are 19 %, 22 %, 19 %, 9 %); a Nano17-like sensor (2-4 mN per sample) or a load cell;
camera 0.3-0.8 um.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

# name -> "effect" (a physical effect a diagnosis library should name) | "decoy" (outside every library)
# (the order matters: single-effect cases cycle through it, so any 20 consecutive seeds from 1 cover the first
# eight, the effects the diagnosis had candidates for when this was written, and grounding)
EFFECTS: dict[str, str] = {
    "hysteresis": "effect",
    "creep": "effect",
    "d31_field": "effect",
    "drift": "effect",
    "base_compliance": "effect",
    "sensor_compliance": "effect",
    "width_loss": "effect",
    "grounding": "effect",
    "pzt_thickness": "effect",
    "pzt_modulus": "effect",
    "length": "effect",
    "amplifier_droop": "decoy",
    "sensor_scale": "decoy",
    "depolarisation": "decoy",
    "thermal_modulus": "decoy",
}
PHYSICAL = [n for n, k in EFFECTS.items() if k == "effect"]
DECOYS = [n for n, k in EFFECTS.items() if k == "decoy"]
# Kinds in a fixed pattern over 20 consecutive seeds (8 single, 6 multi, 3 null, 3 decoy), so a development
# set of 20 seeds is balanced; everything else about a case is drawn at random.
KIND_PATTERN = ("single", "multi", "null", "single", "decoy", "single", "multi", "single", "single", "multi",
                "null", "single", "decoy", "multi", "single", "single", "multi", "decoy", "null", "multi")

# Fabrication tolerance of a build (1 sigma, relative; clipped at 2.5 sigma) and specimen-to-specimen scatter.
BUILD_TOLERANCE = {"width": 0.02, "pzt": 0.025, "modulus": 0.03, "d31": 0.03, "length": 0.01,
                   "cf_layer": 0.04, "cf_modulus": 0.05}
SPECIMEN_SCATTER = {"width": 0.015, "pzt": 0.015, "modulus": 0.02, "d31": 0.025, "length": 0.007}
PROJECT_DEFAULT_TIMING = {"ramp_s": 0.05, "dwell_s": 0.4}


@dataclass
class Case:
    case_id: str
    seed: int
    kind: str
    effects: list[dict[str, Any]]                  # {"name", "variant", "params", "observable"}
    layers: list[int]
    voltages_V: list[float]
    n_specimens: int
    specimen_labels: list[str]
    tests: list[str]                               # order within a mounting
    timing: dict[str, Any]
    sample_rate_Hz: float
    force_sensor: dict[str, Any]
    camera: dict[str, Any]
    monitor: dict[str, Any]
    amplifier_tau_s: float
    room: dict[str, float]
    tolerance: dict[str, float]                    # the build's relative offsets from Table I
    scatter: list[dict[str, float]]                # per layer count x specimen (flattened by layer order)
    contact_gap_m: list[float]                     # per layer count x specimen
    session_gaps_s: dict[str, float]      # mean gaps; each gap jitters +-30 %
    time_layout: str                               # "continuous" (session clock) | "restart" (blocks from 0)
    stage_style: str                               # "blank" | "constant" | "first-row"
    stage_m: dict[str, float]
    csv_precision: dict[str, str] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return asdict(self)

    def effect(self, name: str) -> dict[str, Any] | None:
        return next((e for e in self.effects if e["name"] == name), None)


def _u(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(rng.uniform(lo, hi))


def _logu(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _clipped_normal(rng: np.random.Generator, sigma: float) -> float:
    return float(np.clip(rng.normal(0.0, sigma), -2.5 * sigma, 2.5 * sigma))


Draw = tuple[str, dict[str, float]]


def _hysteresis(rng: np.random.Generator, bonded: bool) -> Draw:
    return "krasnoselskii-pokrovskii", {"share": _u(rng, 0.12, 0.4), "width_scale": _logu(rng, 0.5, 3.0),
                                        "width_skew": _u(rng, -0.8, 0.8), "ramp": _u(rng, 0.01, 0.05)}


def _creep(rng: np.random.Generator, bonded: bool) -> Draw:
    return "kohlrausch", {"per_decade": _u(rng, 0.01, 0.025), "beta": _u(rng, 0.25, 0.55),
                          "tau_s": _logu(rng, 0.3, 30.0)}


def _d31_field(rng: np.random.Generator, bonded: bool) -> Draw:
    if rng.random() < 0.6:
        return "rayleigh-amplitude", {"gain_at_full_field": _u(rng, 1.2, 1.9)}
    rise = rng.random() < 0.5
    return "cubic", {"gain_at_full_field": _u(rng, 1.3, 1.9) if rise else _u(rng, 0.55, 0.8)}


def _drift(rng: np.random.Generator, bonded: bool) -> Draw:
    return "thermal-first-order+pink", {
        "coupling_N_per_K": _u(rng, 3e-3, 10e-3), "sensor_tau_s": _logu(rng, 30.0, 200.0),
        "warmup_K": _u(rng, 1.5, 5.0), "warmup_tau_s": _logu(rng, 120.0, 900.0),
        "pink_N": _u(rng, 1e-3, 3e-3)}


def _base_compliance(rng: np.random.Generator, bonded: bool) -> Draw:
    # the pull side only shows when the sensor is bonded to the tip (a push-only sensor never pulls)
    if bonded and rng.random() < 0.4:
        return "push-pull-asymmetric", {"push_over_k_act": _u(rng, 3.0, 8.0),
                                        "pull_over_push": _u(rng, 0.3, 0.6), "blend_N": 5e-3}
    return "sinh-hardening", {"k0_over_k_act": _u(rng, 2.5, 8.0), "hardening_m": _u(rng, 2e-6, 10e-6)}


def _grounding(rng: np.random.Generator, bonded: bool) -> Draw:
    return "winkler-clamp", {"lengthening": _u(rng, 0.02, 0.08), "clamp_length_m": _u(rng, 0.8e-3, 1.6e-3),
                             "mount_scatter": 0.15}


def _sensor_compliance(rng: np.random.Generator, bonded: bool) -> Draw:
    return "linear+hertz", {"k_over_k_act": _u(rng, 6.0, 20.0),
                            "hertz_indent_at_100mN_m": _u(rng, 0.5e-6, 2.5e-6)}


def _width_loss(rng: np.random.Generator, bonded: bool) -> Draw:
    return "heat-affected-edge-band", {"band_fraction": _u(rng, 0.05, 0.12),
                                       "band_modulus_factor": _u(rng, 0.2, 0.6)}


def _pzt_thickness(rng: np.random.Generator, bonded: bool) -> Draw:
    return "asymmetric-plates", {"bottom_factor": _u(rng, 1.10, 1.28), "top_factor": _u(rng, 1.10, 1.28)}


def _pzt_modulus(rng: np.random.Generator, bonded: bool) -> Draw:
    return "asymmetric-plates", {"bottom_factor": _u(rng, 0.72, 0.88), "top_factor": _u(rng, 0.72, 0.88)}


def _length(rng: np.random.Generator, bonded: bool) -> Draw:
    return "longer-active-length", {"factor": _u(rng, 1.05, 1.12)}


def _amplifier_droop(rng: np.random.Generator, bonded: bool) -> Draw:
    return "thermal-gain-droop", {"max_droop": _u(rng, 0.08, 0.16), "tau_s": _logu(rng, 15.0, 90.0)}


def _sensor_scale(rng: np.random.Generator, bonded: bool) -> Draw:
    return "calibration-reads-high", {"scale": _u(rng, 1.06, 1.15)}


def _depolarisation(rng: np.random.Generator, bonded: bool) -> Draw:
    return "reverse-field-between-runs", {"max_loss": _u(rng, 0.02, 0.06),
                                          "coercive_V_per_um": _u(rng, 0.35, 0.6), "spread_V_per_um": 0.1}


def _thermal_modulus(rng: np.random.Generator, bonded: bool) -> Draw:
    return "self-heating", {"per_K": _u(rng, 0.004, 0.01), "heat_K": _u(rng, 8.0, 20.0),
                            "tau_s": _logu(rng, 5.0, 30.0)}


DRAWS: dict[str, Callable[[np.random.Generator, bool], Draw]] = {
    "hysteresis": _hysteresis, "creep": _creep, "d31_field": _d31_field, "drift": _drift,
    "base_compliance": _base_compliance, "sensor_compliance": _sensor_compliance, "width_loss": _width_loss,
    "grounding": _grounding, "pzt_thickness": _pzt_thickness, "pzt_modulus": _pzt_modulus, "length": _length,
    "amplifier_droop": _amplifier_droop, "sensor_scale": _sensor_scale, "depolarisation": _depolarisation,
    "thermal_modulus": _thermal_modulus,
}


def draw_effect(name: str, rng: np.random.Generator, bonded_sensor: bool) -> dict[str, Any]:
    """Form and strength of one effect as plain data (simulate.py builds the objects); `observable` is filled
    in after the case is simulated (truth.py)."""
    if name not in DRAWS:
        raise ValueError(f"unknown effect {name!r}")
    variant, params = DRAWS[name](rng, bonded_sensor)
    return {"name": name, "variant": variant, "params": params, "observable": {}}


MAX_ROWS_PER_BLOCK = 25_000   # keeps a case's files in the tens of MB and its import in seconds


def _draw_timing(rng: np.random.Generator, rate_Hz: float) -> dict[str, Any]:
    while True:
        ramp = _logu(rng, 0.01, 0.2)
        dwell_low, dwell_high = _u(rng, 0.15, 0.7), _u(rng, 0.15, 0.7)
        near_default = (abs(ramp - PROJECT_DEFAULT_TIMING["ramp_s"]) < 0.012
                        and abs(dwell_high - PROJECT_DEFAULT_TIMING["dwell_s"]) < 0.08)
        if not near_default:
            break
    ramps = [ramp]
    if rng.random() < 0.5:
        ramps.append(min(ramp * _u(rng, 3.0, 6.0), 0.5))
    timing: dict[str, Any] = {"dwell_low_s": dwell_low, "dwell_high_s": dwell_high, "ramp_s": ramps,
                              "cycles": int(rng.integers(3, 7)),
                              "repetitions": int(rng.choice([2, 3], p=[0.7, 0.3])),
                              "pause_s": _u(rng, 0.5, 2.5), "lead_s": _u(rng, 0.3, 1.5),
                              "tail_s": _u(rng, 0.3, 1.0),
                              "pre_roll_s": _u(rng, 1.0, 6.0)}

    def rows() -> float:
        period = [dwell_low + dwell_high + 2 * ramps[k % len(ramps)] for k in range(timing["repetitions"])]
        return rate_Hz * (timing["cycles"] * sum(period) + timing["pause_s"] * (timing["repetitions"] - 1)
                          + timing["lead_s"] + timing["tail_s"])

    while rows() > MAX_ROWS_PER_BLOCK and (timing["cycles"] > 2 or timing["repetitions"] > 2):
        if timing["cycles"] > 2:
            timing["cycles"] -= 1
        else:
            timing["repetitions"] -= 1
    return timing


def _draw_instruments(rng: np.random.Generator, rate_Hz: float) -> tuple[dict, dict, dict]:
    push_only = bool(rng.random() < 0.6)
    if rng.random() < 0.6:
        sensor = {"kind": "nano17", "noise_N": _u(rng, 2e-3, 4e-3), "filter_s": _u(rng, 0.1e-3, 0.6e-3),
                  "lag_s": 0.0, "decimation": 1, "resolution_N": 1.0 / 640.0}
    else:
        rate = float(rng.choice([r for r in (250.0, 500.0, 1000.0) if rate_Hz % r == 0] or [rate_Hz]))
        sensor = {"kind": "load-cell", "noise_N": _u(rng, 0.5e-3, 1.5e-3), "filter_s": _u(rng, 1e-3, 5e-3),
                  "lag_s": _u(rng, 0.0, 8e-3), "decimation": int(round(rate_Hz / rate)), "resolution_N": 1e-4}
    sensor.update(push_only=push_only, scale=1.0)
    fps_choices = [f for f in (100.0, 125.0, 200.0, 250.0, 500.0) if rate_Hz % f == 0]
    fps = float(rng.choice(fps_choices))
    decimation = int(round(rate_Hz / fps))
    camera = {"fps": fps, "decimation": decimation,
              "exposure_rows": max(1, int(round(decimation * _u(rng, 0.3, 0.9)))),
              "noise_m": _u(rng, 0.3e-6, 0.8e-6)}
    monitor = {"noise_V": _u(rng, 0.05, 0.5), "source": "amplifier" if rng.random() < 0.5 else "command"}
    return sensor, camera, monitor


def _kind_and_effects(seed: int, rng: np.random.Generator) -> tuple[str, list[str]]:
    """The seed's slot in KIND_PATTERN gives the kind; single-effect and decoy cases cycle through their lists
    (the k-th single case of the sequence seed 1, 2, ... gets effect k mod 11); multi-effect cases draw 2 (70
    %) or 3 distinct effects at random."""
    slot, cycle = (seed - 1) % len(KIND_PATTERN), (seed - 1) // len(KIND_PATTERN)
    kind = KIND_PATTERN[slot]
    if kind == "null":
        return kind, []
    if kind in ("single", "decoy"):
        per_cycle = KIND_PATTERN.count(kind)
        index = cycle * per_cycle + KIND_PATTERN[:slot].count(kind)
        names = PHYSICAL if kind == "single" else DECOYS
        return kind, [names[index % len(names)]]
    n = 2 if rng.random() < 0.7 else 3
    return kind, [str(x) for x in rng.choice(PHYSICAL, size=n, replace=False)]


def draw_case(seed: int) -> Case:
    """Everything about case `seed`, drawn from one generator in a fixed order."""
    rng = np.random.default_rng(np.random.SeedSequence([20251, seed]))
    kind, names = _kind_and_effects(seed, rng)
    rate = float(rng.choice([1000.0, 2000.0, 2500.0, 5000.0], p=[0.45, 0.35, 0.1, 0.1]))
    sensor, camera, monitor = _draw_instruments(rng, rate)
    effects = [draw_effect(n, rng, bonded_sensor=not sensor["push_only"]) for n in names]
    if any(e["name"] == "amplifier_droop" for e in effects):
        monitor["source"] = "command"   # a monitor on the amplifier's output would show the droop
    if any(e["name"] == "sensor_scale" for e in effects):
        sensor["scale"] = next(e for e in effects if e["name"] == "sensor_scale")["params"]["scale"]
    n_layers = int(rng.choice([1, 2, 3], p=[0.55, 0.3, 0.15]))
    layers = sorted(int(x) for x in rng.choice([1, 2, 3], size=n_layers, replace=False))
    step = float(rng.choice([25.0, 50.0]))
    lo = float(rng.choice([100.0, 125.0, 150.0])) if step == 25.0 else 100.0
    grid = np.arange(lo, 250.0 + 1e-9, step)
    n_v = min(int(grid.size), int(rng.integers(3, 6)))
    voltages = sorted(float(v) for v in rng.choice(grid, size=n_v, replace=False))
    n_spec = int(rng.choice([2, 3, 4], p=[0.15, 0.7, 0.15]))
    if rng.random() < 0.5:
        labels = [str(i + 1) for i in range(n_spec)]
    else:
        batch = str(rng.choice(["A", "B", "K", "X"]))
        first = int(rng.integers(1, 20))
        labels = [f"{batch}{first + i:02d}" for i in range(n_spec)]
    tests = ["blocked", "free"] if rng.random() < 0.7 else ["free", "blocked"]
    timing = _draw_timing(rng, rate)
    tolerance = {k: _clipped_normal(rng, s) for k, s in BUILD_TOLERANCE.items()}
    scatter = [{k: _clipped_normal(rng, s) for k, s in SPECIMEN_SCATTER.items()}
               | {"pzt_top": _clipped_normal(rng, SPECIMEN_SCATTER["pzt"])} for _ in range(n_layers * n_spec)]
    gaps = [float(rng.normal(0.0, 0.7e-6)) for _ in range(n_layers * n_spec)]
    room = {"trend_K_per_h": _u(rng, -1.0, 1.0), "hvac_K": _u(rng, 0.1, 0.6),
            "hvac_period_s": _u(rng, 300, 1500), "hvac_phase": _u(rng, 0.0, 2 * math.pi)}
    session = {"next_voltage_s": _u(rng, 5.0, 40.0), "next_test_s": _u(rng, 30.0, 120.0),
               "remount_s": _u(rng, 60.0, 300.0), "session_start_s": _u(rng, 30.0, 600.0)}
    time_layout = "continuous" if rng.random() < 0.5 else "restart"
    stage_style = str(rng.choice(["blank", "constant", "first-row"], p=[0.4, 0.3, 0.3]))
    stage = {"blocked_m": _u(rng, 5e-3, 20e-3), "retract_m": _u(rng, 1e-3, 3e-3)}
    camera["offset_m"] = _u(rng, -50e-6, 50e-6)
    return Case(case_id=f"case-{seed:04d}", seed=seed, kind=kind, effects=effects, layers=layers,
                voltages_V=voltages, n_specimens=n_spec, specimen_labels=labels, tests=tests, timing=timing,
                sample_rate_Hz=rate, force_sensor=sensor, camera=camera, monitor=monitor,
                amplifier_tau_s=_u(rng, 0.05e-3, 0.4e-3), room=room, tolerance=tolerance, scatter=scatter,
                contact_gap_m=gaps, session_gaps_s=session, time_layout=time_layout, stage_style=stage_style,
                stage_m=stage)
