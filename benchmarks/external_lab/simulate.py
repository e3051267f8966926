"""One case's specimens and sessions, and the time series of one specimen block (one test at one bias
voltage): drive -> amplifier -> each plate's voltage -> the material effects -> the cantilever's free
deflection -> either the contact force on the sensor (blocked) or the camera's view of the tip (free) -> the
instruments.

The session clock runs over the whole case (per layer count: each specimen mounted once, its tests at every
bias in turn), so the drift, the amplifier's warming and a plate's depolarisation carry from block to block as
they would on a bench.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import lru_cache
from typing import Any

import numpy as np

from benchmarks.external_lab import effects as fx
from benchmarks.external_lab import mechanics, physics, sensors
from benchmarks.external_lab.cases import Case
from benchmarks.external_lab.drive import Amplifier, AmplifierDroop, DriveTiming, bias_waveform, drive_command

SEED_ROOT = 20251


@dataclass
class Specimen:
    """One actuator as mounted: its build (truth), its label, its contact gap and its plates' polarisation."""

    label: str
    layers: int
    index: int
    build: physics.Build
    gap_m: float
    hysteresis_share_scale: float
    polarisation_top: float = 1.0
    polarisation_bottom: float = 1.0


@dataclass(frozen=True)
class Block:
    """One specimen block of one file: where it sits on the session clock and what was recorded."""

    specimen: Specimen
    test: str
    bias_V: float
    session_start_s: float      # session time of the block's first recorded sample
    tare_session_s: float       # when the force sensor was last tared (blocked)
    rng_key: tuple[int, ...]


@dataclass
class BlockData:
    time_s: np.ndarray
    voltage_V: np.ndarray
    force_N: np.ndarray | None
    displacement_m: np.ndarray | None
    notes: dict[str, float] = field(default_factory=dict)


def _effect_params(case: Case, name: str) -> dict[str, Any] | None:
    e = case.effect(name)
    return e["params"] if e else None


def build_for(case: Case, layers: int, spec_index: int) -> physics.Build:
    """Table I off by the build's tolerance, then the fabrication effects, then this specimen's scatter."""
    b = physics.nominal_build(layers)
    tol = case.tolerance
    b = replace(b, width_nom_m=b.width_nom_m * (1 + tol["width"]),
                pzt_bottom_m=b.pzt_bottom_m * (1 + tol["pzt"]), pzt_top_m=b.pzt_top_m * (1 + tol["pzt"]),
                modulus_bottom_Pa=b.modulus_bottom_Pa * (1 + tol["modulus"]),
                modulus_top_Pa=b.modulus_top_Pa * (1 + tol["modulus"]),
                d31_bottom_m_per_V=b.d31_bottom_m_per_V * (1 + tol["d31"]),
                d31_top_m_per_V=b.d31_top_m_per_V * (1 + tol["d31"]),
                length_m=b.length_m * (1 + tol["length"]),
                cf_thickness_m=b.cf_thickness_m * (1 + tol["cf_layer"]),
                cf_modulus_Pa=b.cf_modulus_Pa * (1 + tol["cf_modulus"]))
    b = apply_fabrication(case, b)
    s = case.scatter[case.layers.index(layers) * case.n_specimens + spec_index]
    b = replace(b, width_nom_m=b.width_nom_m * (1 + s["width"]), pzt_bottom_m=b.pzt_bottom_m * (1 + s["pzt"]),
                pzt_top_m=b.pzt_top_m * (1 + s["pzt_top"]),
                modulus_bottom_Pa=b.modulus_bottom_Pa * (1 + s["modulus"]),
                modulus_top_Pa=b.modulus_top_Pa * (1 + s["modulus"]),
                d31_bottom_m_per_V=b.d31_bottom_m_per_V * (1 + s["d31"]),
                d31_top_m_per_V=b.d31_top_m_per_V * (1 + s["d31"]), length_m=b.length_m * (1 + s["length"]))
    g = _effect_params(case, "grounding")
    if g:
        rng = np.random.default_rng([SEED_ROOT, case.seed, layers, spec_index, 77])
        lengthening = g["lengthening"] * (1 + g["mount_scatter"] * float(np.clip(rng.normal(), -2, 2)))
        b = physics.clamp_for_lengthening(b, max(lengthening, 0.002), g["clamp_length_m"])
    return b


