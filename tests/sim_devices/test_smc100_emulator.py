"""The SMC100 state machine and motion model, checked against the manual's transitions and against kinematics
worked out by hand (trapezoid: T = d/v + v/a; triangle: T = 2 sqrt(d/a); x = a t^2 / 2 while accelerating)."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError
from sim_devices.serial_link import LineEndpoint
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params, trapezoid_segments, trapezoid_time_s
from sim_devices.smc100_protocol import Smc100Protocol

V, A = 5e-3, 20e-3  # the default VA and AC


def homed(params=Smc100Params()):
    clock = VirtualClock()
    emu = Smc100Emulator(clock, params)
    assert emu.home(0.0) is None
    assert emu.status(100.0) == (0x32, 0)
    clock.advance_to(100.0)
    return emu, clock


def test_power_up_state_and_homing_sequence():
    emu = Smc100Emulator(VirtualClock(), Smc100Params(initial_position_m=2e-3))
    assert emu.status(0.0) == (0x0A, 0)
    assert emu.home(0.0) is None
    assert emu.status(0.01)[0] == 0x1E
    # 2 mm at the 2.5 mm/s homing speed, 20 mm/s^2, then the 0.2 s index settle
    t_home = trapezoid_time_s(2e-3, 2.5e-3, A) + 0.2
    assert emu.status(t_home - 1e-6)[0] == 0x1E
    assert emu.status(t_home + 1e-6)[0] == 0x32
    assert emu.counter_m(t_home + 1e-6) == 0.0


def test_trapezoid_timing_and_positions():
    emu, clock = homed(Smc100Params(step_m=1e-7))  # 10 mm is a whole number of steps
    t0 = 100.0
    assert emu.move_absolute(t0, 10e-3) is None
    total_s = 10e-3 / V + V / A  # 2.25 s
    assert emu.status(t0 + 0.1)[0] == 0x28
    assert emu.counter_m(t0 + 0.1) == pytest.approx(0.5 * A * 0.1**2, abs=emu.params.step_m)
    assert emu.counter_m(t0 + total_s / 2) == pytest.approx(5e-3, abs=emu.params.step_m)
    assert emu.status(t0 + total_s - 1e-6)[0] == 0x28
    assert emu.status(t0 + total_s + 1e-6)[0] == 0x33
    assert emu.motion_time_s(10e-3) == pytest.approx(total_s)


def test_short_moves_are_triangular():
    assert trapezoid_time_s(0.5e-3, V, A) == pytest.approx(2 * math.sqrt(0.5e-3 / A))
    segments = trapezoid_segments(0.0, 0.0, 0.5e-3, V, A)
    peak = segments[1].v0
    assert peak == pytest.approx(math.sqrt(0.5e-3 * A)) and peak < V


@settings(max_examples=60, deadline=None)
@given(
    x0=st.floats(-0.04, 0.04),
    x1=st.floats(-0.04, 0.04),
    v=st.floats(1e-4, 8e-3),
    a=st.floats(1e-3, 0.08),
)
def test_trapezoid_pieces_join_up_and_end_at_the_target(x0, x1, v, a):
    segments = trapezoid_segments(0.0, x0, x1, v, a)
    if x0 == x1:
        assert segments == []
        return
    for before, after in zip(segments, segments[1:]):
        x_end = before.x0 + before.v0 * before.dur + 0.5 * before.a * before.dur**2
        v_end = before.v0 + before.a * before.dur
        assert after.x0 == pytest.approx(x_end, abs=1e-12)
        assert after.v0 == pytest.approx(v_end, abs=1e-12)
        assert abs(after.v0) <= v * (1 + 1e-9)
    last = segments[-1]
    assert last.x0 + last.v0 * last.dur + 0.5 * last.a * last.dur**2 == pytest.approx(x1, abs=1e-12)
    assert last.v0 + last.a * last.dur == pytest.approx(0.0, abs=1e-12)


def test_targets_are_rounded_to_the_step():
    emu, clock = homed(Smc100Params(step_m=1e-6))
    emu.move_absolute(100.0, 1.2345e-3)
    assert emu.counter_m(200.0) == pytest.approx(1.234e-3, abs=1e-12)


def test_move_to_current_position_never_leaves_ready():
    emu, clock = homed()
    assert emu.move_absolute(100.0, 0.0) is None
    assert emu.status(100.0) == (0x32, 0)


def test_rejections_store_the_manuals_letters():
    clock = VirtualClock()
    emu = Smc100Emulator(clock)
    assert emu.move_absolute(0.0, 1e-3) == "H"  # NOT REFERENCED
    assert emu.take_error_letter() == "H"
    assert emu.take_error_letter() == "@"  # reading clears it
    emu.home(0.0)
    assert emu.home(0.01) == "E"  # home already started
    # PA's error list has no L or M: a move refused while homing or moving stores D ("Command not allowed")
    assert emu.move_absolute(0.01, 1e-3) == "D"  # HOMING
    emu.update(10.0)
    assert emu.move_absolute(10.0, 0.06) == "G"  # beyond SR = 50 mm
    assert emu.home(10.0) == "K"  # READY
    emu.move_absolute(10.0, 10e-3)
    assert emu.move_absolute(10.1, 0.0) == "D"  # MOVING
    assert emu.set_velocity(10.1, 1e-3) == "M"
    emu.update(20.0)
    assert emu.set_velocity(20.0, 0.02) == "C"  # above the PP maximum
    assert emu.set_soft_limit(20.0, "low", -0.06) == "C"  # beyond the travel
    assert emu.set_enabled(20.0, False) is None
    assert emu.status(20.0)[0] == 0x3C
    assert emu.move_absolute(20.0, 0.0) == "J"
    assert emu.set_configuration(20.0, True) == "J"
    assert emu.set_enabled(20.0, True) is None
    assert emu.status(20.0)[0] == 0x34


def test_stop_decelerates_at_ac():
    emu, clock = homed(Smc100Params(step_m=1e-7))
    emu.move_absolute(100.0, 20e-3)
    t_stop = 100.0 + 1.0  # cruising at 5 mm/s since 0.25 s
    x_stop = emu.counter_m(t_stop)
    emu.stop(t_stop)
    assert emu.status(t_stop + V / A - 1e-6)[0] == 0x28
    assert emu.status(t_stop + V / A + 1e-6)[0] == 0x33
    assert emu.counter_m(t_stop + 1.0) == pytest.approx(x_stop + V * V / (2 * A), abs=emu.params.step_m)


def test_reset_is_silent_then_not_referenced():
    emu, clock = homed()
    emu.reset(100.0)
    assert emu.is_silent(100.0 + 1.9)
    assert not emu.is_silent(100.0 + 2.0)
    assert emu.status(102.0) == (0x0A, 0)


def test_configuration_enter_and_slow_exit():
    emu = Smc100Emulator(VirtualClock())
    assert emu.set_configuration(0.0, True) is None
    assert emu.status(0.0)[0] == 0x14
    assert emu.set_configuration(1.0, False) is None
    assert emu.is_silent(5.9)
    assert emu.status(6.0)[0] == 0x0C


def test_following_error_stops_motion_and_disables():
    emu, clock = homed(Smc100Params(step_m=1e-7))
    emu.move_absolute(100.0, 10e-3)
    emu.faults.inject("following_error", at_s=101.0)
    x_fault = 0.5 * A * 0.25**2 + V * 0.75  # 0.25 s accelerating, then 0.75 s at 5 mm/s
    state, bits = emu.status(105.0)
    assert state == 0x3D and bits == 1 << 5
    assert emu.counter_m(105.0) == pytest.approx(x_fault, abs=emu.params.step_m)
    assert emu.position_m(105.0) == pytest.approx(x_fault, abs=emu.params.step_m)


def test_end_of_run_sets_the_direction_bit():
    emu, clock = homed()
    emu.move_absolute(100.0, -10e-3)
    emu.faults.inject("end_of_run", at_s=100.5)
    state, bits = emu.status(101.0)
    # state diagram: an end of run in MOVING aborts the motion -> NOT REFERENCED from MOVING (0F), not 10 (ESP
    # stage error)
    assert state == 0x0F and bits == 1 << 0  # negative end of run
    assert emu.home(101.0) is None  # NOT REFERENCED again: can be homed


def test_backlash_dead_band_on_reversal():
    b = 20e-6
    emu, clock = homed(Smc100Params(backlash_m=b, step_m=1e-7))
    emu.move_absolute(100.0, 2e-3)
    emu.move_absolute(110.0, 1e-3)
    forward = emu.position_m(110.0)
    back = emu.position_m(120.0)
    # the counter went 2 mm -> 1 mm, the carriage only 1 mm - b
    assert emu.counter_m(120.0) == pytest.approx(1e-3, abs=1e-9)
    assert forward - back == pytest.approx(1e-3 - b, abs=1e-9)
    # moving on in the same direction has no further lost motion
    emu.move_absolute(130.0, 0.5e-3)
    assert back - emu.position_m(140.0) == pytest.approx(0.5e-3, abs=1e-9)


def test_unknown_fault_name_is_a_config_error():
    with pytest.raises(ConfigError, match="overload"):
        Smc100Emulator(VirtualClock()).faults.inject("overload")


# -- the line-protocol adapter ----------------------------------------------------------------------------
def talk(endpoint: LineEndpoint, clock: VirtualClock, text: bytes, wait_s: float = 0.1) -> bytes:
    endpoint.receive(text)
    clock.sleep(wait_s)
    return endpoint.output_until(clock.now_s())


def test_protocol_queries_echo_and_accept_lower_case_and_question_mark():
    clock = VirtualClock()
    proto = Smc100Protocol(Smc100Emulator(clock))
    assert talk(proto, clock, b"1TS\r\n") == b"1TS00000A\r\n"
    assert talk(proto, clock, b"1tp?\r\n") == b"1TP0\r\n"
    assert talk(proto, clock, b"1VA?\r\n") == b"1VA5\r\n"
    # PT is executed in DISABLE, READY and motion only: in NOT REFERENCED it stores H
    assert talk(proto, clock, b"1PT10\r\n") == b""
    assert talk(proto, clock, b"1TE\r\n") == b"1TEH\r\n"
    proto.emulator.home(clock.now_s())
    clock.sleep(1.0)
    assert talk(proto, clock, b"1PT10\r\n") == b"1PT2.25\r\n"


def test_protocol_ignores_other_addresses_and_flags_unknown_commands():
    clock = VirtualClock()
    proto = Smc100Protocol(Smc100Emulator(clock))
    assert talk(proto, clock, b"2TS\r\n") == b""
    assert talk(proto, clock, b"1XX\r\n") == b""
    assert talk(proto, clock, b"1TE\r\n") == b"1TEA\r\n"


def test_protocol_reply_latency_is_modelled():
    clock = VirtualClock()
    params = Smc100Params(reply_latency_s=0.004)
    proto = Smc100Protocol(Smc100Emulator(clock, params))
    proto.receive(b"1TS\r\n")
    reply_bytes = len(b"1TS00000A\r\n")
    expected_s = 0.004 + reply_bytes * 10 / 57600
    assert proto.next_output_s() == pytest.approx(expected_s)
    assert proto.output_until(expected_s - 1e-6) == b""
    assert proto.output_until(expected_s) == b"1TS00000A\r\n"


def test_a_fault_injected_now_acts_from_now_not_from_the_start_of_the_move():
    emu, clock = homed(Smc100Params(step_m=1e-7))
    emu.move_absolute(100.0, 10e-3)
    clock.advance_to(101.0)
    emu.faults.inject("following_error")  # now = 101 s
    x_fault = 0.5 * A * 0.25**2 + V * 0.75
    assert emu.status(102.0)[0] == 0x3D
    assert emu.counter_m(102.0) == pytest.approx(x_fault, abs=1e-7)
