"""The runner's logic on in-memory fakes: plans carried out, streams recorded, and every ending safe."""

import math

import pytest

from hamr_bench.errors import DeviceFault
from hamr_bench.protocols import PROTOCOLS, get_protocol
from hamr_bench.protocols.params import load_params
from hamr_bench.protocols.runner import POLL_INTERVAL_S, Runner
from tests.protocols.fakes import FakeRecorder, fake_rig

QUICK = ["repetitions=1", "drive.cycles=1"]


def run(name, rig, set_options=None):
    protocol = get_protocol(name)
    params = load_params(protocol.Params(), None, set_options if set_options is not None else QUICK)
    rec = FakeRecorder()
    return Runner(rig, rec).run(protocol, params), rec


@pytest.mark.parametrize("name", [n for n in PROTOCOLS if n != "actuator"])
def test_every_leg_protocol_completes_and_ends_safe(name):
    rig = fake_rig()
    result, rec = run(name, rig, [] if name == "static" else QUICK)
    assert result.ok, result.reason
    assert rec.closed == ("success", "completed")
    assert rig.amp_drive.zeroed and rig.amp_bias.zeroed and rig.stage.stopped
    kinds = [e[1] for e in rec.events]
    assert kinds[0] == "run_start" and kinds[-1] == "run_end" and "safe_state" in kinds
    assert rec.scalars["/force"], "force stream recorded"


def test_contact_search_finds_zero_sag_within_one_fine_step():
    rig = fake_rig()
    result, rec = run("blocked-force", rig)
    found = [e[4]["stage_position_m"] for e in rec.events if e[1] == "contact_found"]
    assert result.ok and len(found) == 1
    # The fake leg touches at 2 mm: the last position still touching lies within one fine step (plus the
    # force resolution of the release threshold) of it.
    params = get_protocol("blocked-force").Params().contact
    assert abs(found[0] - rig.force_sensor.touch_m) <= params.fine_step_m + params.threshold_N / 4 / 2.0


@pytest.mark.parametrize("k_N_per_m", [2.0, 10.0])
def test_contact_search_measures_from_a_baseline_that_drifted_during_it(k_N_per_m):
    # The load cell's baseline rises by 0.15 mN once the leg is first touched, above the search's release level
    # (0.1 mN): backing off never brings the reading under it. The search must see that backing off no longer changes
    # the force, measure from that baseline, and find the zero as it would without the drift (it used to back off
    # to the end of the stage's travel and stop the run).
    found = {}
    for drift_N in (0.0, 0.15e-3):
        rig = fake_rig(k_N_per_m=k_N_per_m, drift_after_touch_N=drift_N)
        result, rec = run("blocked-force", rig)
        assert result.ok, result.reason
        (event,) = [e for e in rec.events if e[1] == "contact_found"]
        found[drift_N] = event[4]["stage_position_m"]
        assert event[4].get("baseline_N", 0.0) == pytest.approx(drift_N, abs=0.02e-3)
    params = get_protocol("blocked-force").Params().contact
    assert abs(found[0.15e-3] - found[0.0]) <= params.fine_step_m


def test_contact_search_refuses_a_sensor_that_reads_force_out_of_contact():
    # Right after its tare, where the search starts, the sensor reads 0.25 mN (over half the 0.4 mN threshold): a
    # tare that did not take. The search would see contact everywhere; it must stop with one clear line instead of
    # recording a wrong zero, and leave the rig safe.
    rig = fake_rig(baseline_N=0.25e-3)
    result, rec = run("blocked-force", rig)
    assert not result.ok and "where the contact search starts" in result.reason and "\n" not in result.reason
    assert not [e for e in rec.events if e[1] == "contact_found"]
    assert rig.amp_drive.zeroed and rig.amp_bias.zeroed and rig.stage.stopped


def test_a_run_that_completes_but_cannot_be_made_safe_has_failed():
    # The protocol completes, then stopping the force stream fails (a sensor gone bad at the very end). The
    # recording and the result returned to the caller (the CLI's exit code) must both say failed, with the reason.
    rig = fake_rig()

    def stop_stream():
        raise DeviceFault("fake sensor: unreadable reply", device="force_sensor")

    rig.force_sensor.stop_stream = stop_stream
    result, rec = run("blocked-force", rig, ["repetitions=1", "drive.cycles=1", "voltages_V=200"])
    assert rec.closed[0] == "failed" and "while making safe" in rec.closed[1]
    assert not result.ok and result.exit_status == "failed" and "while making safe" in result.reason


