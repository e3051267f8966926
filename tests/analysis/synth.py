"""Synthetic recordings for the analysis tests, written with the Recorder to the runner's contract (metadata
`design` / `protocol` / `run`; `step`, `set_voltages`, `drive_start`, `drive_end`, `contact_found` events; the
drive command waveform sample by sample; /force; /camera/displacement relative to the first frame of each drive).

The traces come from the model's primitives evaluated along the drive waveform (foot_force_N / free_foot_height_m /
tip force over time), not from analysis/observations.py, so the dataset's reduction of traces to observations is
checked against an independent path. Noise: white sensor noise per sample, a per-step offset (drift / re-seating
between repetitions), white camera noise per frame. `table_observations` draws the same thing at the level of
per-step means (for the many-seed coverage test, where writing files would only cost time).
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from analysis.dataset import Observation
from hamr_bench.model import ActuatorParams, DesignParams, Powertrain, actuator_preset, design_preset
from hamr_bench.protocols import get_protocol
from hamr_bench.protocols.drive import trapezoid_V
from hamr_bench.recording import Recorder


@dataclass(frozen=True)
class Noise:
    force_sample_N: float = 0.3e-3          # leg sensor, per sample (1 kHz)
    force_step_N: float = 0.03e-3           # per-step offset
    actuator_force_sample_N: float = 2e-3   # actuator sensor range is larger
    actuator_force_step_N: float = 0.5e-3
    camera_frame_m: float = 4e-6            # per frame
    camera_step_m: float = 1e-6
    preload_fraction: float = 0.7           # preload left by the contact search, fraction of the release threshold


FORCE_RATE_HZ = 1000.0
CAMERA_RATE_HZ = 60.0


def _metadata(rec: Recorder, protocol: str, design: int | None, layers: int, seed: int, params) -> None:
    fixture = get_protocol(protocol).FIXTURE
    rec.add_metadata("design", {"design": "" if design is None or fixture == "actuator" else str(design),
                                "layers": str(layers), "fixture": fixture, "params_set": "effective",
                                "model_params": "{}"})
    rec.add_metadata("protocol", {"name": protocol, "params": json.dumps(asdict(params)), "protocol_file": ""})
    rec.add_metadata("run", {"seed": str(seed), "clock": "virtual", "effects": "{}", "source": "synthetic"})


def write_recording(path: Path, protocol: str, *, design: int = 4, layers: int = 2, seed: int = 0,
                    actuator: ActuatorParams | None = None, design_params: DesignParams | None = None,
                    noise: Noise = Noise(), set_params: dict | None = None) -> Path:
    """One synthetic run of `protocol` (default protocol parameters, optionally replaced) into `path`."""
    rng = np.random.default_rng(seed)
    module = get_protocol(protocol)
    params = module.Params()
    if set_params:
        from dataclasses import replace

        params = replace(params, **set_params)
    a = actuator or actuator_preset(layers, "effective")
    is_act = protocol == "actuator"
    pt = None if is_act else Powertrain(a, design_params or design_preset(design))
    rec = Recorder(path, overwrite=True, start_time_ns=0)
    _metadata(rec, protocol, design, layers, seed, params)
    t = 0.0
    rec.write_event(t, "run_start", 0, f"protocol {protocol}")
    f_sample = noise.actuator_force_sample_N if is_act else noise.force_sample_N
    f_step = noise.actuator_force_step_N if is_act else noise.force_step_N

    def force_samples(t0: float, t1: float, fn) -> None:
        ts = np.arange(np.ceil(t0 * FORCE_RATE_HZ), np.floor(t1 * FORCE_RATE_HZ) + 1) / FORCE_RATE_HZ
        offset = rng.normal(0, f_step)
        values = fn(ts) + offset + rng.normal(0, f_sample, ts.size)
        for ti, fi in zip(ts, values):
            rec.write_scalar("/force", float(ti), force_N=float(fi))

    h0 = 0.0
    preload = 0.0
    if protocol != "free-displacement":
        # contact search: the last force window before contact_found reads the preload it left
        release = params.contact.threshold_N / 4
        preload = noise.preload_fraction * release
        if pt is not None:
            h0 = float(pt.static_displacement_m(preload))
        force_samples(t, t + 0.1, lambda ts: np.full(ts.shape, preload))
        t += 0.1
        rec.write_event(t, "contact_found", 0, "zero sag", stage_position_m=1e-3)

    if protocol == "static":
        assert pt is not None  # a leg protocol
        for index, (sag, direction) in enumerate(params.sags_m()):
            t += params.settle_s
            rec.write_event(t, "step", index, f"sag {sag}", voltage_V=0.0, sag_m=float(sag), repetition=0,
                            direction=direction)
            f = max(float(pt.foot_force_N(0.0, 0.0, sag + h0)), 0.0)
            force_samples(t, t + params.hold_s, lambda ts: np.full(ts.shape, f))
            t += params.hold_s + 0.05
        rec.write_event(t, "run_end", 0, "completed", exit_status="success")
        rec.close("success", "completed")
        return path

    d = params.drive
    steps = []
    if protocol == "actuator":
        for mode in ("blocked", "free"):
            for rep in range(params.repetitions):
                for v in sorted(params.voltages_V):
                    steps.append({"voltage_V": v, "repetition": rep, "mode": mode, "direction": "up"})
    elif protocol == "blocked-force":
        for rep in range(params.repetitions):
            down = params.alternate_direction and rep % 2 == 1
            for v in sorted(params.voltages_V, reverse=down):
                steps.append({"voltage_V": v, "sag_m": 0.0, "repetition": rep, "direction": "down" if down else "up"})
    elif protocol == "sag-sweep":
        for rep in range(params.repetitions):
            for s in params.sags_m:
                steps.append({"voltage_V": params.voltage_V, "sag_m": s, "repetition": rep, "direction": "up"})
    else:  # free-displacement
        for rep in range(params.repetitions):
            for v in sorted(params.voltages_V):
                steps.append({"voltage_V": v, "repetition": rep, "direction": "up"})

    for index, cond in enumerate(steps):
        v = float(cond["voltage_V"])
        rec.write_event(t, "step", index, "step", **cond)
        rec.write_event(t, "set_voltages", index, "", bias_V=v, drive_V=0.0)
        rec.write_scalar("/amplifier/bias/command", t, voltage_V=v)
        rec.write_scalar("/amplifier/drive/command", t, voltage_V=0.0)
        t += 0.1
        wave = trapezoid_V(v, d.ramp_s, d.dwell_high_s, d.dwell_low_s, d.cycles, d.sample_rate_Hz)
        tw = t + np.arange(wave.size) / d.sample_rate_Hz
        tracked = protocol == "free-displacement" or cond.get("mode") == "free"
        rec.write_event(t, "drive_start", index, "", sample_rate_Hz=d.sample_rate_Hz, n_samples=int(wave.size),
                        peak_V=float(wave.max()), track=tracked)
        for ti, vi in zip(tw, wave):
            rec.write_scalar("/amplifier/drive/command", float(ti), voltage_V=float(vi))
        t_end = float(tw[-1])

        def drive_at(ts: np.ndarray) -> np.ndarray:
            return np.interp(ts, tw, wave)

        if tracked:
            ts = np.arange(np.ceil(t * CAMERA_RATE_HZ), np.floor(t_end * CAMERA_RATE_HZ) + 1) / CAMERA_RATE_HZ
            vd = drive_at(ts)
            if pt is None:
                pos = a.free_tip_deflection_m(np.full(ts.shape, v), vd)      # positive toward the sensor
            else:
                pos = -pt.free_foot_height_m(np.full(ts.shape, v), vd)      # downward travel
            pos = pos + rng.normal(0, noise.camera_step_m) + rng.normal(0, noise.camera_frame_m, ts.size)
            rel = pos - pos[0]
            for ti, di in zip(ts, rel):
                rec.write_scalar("/camera/displacement", float(ti), displacement_m=float(di), x_px=320.0,
                                 y_px=240.0 + float(di) / 5e-6)
            force_samples(t, t_end, lambda q: np.zeros(q.shape))
        elif pt is None:
            x0 = preload / a.stiffness_N_per_m
            force_samples(t, t_end, lambda q: np.maximum(a.tip_force_N(np.full(q.shape, v), drive_at(q), -x0), 0.0))
        else:
            h = float(cond["sag_m"]) + h0
            force_samples(t, t_end, lambda q: np.maximum(pt.foot_force_N(np.full(q.shape, v), drive_at(q),
                                                                         np.full(q.shape, h)), 0.0))
        t = t_end
        rec.write_event(t, "drive_end", index, "")
        t += 0.05
    rec.write_event(t, "run_end", 0, "completed", exit_status="success")
    rec.close("success", "completed")
    return path


def write_design_set(directory: Path, design: int, seed: int, layers: int = 2, **kw) -> list[Path]:
    """The three fitted leg protocols (plus static) for one design."""
    out = []
    for i, protocol in enumerate(("blocked-force", "sag-sweep", "free-displacement", "static")):
        out.append(write_recording(directory / f"design{design}-{protocol}.mcap", protocol, design=design,
                                   layers=layers, seed=seed * 100 + i, **kw))
    return out


# ------------------------------------------------------------------------------------------- table level
def _sd_mean(sample: float, step: float, n_samples: int) -> float:
    return float(np.sqrt(sample**2 / n_samples + step**2))


def table_observations(design: int, seed: int, noise: Noise = Noise(), layers: int = 2,
                       design_params: DesignParams | None = None) -> list[Observation]:
    """Per-step observations of the three fitted leg protocols drawn directly (same noise as the recordings:
    3 cycles x a 0.2 s averaging window at 1 kHz for force, 3 x 12 frames per plateau pair for the camera)."""
    rng = np.random.default_rng(seed)
    a = actuator_preset(layers, "effective")
    pt = Powertrain(a, design_params or design_preset(design))
    preload = noise.preload_fraction * get_protocol("blocked-force").Params().contact.threshold_N / 4
    h0 = float(pt.static_displacement_m(preload))
    sd_f = _sd_mean(noise.force_sample_N, noise.force_step_N, 3 * 200)
    sd_d = _sd_mean(noise.camera_frame_m * np.sqrt(2), 0.0, 3 * 12)
    obs = []
    step = 0

    def add(run, protocol, quantity, v, sag, rep, value):
        nonlocal step
        obs.append(Observation(run=run, protocol=protocol, fixture="leg", design=design, layers=layers, mode="",
                               quantity=quantity, voltage_V=float(v), sag_m=float(sag), repetition=rep,
                               direction="up", step=step, value=float(value), spread=float("nan"), n_cycles=3,
                               preload_N=preload if protocol != "free-displacement" else 0.0))
        step += 1

    for rep in range(5):
        for v in (100.0, 150.0, 200.0, 250.0):
            f = max(float(pt.foot_force_N(v, v, h0)), 0.0)
            add(0, "blocked-force", "force_N", v, 0.0, rep, f + rng.normal(0, sd_f))
    for rep in range(3):
        for s in (0.0, 1e-3, 2e-3, 3e-3):
            f = max(float(pt.foot_force_N(250.0, 250.0, s + h0)), 0.0)
            add(1, "sag-sweep", "force_N", 250.0, s, rep, f + rng.normal(0, sd_f))
    for rep in range(2):
        for v in (100.0, 150.0, 200.0, 250.0):
            hh = pt.free_foot_height_m(np.array([v, v]), np.array([0.0, v]))
            add(2, "free-displacement", "displacement_m", v, 0.0, rep, hh[0] - hh[1] + rng.normal(0, sd_d))
    return obs


def table_dataset(design: int, seed: int, noise: Noise = Noise(), **kw):
    """A Dataset of `table_observations` with the run descriptions a recording would give."""
    from analysis.dataset import Dataset, Run, RunInfo

    obs = table_observations(design, seed, noise, **kw)
    runs = []
    for index, protocol in enumerate(("blocked-force", "sag-sweep", "free-displacement")):
        info = RunInfo(path=f"table:{protocol}", protocol=protocol, fixture="leg", design=design,
                       layers=obs[0].layers, params_set="effective", model_params={},
                       protocol_params={"contact": {"threshold_N": 0.4e-3}}, seed=str(seed), effects={},
                       exit_status="success", source="synthetic", preload_N=0.0)
        runs.append(Run(info, [o for o in obs if o.run == index]))
    return Dataset(runs, obs)


def table_actuator_dataset(layers: int, seed: int, noise: Noise = Noise(), offset_N: float = 0.6e-3):
    """Actuator-protocol observations drawn per step (3 repetitions x 4 voltages per mode), as the recording gives
    them: force = F_b + offset (the contact search's), stroke = 2 delta."""
    from analysis.dataset import Dataset, Run, RunInfo

    rng = np.random.default_rng(seed)
    a = actuator_preset(layers, "effective")
    sd_f = _sd_mean(noise.actuator_force_sample_N, noise.actuator_force_step_N, 3 * 200)
    sd_d = noise.camera_frame_m * np.sqrt(2 / 36)
    obs = []
    step = 0
    for mode in ("blocked", "free"):
        for rep in range(3):
            for v in (100.0, 150.0, 200.0, 250.0):
                if mode == "blocked":
                    q, value = "force_N", float(a.blocked_force_N(v)) + offset_N + rng.normal(0, sd_f)
                else:
                    q, value = "displacement_m", 2 * float(a.free_displacement_m(v)) + rng.normal(0, sd_d)
                obs.append(Observation(run=0, protocol="actuator", fixture="actuator", design=None, layers=layers,
                                       mode=mode, quantity=q, voltage_V=v, sag_m=0.0, repetition=rep,
                                       direction="up", step=step, value=value, spread=float("nan"), n_cycles=3,
                                       preload_N=0.0))
                step += 1
    info = RunInfo(path="table:actuator", protocol="actuator", fixture="actuator", design=None, layers=layers,
                   params_set="effective", model_params={}, protocol_params={}, seed=str(seed), effects={},
                   exit_status="success", source="synthetic", preload_N=0.0)
    return Dataset([Run(info, obs)], obs)
