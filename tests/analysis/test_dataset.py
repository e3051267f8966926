"""Recordings -> per-condition observations: the reduction of raw traces checked against the model evaluated
independently (tests/analysis/synth.py writes traces from the model's primitives along the drive waveform)."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.dataset import load_dataset, plateau_windows
from hamr_bench.model import actuator_preset, powertrain
from hamr_bench.protocols.drive import trapezoid_V
from tests.analysis.synth import Noise, write_recording


def test_plateau_windows_follow_the_trapezoid():
    rate = 1000.0
    wave = trapezoid_V(200.0, ramp_s=0.05, dwell_high_s=0.4, dwell_low_s=0.4, cycles=3, sample_rate_Hz=rate)
    t = 10.0 + np.arange(wave.size) / rate
    cycles = plateau_windows(t, wave, settle_s=0.2)
    assert len(cycles) == 3
    period = 0.9
    for k, ((la, lb), (ha, hb)) in enumerate(cycles):
        # low dwell [kP, kP + 0.4], high dwell [kP + 0.45, kP + 0.85]; the last 0.2 s of each is averaged
        assert la == pytest.approx(10.0 + k * period + 0.2, abs=2e-3)
        assert lb == pytest.approx(10.0 + k * period + 0.4, abs=2e-3)
        assert ha == pytest.approx(10.0 + k * period + 0.65, abs=2e-3)
        assert hb == pytest.approx(10.0 + k * period + 0.85, abs=2e-3)
        assert np.all(np.interp(np.linspace(ha, hb, 20), t, wave) > 0.99 * 200.0)


@pytest.fixture(scope="module")
def leg_runs(tmp_path_factory):
    d = tmp_path_factory.mktemp("leg")
    noise = Noise()
    paths = [write_recording(d / f"{p}.mcap", p, design=4, seed=i + 1, noise=noise)
             for i, p in enumerate(("blocked-force", "sag-sweep", "free-displacement", "static"))]
    return load_dataset(paths), noise


def test_table_has_one_row_per_step_and_quantity(leg_runs):
    ds, _ = leg_runs
    count = lambda p, q: len(ds.select(protocol=p, quantity=q))  # noqa: E731
    assert count("blocked-force", "force_N") == 20          # 4 voltages x 5 repetitions
    assert count("sag-sweep", "force_N") == 12              # 4 sags x 3 repetitions
    assert count("free-displacement", "displacement_m") == 8
    assert count("static", "force_N") == 25                 # 13 loading + 12 unloading
    assert count("free-displacement", "force_N") == 0
    bf = ds.select(protocol="blocked-force")
    assert {o.direction for o in bf if o.repetition % 2 == 1} == {"down"}
    assert all(o.n_cycles == 3 for o in bf)


def test_blocked_force_is_the_high_dwell_force(leg_runs):
    ds, noise = leg_runs
    p = powertrain(4)
    preload = noise.preload_fraction * 0.4e-3 / 4
    h0 = float(p.static_displacement_m(preload))
    sd = np.sqrt(noise.force_sample_N**2 / 600 + noise.force_step_N**2)
    for o in ds.select(protocol="blocked-force") + ds.select(protocol="sag-sweep"):
        truth = float(p.foot_force_N(o.voltage_V, o.voltage_V, o.sag_m + h0))
        assert abs(o.value - truth) < 5 * sd, (o, truth)


def test_free_displacement_is_the_peak_to_peak_stroke(leg_runs):
    ds, noise = leg_runs
    p = powertrain(4)
    sd = noise.camera_frame_m * np.sqrt(2 / 36)
    for o in ds.select(protocol="free-displacement"):
        v = o.voltage_V
        stroke = float(p.free_foot_height_m(v, 0.0) - p.free_foot_height_m(v, v))
        assert abs(o.value - stroke) < 5 * sd
        # the camera sees the lift of the low dwell too: more than the model's one-sided stroke
        assert o.value > 1.5 * float(p.free_displacement_m(v))


def test_static_force_follows_the_sag(leg_runs):
    ds, noise = leg_runs
    p = powertrain(4)
    h0 = float(p.static_displacement_m(noise.preload_fraction * 0.4e-3 / 4))
    for o in ds.select(protocol="static"):
        truth = max(float(p.foot_force_N(0.0, 0.0, o.sag_m + h0)), 0.0)
        # one hold of 0.5 s at 1 kHz plus a per-step offset
        assert abs(o.value - truth) < 5 * np.sqrt(noise.force_sample_N**2 / 500 + noise.force_step_N**2)


def test_actuator_rows_split_by_mode(tmp_path):
    path = write_recording(tmp_path / "act.mcap", "actuator", layers=3, seed=3)
    ds = load_dataset([path])
    a = actuator_preset(3, "effective")
    blocked = ds.select(mode="blocked")
    free = ds.select(mode="free")
    assert len(blocked) == len(free) == 12
    assert {o.quantity for o in blocked} == {"force_N"} and {o.quantity for o in free} == {"displacement_m"}
    noise = Noise()
    sd_stroke = noise.camera_frame_m * np.sqrt(2 / 36)       # 3 cycles x 12 frames per plateau, high minus low
    for o in free:   # tip stroke from -delta (V_drive 0) to +delta (V_drive = V_bias)
        assert abs(o.value - 2 * float(a.free_displacement_m(o.voltage_V))) < 5 * sd_stroke
    sd_force = np.hypot(noise.actuator_force_sample_N / np.sqrt(600), noise.actuator_force_step_N)
    preload = noise.preload_fraction * 5e-3 / 4
    for o in blocked:   # the tip held where the contact search left it: F_b + preload
        assert abs(o.value - float(a.blocked_force_N(o.voltage_V)) - preload) < 5 * sd_force
