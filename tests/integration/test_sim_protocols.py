"""Every protocol end to end on the simulated bench, through the real drivers and the emulators: the recording
reads back with CRC validation, says how it ended, and its values match the model within the bench's noise.

The expected values come from the model (hamr_bench.model) evaluated here, not from stored outputs; the
measured values are extracted from the recording by a deliberately simple reading of the protocol (the step
events and the commanded drive), independent of the analysis package."""

from __future__ import annotations

import numpy as np
import pytest

from hamr_bench.model import actuator_preset, powertrain
from hamr_bench.protocols.session import RunRequest, run_protocol
from hamr_bench.recording import RecordingReader
from sim_devices.bench import BenchSettings
from sim_devices.sim_rig_file import write_sim_rig

FAST = ["drive.cycles=2", "drive.dwell_high_s=0.3", "drive.dwell_low_s=0.3"]


def record(tmp_path, protocol, *, design=4, layers=2, seed=3, extra=()):
    out = tmp_path / f"{protocol}.mcap"
    result = run_protocol(RunRequest(protocol=protocol, out=out, design=design, layers=layers, seed=seed,
                                     set_options=[*FAST, *extra] if protocol != "static" else list(extra)))
    assert result.ok, result.reason
    reader = RecordingReader(out, validate_crcs=True)
    assert reader.exit_status == "success" and not reader.partial
    return reader


def step_windows(reader):
    """(condition, start, end) of every step, in order."""
    steps = [e for e in reader.events() if e.kind == "step"]
    end = [e for e in reader.events() if e.kind == "run_end"][0].time_s
    return [(s.data, s.time_s, (steps[i + 1].time_s if i + 1 < len(steps) else end)) for i, s in enumerate(steps)]


def dwell_means(reader, topic, field, voltage_V, start, end, margin_s=0.1):
    """Mean of `field` over the high dwells (drive at the bias) and the low dwells (drive at 0) of one step."""
    cmd = reader.scalars("/amplifier/drive/command")
    data = reader.scalars(topic)
    in_step = (cmd["time_s"] >= start) & (cmd["time_s"] < end)
    t, v = cmd["time_s"][in_step], cmd["voltage_V"][in_step]
    means = {}
    for name, level in (("high", voltage_V), ("low", 0.0)):
        at = np.abs(v - level) < 1e-9
        # runs of consecutive samples at the level, trimmed by margin_s at both ends (amplifier lag, creep)
        edges = np.flatnonzero(np.diff(np.r_[0, at.astype(int), 0]))
        values = []
        for a, b in zip(edges[::2], edges[1::2]):
            lo, hi = t[a] + margin_s, t[b - 1] - 0.01
            sel = (data["time_s"] >= lo) & (data["time_s"] <= hi)
            if hi > lo and sel.any():
                values.append(np.mean(data[field][sel]))
        means[name] = np.array(values)
    return means


def test_blocked_force_matches_model(tmp_path):
    reader = record(tmp_path, "blocked-force", extra=["repetitions=1", "voltages_V=150,250"])
    pt = powertrain(4)
    for condition, start, end in step_windows(reader):
        V = condition["voltage_V"]
        high = dwell_means(reader, "/force", "force_N", V, start, end)["high"]
        # zero sag is found to within a few um: at ~6 N/m that is a few hundredths of a mN
        assert np.mean(high) == pytest.approx(float(pt.blocked_force_N(V, 0.0)), abs=0.15e-3)


def test_sag_sweep_matches_model(tmp_path):
    reader = record(tmp_path, "sag-sweep", design=3, extra=["repetitions=1", "sags_m=0,0.002"])
    pt = powertrain(3)
    for condition, start, end in step_windows(reader):
        high = dwell_means(reader, "/force", "force_N", condition["voltage_V"], start, end)["high"]
        expected = float(pt.blocked_force_N(condition["voltage_V"], condition["sag_m"]))
        assert np.mean(high) == pytest.approx(expected, abs=0.15e-3 + 0.02 * expected)