def apply_fabrication(case: Case, b: physics.Build) -> physics.Build:
    """The fabrication effects of the case (shared by every specimen of the build)."""
    if p := _effect_params(case, "width_loss"):
        b = replace(b, edge_band_m=p["band_fraction"] * b.width_nom_m,
                    edge_band_modulus_factor=p["band_modulus_factor"])
    if p := _effect_params(case, "pzt_thickness"):
        b = replace(b, pzt_bottom_m=b.pzt_bottom_m * p["bottom_factor"],
                    pzt_top_m=b.pzt_top_m * p["top_factor"])
    if p := _effect_params(case, "pzt_modulus"):
        b = replace(b, modulus_bottom_Pa=b.modulus_bottom_Pa * p["bottom_factor"],
                    modulus_top_Pa=b.modulus_top_Pa * p["top_factor"])
    if p := _effect_params(case, "length"):
        b = replace(b, length_m=b.length_m * p["factor"])
    return b


def specimens_for(case: Case, layers: int) -> list[Specimen]:
    out = []
    for k, label in enumerate(case.specimen_labels):
        rng = np.random.default_rng([SEED_ROOT, case.seed, layers, k, 78])
        out.append(Specimen(label=label, layers=layers, index=k, build=build_for(case, layers, k),
                            gap_m=case.contact_gap_m[case.layers.index(layers) * case.n_specimens + k],
                            hysteresis_share_scale=float(1 + 0.08 * np.clip(rng.normal(), -2, 2))))
    return out


@lru_cache(maxsize=256)
def coefficients(build: physics.Build, modulus_scale: float = 1.0) -> physics.Coefficients:
    return physics.solve_cantilever(build, modulus_scale)


def timing_of(case: Case) -> DriveTiming:
    t = case.timing
    return DriveTiming(dwell_low_s=t["dwell_low_s"], dwell_high_s=t["dwell_high_s"],
                       ramp_s=tuple(t["ramp_s"]), cycles=t["cycles"], repetitions=t["repetitions"],
                       pause_s=t["pause_s"], lead_s=t["lead_s"], tail_s=t["tail_s"],
                       pre_roll_s=t["pre_roll_s"])


def creep_of(case: Case) -> fx.KohlrauschCreep | None:
    p = _effect_params(case, "creep")
    if not p:
        return None
    unit = fx.KohlrauschCreep(1.0, p["beta"], p["tau_s"])
    lo, hi = unit.step_response(np.array([0.1, 10.0])) - 1.0
    g = p["per_decade"]
    return fx.KohlrauschCreep(2 * g / (hi - lo - 2 * g * lo), p["beta"], p["tau_s"])


def d31_law_of(case: Case, layers: int) -> fx.RayleighAmplitudeD31 | fx.CubicFieldD31 | None:
    e = case.effect("d31_field")
    if not e:
        return None
    full_field = 250.0 / (physics.TABLE_I_EFFECTIVE["pzt_thickness_m"] * 1e6)
    g = e["params"]["gain_at_full_field"]
    if e["variant"] == "rayleigh-amplitude":
        return fx.RayleighAmplitudeD31(alpha=(g - 1.0) * fx.FIELD_REF_V_PER_UM / full_field)
    return fx.CubicFieldD31(b=g - 1.0, field_ref_V_per_um=full_field)


def hysteresis_of(case: Case, specimen: Specimen) -> fx.KPHysteresis | None:
    p = _effect_params(case, "hysteresis")
    if not p:
        return None
    return fx.KPHysteresis(share=min(p["share"] * specimen.hysteresis_share_scale, 0.6),
                           width_scale=p["width_scale"], width_skew=p["width_skew"], ramp=p["ramp"])


def series_springs(case: Case, k_act: float) -> list[mechanics.Deflection]:
    """Base spring (if any) and the sensor's contact, scaled to the actuator's stiffness."""
    springs: list[mechanics.Deflection] = []
    e = case.effect("base_compliance")
    if e:
        p = e["params"]
        if e["variant"] == "sinh-hardening":
            springs.append(mechanics.SinhBaseSpring(p["k0_over_k_act"] * k_act, p["hardening_m"]).deflection)
        else:
            push = p["push_over_k_act"] * k_act
            spring = mechanics.AsymmetricBaseSpring(push, push * p["pull_over_push"], p["blend_N"])
            springs.append(spring.deflection)
    if p := _effect_params(case, "sensor_compliance"):
        hertz = 0.1 / p["hertz_indent_at_100mN_m"] ** 1.5
        springs.append(mechanics.SensorContact(p["k_over_k_act"] * k_act, hertz).deflection)
    else:
        springs.append(mechanics.SensorContact().deflection)
    return springs