def test_drive_waveform_is_recorded_as_commanded_samples():
    rig = fake_rig()
    result, rec = run("blocked-force", rig, ["repetitions=1", "drive.cycles=1", "voltages_V=200"])
    volts = [f["voltage_V"] for _, f in rec.scalars["/amplifier/drive/command"]]
    assert result.ok and max(volts) == pytest.approx(200.0)
    times = [t for t, _ in rec.scalars["/amplifier/drive/command"]]
    assert all(b >= a for a, b in zip(times, times[1:]))


def test_force_limit_aborts_and_stops_pushing():
    rig = fake_rig(force_limit_N=0.004)  # the sag sweep pushes 3 mm into a 2 N/m leg: 6 mN
    result, rec = run("sag-sweep", rig)
    assert result.exit_status == "aborted" and "exceeds the limit" in result.reason
    assert rec.closed[0] == "aborted"
    forces = [f["force_N"] for _, f in rec.scalars["/force"]]
    # No stage move was commanded after the first over-limit sample.
    over_time = next(t for t, f in rec.scalars["/force"] if f["force_N"] > 0.004)
    later_moves = [t for t, _ in rec.scalars["/stage/command"] if t > over_time]
    # The overshoot is bounded by what can change before the runner reacts: one stage step into the spring, or
    # the drive ramp over one polling interval plus one sample period.
    sensor, drive = rig.force_sensor, get_protocol("sag-sweep").Params().drive
    ramp_N = sensor.gain * 250.0 / drive.ramp_s * (POLL_INTERVAL_S + sensor.period)
    bound = 0.004 + max(sensor.k * rig.limits.max_stage_step_m, ramp_N)
    assert max(forces) <= bound + 1e-12 and not later_moves
    assert rig.amp_drive.zeroed and rig.stage.stopped


def test_device_fault_mid_run_fails_safe_and_keeps_data():
    rig = fake_rig(fail_at_s=20.0)
    result, rec = run("blocked-force", rig, ["drive.cycles=2"])
    assert result.exit_status == "failed" and "fake sensor disconnected" in result.reason
    assert rec.closed[0] == "failed" and rig.amp_bias.zeroed and rig.stage.stopped
    assert rec.scalars["/force"][-1][0] < 20.0 + 1e-9


def test_ctrl_c_aborts_and_records_why():
    rig = fake_rig()
    original = rig.amp_drive.play_waveform
    calls = {"n": 0}

    def interrupted(*a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise KeyboardInterrupt
        return original(*a, **k)

    rig.amp_drive.play_waveform = interrupted
    result, rec = run("blocked-force", rig)
    assert result.exit_status == "aborted" and "Ctrl-C" in result.reason
    assert rec.closed[0] == "aborted" and rig.amp_drive.value == 0.0


def test_stage_target_outside_soft_limits_is_refused_before_moving():
    rig = fake_rig()
    result, rec = run("static", rig, ["max_sag_m=0.05", "step_m=0.01"])
    assert result.exit_status == "aborted" and "soft limits" in result.reason
    low, high = rig.stage.limits_m
    assert all(low <= p <= high for p in rig.stage.moves)


def test_bug_in_a_device_still_leaves_rig_safe_and_file_closed():
    rig = fake_rig()
    rig.amp_drive.play_waveform = lambda *a, **k: 1 / 0
    with pytest.raises(ZeroDivisionError):
        run("blocked-force", rig)
    assert rig.amp_drive.zeroed and rig.stage.stopped


def test_step_events_carry_the_condition():
    rig = fake_rig()
    result, rec = run("blocked-force", rig, ["repetitions=2", "drive.cycles=1", "voltages_V=100,250"])
    steps = [e[4] for e in rec.events if e[1] == "step"]
    assert [s["voltage_V"] for s in steps] == [100.0, 250.0, 250.0, 100.0]
    assert [s["direction"] for s in steps] == ["up", "up", "down", "down"]
    assert result.steps_done == 4 and not math.isnan(steps[0]["sag_m"])