def test_static_matches_model(tmp_path):
    reader = record(tmp_path, "static", design=1, extra=["max_sag_m=0.002", "step_m=0.001", "unload=false"])
    pt = powertrain(1)
    forces = reader.scalars("/force")
    moves = reader.scalars("/stage/command")["time_s"]
    for condition, start, end in step_windows(reader):
        end = min(end, *moves[moves > start][:1])  # the hold ends when the stage moves on
        sel = (forces["time_s"] > start) & (forces["time_s"] < end)
        expected = float(pt.foot_force_N(0.0, 0.0, condition["sag_m"]))
        assert np.mean(forces["force_N"][sel]) == pytest.approx(expected, abs=0.1e-3 + 0.02 * expected)


def test_free_displacement_matches_model(tmp_path):
    reader = record(tmp_path, "free-displacement", design=2, extra=["repetitions=1", "voltages_V=250"])
    pt = powertrain(2)
    for condition, start, end in step_windows(reader):
        V = condition["voltage_V"]
        means = dwell_means(reader, "/camera/displacement", "displacement_m", V, start, end, margin_s=0.15)
        stroke = np.mean(means["high"]) - np.mean(means["low"])
        expected = float(pt.free_foot_height_m(V, 0.0) - pt.free_foot_height_m(V, V))
        # camera tracking of a 10 um/px image: sub-pixel, so well under 1 % of a ~1 mm stroke
        assert stroke == pytest.approx(expected, rel=0.02)


def test_actuator_blocked_force_and_free_displacement_match_model(tmp_path):
    reader = record(tmp_path, "actuator", layers=3, extra=["repetitions=1", "voltages_V=200"])
    actuator = actuator_preset(3, "effective")
    for condition, start, end in step_windows(reader):
        V = condition["voltage_V"]
        if condition["mode"] == "blocked":
            high = dwell_means(reader, "/force", "force_N", V, start, end)["high"]
            # contact is found to within a fraction of a um on a ~2700 N/m actuator: ~1 mN
            assert np.mean(high) == pytest.approx(float(actuator.blocked_force_N(V)), abs=2e-3)
        elif condition["mode"] == "stiffness":
            # undriven tip pushed sag_m past contact: F = k_act x push (same contact accuracy as above); the hold
            # ends when the stage moves on
            forces = reader.scalars("/force")
            moves = reader.scalars("/stage/command")["time_s"]
            end = min(end, *moves[moves > start][:1])
            sel = (forces["time_s"] > start) & (forces["time_s"] < end)
            expected = actuator.stiffness_N_per_m * condition["sag_m"]
            assert np.mean(forces["force_N"][sel]) == pytest.approx(expected, abs=2e-3)
        else:
            means = dwell_means(reader, "/camera/displacement", "displacement_m", V, start, end, margin_s=0.15)
            stroke = np.mean(means["high"]) - np.mean(means["low"])
            assert stroke == pytest.approx(2 * float(actuator.free_displacement_m(V)), rel=0.03)


def test_contact_search_and_stiffness_sweep_take_up_stage_play(tmp_path):
    # A stage with 20 um of play and a stiff drive behind it (the stage_backlash form's drive lag set to 0, so the
    # carriage lags the motor by exactly half the play in the direction of motion). The contact search approaches
    # from one side only, so its zero is the motor position that just touches with the play taken up toward the
    # tip: touch + play / 2. The sweep's loading branch then presses k_act x push, the unloading branch
    # k_act x min(push + play, largest push) (the carriage stays put for the first `play` of the way back), and
    # the blocked steps, reached from below after the sweep, press nothing extra. The Nano17's own stiffness is
    # in series with the tip (k_act / k_sensor = 2.5e-4: inside the tolerance).
    play_m = 20e-6
    out = tmp_path / "actuator-play.mcap"
    rig = write_sim_rig(tmp_path / "rig.toml", {"effects": {"stage_backlash": play_m},
                                                "effect_shapes": {"stage_backlash": {"lag_m": 0.0}}})
    result = run_protocol(RunRequest(protocol="actuator", out=out, layers=3, seed=3, rig_path=rig,
                                     set_options=[*FAST, "repetitions=1", "voltages_V=200"]))
    assert result.ok, result.reason
    reader = RecordingReader(out, validate_crcs=True)
    (contact,) = [e for e in reader.events() if e.kind == "contact_found"]
    assert contact.data["stage_position_m"] == pytest.approx(BenchSettings().touch_stage_m + play_m / 2, abs=1e-6)
    actuator = actuator_preset(3, "effective")
    forces = reader.scalars("/force")
    moves = reader.scalars("/stage/command")["time_s"]
    largest_push = max(c["sag_m"] for c, _, _ in step_windows(reader) if c["mode"] == "stiffness")
    for condition, start, end in step_windows(reader):
        if condition["mode"] == "stiffness":
            end = min(end, *moves[moves > start][:1])
            sel = (forces["time_s"] > start) & (forces["time_s"] < end)
            push = condition["sag_m"] if condition["direction"] == "up" else min(condition["sag_m"] + play_m,
                                                                                largest_push)
            assert np.mean(forces["force_N"][sel]) == pytest.approx(actuator.stiffness_N_per_m * push, abs=2e-3)
        elif condition["mode"] == "blocked":
            high = dwell_means(reader, "/force", "force_N", condition["voltage_V"], start, end)["high"]
            assert np.mean(high) == pytest.approx(float(actuator.blocked_force_N(condition["voltage_V"])), abs=2e-3)