def plate_response(case: Case, specimen: Specimen, t: np.ndarray, v_plate: np.ndarray, thickness_m: float
                   ) -> np.ndarray:
    """A plate's effective voltage: the hysteresis operator on its voltage (its kernels span the plate's
    voltage range), times the field law's d31 gain at the plate's field, then creep acting on what that
    produces."""
    e = v_plate
    if hyst := hysteresis_of(case, specimen):
        e = hyst.apply(e)
    if law := d31_law_of(case, specimen.layers):
        e = e * law.gain(v_plate, thickness_m)
    if creep := creep_of(case):
        e = creep.apply(t, e)
    return e


def simulate_block(case: Case, block: Block, drift: tuple[np.ndarray, np.ndarray] | None,
                   droop_state: float) -> tuple[BlockData, float]:
    """The recorded rows of one block, and the amplifier's thermal state at its end."""
    rng = np.random.default_rng([SEED_ROOT, case.seed, *block.rng_key])
    sp = block.specimen
    timing = timing_of(case)
    rate = case.sample_rate_Hz
    t, v_cmd, driven = drive_command(timing, block.bias_V, rate)
    t_session = block.session_start_s + t
    notes: dict[str, float] = {}
    gain: np.ndarray | float = 1.0
    if p := _effect_params(case, "amplifier_droop"):
        droop = AmplifierDroop(p["max_droop"], p["tau_s"])
        gain, droop_state = droop.gain(t_session, block.bias_V, droop_state)
        notes["droop_max"] = float(1.0 - np.min(gain))
    v_drive = Amplifier(case.amplifier_tau_s).output(t, v_cmd, gain)
    v_bias = bias_waveform(t, block.bias_V)
    b = sp.build
    e_bottom = plate_response(case, sp, t, v_drive, b.pzt_bottom_m) * sp.polarisation_bottom
    e_top = plate_response(case, sp, t, v_bias - v_drive, b.pzt_top_m) * sp.polarisation_top
    c = coefficients(b)
    a_bottom: np.ndarray | float = c.free_bottom_m_per_V
    a_top: np.ndarray | float = c.free_top_m_per_V
    compliance: np.ndarray | float = c.compliance_m_per_N
    if p := _effect_params(case, "thermal_modulus"):
        heating = fx.SelfHeatingModulus(p["per_K"], p["heat_K"], p["tau_s"])
        duty = float(np.mean(np.abs(np.diff(v_cmd)) > 0))
        scale = heating.modulus_scale(t, driven, block.bias_V, duty)
        soft = coefficients(b, 0.8)
        w = (1.0 - scale) / 0.2    # linear between the coefficients at scale 1 and 0.8
        a_bottom = c.free_bottom_m_per_V + w * (soft.free_bottom_m_per_V - c.free_bottom_m_per_V)
        a_top = c.free_top_m_per_V + w * (soft.free_top_m_per_V - c.free_top_m_per_V)
        compliance = c.compliance_m_per_N + w * (soft.compliance_m_per_N - c.compliance_m_per_N)
        notes["modulus_drop_max"] = float(1.0 - np.min(scale))
    free = a_bottom * e_bottom - a_top * e_top
    rec = t >= 0.0
    mon = case.monitor
    seen_V = v_drive if mon["source"] == "amplifier" else v_cmd
    voltage = seen_V[rec] + mon["noise_V"] * rng.standard_normal(int(rec.sum()))
    if block.test == "blocked":
        fs = case.force_sensor
        springs = series_springs(case, c.stiffness_N_per_m)
        force = mechanics.contact_force(free, compliance, sp.gap_m, springs, push_only=fs["push_only"])
        baseline = np.zeros(t.size)
        if drift is not None:
            grid, base = drift
            baseline = np.interp(t_session, grid, base) - float(np.interp(block.tare_session_s, grid, base))
            notes["drift_pp_N"] = float(np.ptp(baseline[rec]))               # within the block
            notes["drift_since_tare_N"] = float(np.max(np.abs(baseline[rec])))   # since the mounting's tare
        sensor = sensors.ForceSensor(kind=fs["kind"], noise_N=fs["noise_N"], filter_s=fs["filter_s"],
                                     lag_s=fs["lag_s"], decimation=fs["decimation"], scale=fs["scale"],
                                     push_only=fs["push_only"], resolution_N=fs["resolution_N"])
        reading = sensor.read(t, force, baseline, rng)[rec]
        kept = np.full(reading.size, np.nan)
        kept[::fs["decimation"]] = reading[::fs["decimation"]]
        return BlockData(t[rec], voltage, kept, None, notes), droop_state
    cam = case.camera
    camera = sensors.Camera(cam["decimation"], cam["exposure_rows"], cam["noise_m"], cam["offset_m"])
    return BlockData(t[rec], voltage, None, camera.read(free[rec], rng), notes), droop_state


