"""The real SMC100 driver against the SMC100 emulator, over both transports: in-process (`hamrsim://`, virtual
clock) and a pseudo-terminal served with a real clock. The same test bodies run on both. Expected positions
and times come from the stage settings (trapezoid timing, step rounding), not from earlier runs."""

import itertools

import pytest

from drivers.newport_smc100 import NewportSMC100
from hamr_bench.clock import RealClock, VirtualClock
from hamr_bench.errors import DeviceFault, DeviceProtocolError, DeviceTimeout, SafetyLimitError
from sim_devices.pty_server import PtyServer
from sim_devices.serial_link import register_endpoint, unregister_endpoint
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol

# Fast stage so the real-time pty variant stays short: 1 mm takes 1/8 + 8/80 = 0.225 s.
FAST = Smc100Params(
    velocity_m_per_s=8e-3, acceleration_m_per_s2=80e-3, home_settle_s=0.05, initial_position_m=0.4e-3,
    reset_time_s=0.3,
)
_names = itertools.count()


@pytest.fixture(params=["inprocess", "pty"])
def rig(request):
    """(driver, emulator, clock) on one transport."""
    if request.param == "inprocess":
        clock = VirtualClock()
        emulator = Smc100Emulator(clock, FAST)
        name = f"smc100-test-{next(_names)}"
        url = register_endpoint(name, Smc100Protocol(emulator))
        stage = NewportSMC100(url, clock, timeout_s=0.2, poll_interval_s=0.02)
        yield stage, emulator, clock
        stage.close()
        unregister_endpoint(name)
    else:
        clock = RealClock()
        emulator = Smc100Emulator(clock, FAST)
        server = PtyServer(Smc100Protocol(emulator)).start()
        stage = NewportSMC100(server.path, clock, timeout_s=0.2, poll_interval_s=0.02)
        yield stage, emulator, clock
        stage.close()
        server.close()


def test_home_then_absolute_and_relative_moves(rig):
    stage, emulator, clock = rig
    assert stage.status().state == "NOT REFERENCED"
    stage.home()
    assert stage.status().state_code == 0x32
    assert stage.position_m() == 0.0
    stage.move_to(1.0e-3)
    step = FAST.step_m
    assert stage.position_m() == pytest.approx(round(1.0e-3 / step) * step, abs=1e-9)
    assert stage.status().state_code == 0x33
    stage.move_by(-0.5e-3)
    assert stage.position_m() == pytest.approx(0.5e-3, abs=step)
    # the carriage is where the controller says (no backlash configured)
    assert emulator.position_m(clock.now_s()) == pytest.approx(stage.position_m(), abs=step)


def test_move_duration_follows_the_trapezoid(rig):
    stage, emulator, clock = rig
    stage.home()
    start_s = clock.now_s()
    stage.move_to(2.0e-3)
    elapsed_s = clock.now_s() - start_s
    expected_s = 2.0e-3 / FAST.velocity_m_per_s + FAST.velocity_m_per_s / FAST.acceleration_m_per_s2
    # completion is seen at the first TS poll after the move ends: within a poll interval plus round trips
    assert expected_s <= elapsed_s <= expected_s + 0.02 + 0.08
    assert stage.motion_time_s(2.0e-3) == pytest.approx(expected_s, abs=1e-6)


def test_move_to_current_position_returns_at_once(rig):
    stage, emulator, clock = rig
    stage.home()
    start_s = clock.now_s()
    stage.move_to(0.0)
    assert clock.now_s() - start_s < 0.1  # PA + TE + one TS: two ~10 ms round trips, no motion


def test_settings_round_trip(rig):
    stage, emulator, clock = rig
    stage.home()  # VA, AC, SL, SR are set in CONFIGURATION, DISABLE or READY, not NOT REFERENCED (H)
    stage.set_velocity(4e-3)
    assert stage.velocity_m_per_s() == pytest.approx(4e-3)
    stage.set_acceleration(50e-3)
    assert stage.acceleration_m_per_s2() == pytest.approx(50e-3)
    stage.set_soft_limits(-10e-3, 20e-3)
    assert stage.soft_limits_m() == pytest.approx((-10e-3, 20e-3))
    with pytest.raises(SafetyLimitError):
        stage.move_to(21e-3)


def test_rejections_come_back_as_error_letters(rig):
    stage, emulator, clock = rig
    with pytest.raises(DeviceFault, match="H "):
        stage.move_to(1e-3)  # NOT REFERENCED
    stage.home()
    stage.disable()
    assert stage.status().state_code == 0x3C
    with pytest.raises(DeviceFault, match="J "):
        stage.move_to(1e-3)
    stage.enable()
    assert stage.status().state_code == 0x34
    with pytest.raises(DeviceFault, match="C "):
        stage.set_velocity(1.0)


def test_reset_returns_to_not_referenced(rig):
    stage, emulator, clock = rig
    stage.home()
    stage.reset()
    assert stage.status().state_code == 0x0A


def test_stop_during_a_move(rig):
    stage, emulator, clock = rig
    stage.home()
    stage._checked("PA10")  # start a long move without waiting (1.35 s)
    clock.sleep(0.3)
    stage.stop()
    clock.sleep(0.2)  # deceleration from 8 mm/s at 80 mm/s^2 takes 0.1 s
    status = stage.status()
    assert status.state_code == 0x33
    assert 1.0e-3 < stage.position_m() < 3.0e-3


# -- faults: each ends in a typed error within the driver's timeout ------------------------------------------
@pytest.mark.parametrize(
    "fault,error",
    [("no_reply", DeviceTimeout), ("garbage_bytes", DeviceProtocolError), ("dropped_bytes", DeviceTimeout),
     ("disconnect", DeviceFault)],
)
def test_wire_faults(rig, fault, error):
    stage, emulator, clock = rig
    assert stage.position_m() == 0.0
    emulator.faults.inject(fault)
    start_s = clock.now_s()
    with pytest.raises(error) as info:
        stage.position_m()
    assert clock.now_s() - start_s <= 0.2 + 0.05
    assert "\n" not in str(info.value) and str(info.value).startswith("stage: ")
    if fault == "disconnect":
        assert "disconnected" in str(info.value)


@pytest.mark.parametrize(
    "fault,message", [("following_error", "following error"), ("end_of_run", "end of run")]
)
def test_stage_faults_during_a_move(rig, fault, message):
    stage, emulator, clock = rig
    stage.home()
    emulator.faults.inject(fault, at_s=clock.now_s() + 0.1)
    start_s = clock.now_s()
    with pytest.raises(DeviceFault, match=message):
        stage.move_to(5e-3)
    assert clock.now_s() - start_s <= 0.1 + 0.1  # seen at the first TS poll after the fault
    # the carriage stopped where the fault hit, well short of 5 mm
    assert emulator.position_m(clock.now_s()) < 2e-3


def test_motion_timeout_stops_the_emulated_stage(rig):
    stage, emulator, clock = rig
    stage.home()
    with pytest.raises(DeviceTimeout, match="stopped"):
        stage.move_to(10e-3, timeout_s=0.2)
    clock.sleep(0.2)
    assert stage.status().state_code == 0x33
    assert stage.position_m() < 3e-3


@pytest.mark.parametrize("port", ["/dev/hamr-bench-no-such-port", "hamrsim://no-such-device"])
def test_a_port_that_cannot_be_opened_is_a_one_line_device_fault(port):
    with pytest.raises(DeviceFault, match="cannot open serial port") as info:
        NewportSMC100(port, VirtualClock(), limits_m=(-0.01, 0.01))
    assert "\n" not in str(info.value)