@pytest.mark.parametrize("compliance_m_per_N", [1 / 20000.0, 1 / 2000.0])
def test_sensor_compliance_in_series_with_the_actuator_tip(tmp_path, compliance_m_per_N):
    """The mount's compliance c in series with the Nano17 (k_N) and the tip (k_act): the held steps of the
    stiffness sweep read the series-spring force push / (1 / k_act + 1 / k_N + c), also when the mount is softer
    than the actuator (k_act c = 1.35 for the 3-layer actuator and c = 1/2000)."""
    from sim_devices.bench_physics import NANO17_STIFFNESS_N_PER_M

    out = tmp_path / "actuator-compliant.mcap"
    result = run_protocol(RunRequest(protocol="actuator", out=out, layers=3, seed=3,
                                     effects={"sensor_compliance": compliance_m_per_N},
                                     set_options=[*FAST, "repetitions=1", "voltages_V=200"]))
    assert result.ok, result.reason
    reader = RecordingReader(out)
    k_act = actuator_preset(3, "effective").stiffness_N_per_m
    k_series = 1.0 / (1.0 / k_act + 1.0 / NANO17_STIFFNESS_N_PER_M + compliance_m_per_N)
    forces = reader.scalars("/force")
    moves = reader.scalars("/stage/command")["time_s"]
    held = [(c, s, e) for c, s, e in step_windows(reader) if c["mode"] == "stiffness" and c["direction"] == "up"]
    assert len(held) >= 4
    for condition, start, end in held:
        end = min(end, *moves[moves > start][:1])
        sel = (forces["time_s"] > start + 0.1) & (forces["time_s"] < end)
        assert np.mean(forces["force_N"][sel]) == pytest.approx(k_series * condition["sag_m"], abs=1.5e-3)


def test_a_slow_amplifier_between_tracked_drives_does_not_fault_the_camera(tmp_path) -> None:
    """At 500 V/s the bias takes 0.3 s from 100 V to 250 V between two free-displacement drives; the camera is not
    read then, and those frames are not drops (at the default 60 Hz the driver faults on a gap of 4)."""
    from sim_devices.sim_rig_file import sim_rig_text

    text = sim_rig_text({})
    assert "slew_rate_V_per_s = 10000.0" in text
    rig = tmp_path / "slow-amplifier.toml"
    rig.write_text(text.replace("slew_rate_V_per_s = 10000.0", "slew_rate_V_per_s = 500.0"), encoding="utf-8")
    out = tmp_path / "slow.mcap"
    result = run_protocol(RunRequest(protocol="actuator", out=out, rig_path=rig, set_options=[
        *FAST, "repetitions=1", "voltages_V=100,250", "drive.cycles=1"]))
    assert result.ok, result.reason
    tracked = [e for e in RecordingReader(out).events() if e.kind == "drive_start" and e.data["track"]]
    assert len(tracked) == 2