def depolarise(case: Case, specimen: Specimen, bias_V: float) -> None:
    """After a block: the lab parks the drive at V_bias / 2 and switches the bias off first (decoy)."""
    if p := _effect_params(case, "depolarisation"):
        d = fx.ReverseFieldDepolarisation(p["max_loss"], p["coercive_V_per_um"], p["spread_V_per_um"])
        specimen.polarisation_top *= 1.0 - d.loss(bias_V / 2.0 / (specimen.build.pzt_top_m * 1e6))


def drift_baseline(case: Case, session_s: float) -> tuple[np.ndarray, np.ndarray] | None:
    p = _effect_params(case, "drift")
    if not p:
        return None
    room = sensors.RoomTemperature(**case.room)
    model = sensors.ThermalDrift(p["coupling_N_per_K"], p["sensor_tau_s"], p["warmup_K"], p["warmup_tau_s"],
                                 p["pink_N"])
    return model.baseline(room, session_s, seed=case.seed * 1000 + 17)


def jitter(case: Case, key: str, *salt: int) -> float:
    """A session gap: the case's mean gap +-30 %, drawn per occurrence."""
    rng = np.random.default_rng([SEED_ROOT, case.seed, 99, *salt])
    return case.session_gaps_s[key] * float(rng.uniform(0.7, 1.3))


def schedule(case: Case) -> list[Block]:
    """Every block in the order the lab ran them: per layer count, each specimen mounted once, its tests in
    the case's order, each at every bias voltage (ascending)."""
    timing = timing_of(case)
    blocks: list[Block] = []
    t = case.session_gaps_s["session_start_s"]
    for li, layers in enumerate(case.layers):
        for sp in specimens_for(case, layers):
            if blocks:
                t += jitter(case, "remount_s", li, sp.index)
            tare = t
            for ti, test in enumerate(case.tests):
                if ti:
                    t += jitter(case, "next_test_s", li, sp.index, ti)
                if test == "blocked":
                    tare = t
                for vi, v in enumerate(case.voltages_V):
                    if vi:
                        t += jitter(case, "next_voltage_s", li, sp.index, ti, vi)
                    bias = v + float(np.random.default_rng([SEED_ROOT, case.seed, 5, li, sp.index, ti, vi])
                                     .normal(0.0, 0.4))
                    t += timing.pre_roll_s
                    blocks.append(Block(sp, test, bias, t, tare, (li, sp.index, ti, vi)))
                    t += timing.duration_s()
    return blocks


def session_length_s(blocks: list[Block], case: Case) -> float:
    return (blocks[-1].session_start_s + timing_of(case).duration_s() + 60.0) if blocks else 0.0


def run_session(case: Case) -> list[tuple[Block, BlockData]]:
    """Simulate every block in session order (the states that carry over are updated in that order)."""
    blocks = schedule(case)
    drift = drift_baseline(case, session_length_s(blocks, case))
    droop = 0.0
    last_end = 0.0
    droop_tau = (_effect_params(case, "amplifier_droop") or {}).get("tau_s", math.inf)
    out = []
    for blk in blocks:
        start = blk.session_start_s - timing_of(case).pre_roll_s
        droop *= math.exp(-(start - last_end) / droop_tau) if math.isfinite(droop_tau) else 0.0
        data, droop = simulate_block(case, blk, drift, droop)
        last_end = blk.session_start_s + float(data.time_s[-1])
        depolarise(case, blk.specimen, blk.bias_V)
        data.notes["polarisation_top_after"] = blk.specimen.polarisation_top
        out.append((blk, data))
    return out
