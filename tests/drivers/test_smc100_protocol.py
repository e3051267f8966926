"""Byte-exact tests of the SMC100 driver: every command as the bytes the SMC100 manual (rev A812B4) says go
over the wire, with the controller's replies. Exchanges are written from the manual's syntax (`nnAAxx` + CR
LF; queries echo `nnAA`; rejected commands are silent and leave a TE letter), not from running the driver."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from drivers.newport_smc100 import NewportSMC100, format_mm
from drivers.smc100_codes import parse_status
from drivers.testing import expected_protocol, scripted_port
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import DeviceFault, DeviceProtocolError, DeviceTimeout, SafetyLimitError

OK = (b"1TE\r\n", b"1TE@\r\n")
LIMITS = {"limits_m": (-0.025, 0.025)}


def smc100(script, **settings):
    """The driver on a scripted port. Travel limits are configured unless a test says otherwise, so opening
    sends nothing; without them the driver reads SL/SR when it opens."""
    if "limits_m" not in settings:
        settings["limits_m"] = LIMITS["limits_m"]
    elif settings["limits_m"] is None:
        del settings["limits_m"]
    return expected_protocol(NewportSMC100, script, **settings)


def test_port_is_opened_57600_8n1_with_xon_xoff():
    with smc100([]) as stage:
        settings = scripted_port(stage).settings
    assert settings["baudrate"] == 57600
    assert settings["xonxoff"] is True
    assert (settings["bytesize"], settings["parity"], settings["stopbits"]) == (8, "N", 1)


def test_position_is_read_in_mm_and_returned_in_m():
    with smc100([(b"1TP\r\n", b"1TP12.3456\r\n")]) as stage:
        assert stage.position_m() == pytest.approx(12.3456e-3, abs=1e-12)


def test_address_prefixes_every_command_and_echo():
    with smc100([(b"12TP\r\n", b"12TP-0.5\r\n")], address=12) as stage:
        assert stage.position_m() == pytest.approx(-0.5e-3)


@pytest.mark.parametrize("address", [0, 32])
def test_address_outside_1_to_31_is_refused(address):
    with pytest.raises(ValueError, match="1..31"):
        NewportSMC100("scripted://", VirtualClock(), address=address, port_opener=lambda *a, **k: None)


# Every state code in the manual's TS table, with the family it belongs to.
MANUAL_STATES = [
    ("0A", "NOT REFERENCED"), ("0B", "NOT REFERENCED"), ("0C", "NOT REFERENCED"), ("0D", "NOT REFERENCED"),
    ("0E", "NOT REFERENCED"), ("0F", "NOT REFERENCED"), ("10", "NOT REFERENCED"), ("11", "NOT REFERENCED"),
    ("14", "CONFIGURATION"), ("1E", "HOMING"), ("1F", "HOMING"), ("28", "MOVING"),
    ("32", "READY"), ("33", "READY"), ("34", "READY"), ("35", "READY"),
    ("3C", "DISABLE"), ("3D", "DISABLE"), ("3E", "DISABLE"), ("46", "JOGGING"), ("47", "JOGGING"),
]

MANUAL_STATES_BY_CODE = [(int(code, 16), family) for code, family in MANUAL_STATES]


@pytest.mark.parametrize("code,family", MANUAL_STATES)
def test_status_decodes_every_state_code(code, family):
    with smc100([(b"1TS\r\n", f"1TS0000{code}\r\n".encode())]) as stage:
        status = stage.status()
    assert status.state == family
    assert status.state_code == int(code, 16)
    assert status.errors == ()


MANUAL_ERROR_BITS = [
    (0, "negative end of run"), (1, "positive end of run"), (2, "peak current"), (3, "RMS current"),
    (4, "short circuit"), (5, "following error"), (6, "homing time-out"), (7, "wrong ESP stage"),
    (8, "DC voltage too low"), (9, "80 W"),
]


@pytest.mark.parametrize("bit,meaning", MANUAL_ERROR_BITS)
def test_status_decodes_every_error_bit(bit, meaning):
    reply = f"1TS{1 << bit:04X}3D\r\n".encode()
    with smc100([(b"1TS\r\n", reply)]) as stage:
        status = stage.status()
    assert len(status.errors) == 1 and meaning in status.errors[0]


def test_status_decodes_several_error_bits_at_once():
    with smc100([(b"1TS\r\n", b"1TS022110\r\n")]) as stage:
        errors = stage.status().errors
    # 0x0221 = bits 0, 5, 9
    assert [e.split()[0] for e in errors] == ["negative", "following", "80"]


def test_home_sends_or_once_reads_te_and_polls_ts_until_ready():
    clock = VirtualClock()
    script = [
        (b"1TS\r\n", b"1TS00000A\r\n"),
        (b"1OR\r\n", None),
        OK,
        (b"1TS\r\n", b"1TS00001E\r\n"),
        (b"1TS\r\n", b"1TS00001E\r\n"),
        (b"1TS\r\n", b"1TS000032\r\n"),
    ]
    with smc100(script, clock=clock, poll_interval_s=0.05) as stage:
        stage.home()
    assert clock.now_s() == pytest.approx(0.10)  # two polls waited out through the clock, nothing else


def test_home_when_already_ready_sends_nothing_but_ts():
    with smc100([(b"1TS\r\n", b"1TS000033\r\n")]) as stage:
        stage.home()


def test_home_in_disable_is_refused_without_sending_or():
    with smc100([(b"1TS\r\n", b"1TS00003C\r\n")]) as stage, pytest.raises(DeviceFault, match="DISABLE"):
        stage.home()


@pytest.mark.parametrize("ready", ["32", "33", "34", "35"])
def test_move_completes_on_every_ready_code(ready):
    script = [
        (b"1PA2.5\r\n", None),
        OK,
        (b"1TS\r\n", b"1TS000028\r\n"),
        (b"1TS\r\n", f"1TS0000{ready}\r\n".encode()),
    ]
    with smc100(script) as stage:
        stage.move_to(2.5e-3)


def test_move_to_current_position_completes_without_ever_seeing_moving():
    script = [(b"1PA-1.25\r\n", None), OK, (b"1TS\r\n", b"1TS000033\r\n")]
    with smc100(script) as stage:
        stage.move_to(-1.25e-3)


def test_move_formats_sub_micrometre_targets_without_exponent():
    script = [(b"1PA0.0003\r\n", None), OK, (b"1TS\r\n", b"1TS000033\r\n")]
    with smc100(script) as stage:
        stage.move_to(0.3e-6)


def test_limits_come_from_sl_sr_when_not_configured():
    script = [
        (b"1SL?\r\n", b"1SL-25\r\n"),
        (b"1SR?\r\n", b"1SR25\r\n"),
        (b"1PA10\r\n", None),
        OK,
        (b"1TS\r\n", b"1TS000033\r\n"),
    ]
    with smc100(script, limits_m=None) as stage:
        assert stage.limits_m == pytest.approx((-25e-3, 25e-3))
        stage.move_to(10e-3)
        with pytest.raises(SafetyLimitError):
            stage.move_to(26e-3)


@pytest.mark.parametrize("target_m", [0.0251, -0.03, float("nan"), float("inf")])
def test_move_outside_limits_raises_before_sending_anything(target_m):
    with smc100([]) as stage, pytest.raises(SafetyLimitError, match="outside stage limits"):
        stage.move_to(target_m)


def test_relative_move_checks_where_it_would_end():
    script = [(b"1TP\r\n", b"1TP24\r\n")]
    with smc100(script) as stage, pytest.raises(SafetyLimitError):
        stage.move_by(2e-3)


def test_relative_move_sends_pr():
    script = [(b"1TP\r\n", b"1TP1\r\n"), (b"1PR-0.5\r\n", None), OK, (b"1TS\r\n", b"1TS000033\r\n")]
    with smc100(script) as stage:
        stage.move_by(-0.5e-3)


def test_rejected_move_reports_the_error_letter():
    script = [(b"1PA1\r\n", None), (b"1TE\r\n", b"1TEH\r\n")]
    with smc100(script) as stage, pytest.raises(DeviceFault, match="rejected 1PA1: H .*NOT REFERENCED"):
        stage.move_to(1e-3)


def test_a_motion_command_is_never_retried_when_te_goes_unanswered():
    # The script ends after one PA + one silent TE: any retry would be an unexpected write (AssertionError).
    clock = VirtualClock()
    script = [(b"1PA1\r\n", None), (b"1TE\r\n", None)]
    with smc100(script, clock=clock, timeout_s=0.3) as stage:
        with pytest.raises(DeviceTimeout, match="no reply to '1TE' within 0.3 s"):
            stage.move_to(1e-3)
    assert clock.now_s() == pytest.approx(0.3)


def test_motion_timeout_stops_the_stage_then_raises():
    script = [(b"1PA1\r\n", None), OK] + [(b"1TS\r\n", b"1TS000028\r\n")] * 4 + [(b"1ST\r\n", None), OK]
    with smc100(script, poll_interval_s=0.05) as stage:
        with pytest.raises(DeviceTimeout, match="not finished within 0.12 s.*stopped"):
            stage.move_to(1e-3, timeout_s=0.12)


def test_following_error_during_a_move_is_a_fault():
    script = [(b"1PA1\r\n", None), OK, (b"1TS\r\n", b"1TS000028\r\n"), (b"1TS\r\n", b"1TS00203D\r\n")]
    with smc100(script) as stage, pytest.raises(DeviceFault, match="following error"):
        stage.move_to(1e-3)


def test_end_of_run_during_a_move_is_a_fault():
    script = [(b"1PA1\r\n", None), OK, (b"1TS\r\n", b"1TS000210\r\n")]
    with smc100(script) as stage, pytest.raises(DeviceFault, match="NOT REFERENCED.*positive end of run"):
        stage.move_to(1e-3)


def test_stop_addresses_only_this_controller_and_reads_te():
    with smc100([(b"1ST\r\n", None), OK]) as stage:
        stage.stop()


def test_stop_refused_in_not_referenced_leaves_no_letter_for_the_next_command():
    # ST is not executed in NOT REFERENCED (H): stop() reads that letter, so the OR that follows reads its own TE.
    script = [(b"1ST\r\n", None), (b"1TE\r\n", b"1TEH\r\n"),
              (b"1TS\r\n", b"1TS00000A\r\n"), (b"1OR\r\n", None), OK, (b"1TS\r\n", b"1TS000032\r\n")]
    with smc100(script) as stage:
        stage.stop()
        stage.home()


def test_identify_reads_ve_and_id():
    script = [(b"1VE\r\n", b"1VE SMC_CC - Controller-driver version  3. 1. 2\r\n"),
              (b"1ID?\r\n", b"1IDLTA-HS_PN:B0601246985103_UD:062509\r\n")]
    with smc100(script) as stage:
        assert stage.identify() == ("SMC_CC - Controller-driver version  3. 1. 2",
                                    "LTA-HS_PN:B0601246985103_UD:062509")


def test_is_moving_reads_ts():
    script = [(b"1TS\r\n", b"1TS000028\r\n"), (b"1TS\r\n", b"1TS000033\r\n")]
    with smc100(script) as stage:
        assert stage.is_moving() is True
        assert stage.is_moving() is False


def test_reset_waits_through_silence_for_not_referenced():
    script = [(b"1RS\r\n", None), (b"1TS\r\n", None), (b"1TS\r\n", b"1TS00000A\r\n")]
    with smc100(script) as stage:
        stage.reset()


def test_reset_that_never_answers_times_out():
    clock = VirtualClock()
    script = [(b"1RS\r\n", None)] + [(b"1TS\r\n", None)] * 4
    with smc100(script, clock=clock, timeout_s=0.2, poll_interval_s=0.05, reset_timeout_s=1.0) as stage:
        with pytest.raises(DeviceTimeout, match="after reset"):
            stage.reset()
    assert clock.now_s() == pytest.approx(1.0)


def test_enable_and_disable_send_mm_and_check_te():
    script = [(b"1MM0\r\n", None), OK, (b"1MM1\r\n", None), OK]
    with smc100(script) as stage:
        stage.disable()
        stage.enable()


def test_enable_rejected_in_not_referenced():
    with smc100([(b"1MM1\r\n", None), (b"1TE\r\n", b"1TEH\r\n")]) as stage, pytest.raises(DeviceFault, match="H"):
        stage.enable()


def test_velocity_and_acceleration_read_and_set_in_mm():
    script = [
        (b"1VA?\r\n", b"1VA5\r\n"),
        (b"1VA2.5\r\n", None),
        OK,
        (b"1AC?\r\n", b"1AC20\r\n"),
        (b"1AC40\r\n", None),
        OK,
    ]
    with smc100(script) as stage:
        assert stage.velocity_m_per_s() == pytest.approx(5e-3)
        stage.set_velocity(2.5e-3)
        assert stage.acceleration_m_per_s2() == pytest.approx(20e-3)
        stage.set_acceleration(40e-3)


def test_velocity_out_of_range_reports_letter_c():
    with smc100([(b"1VA50\r\n", None), (b"1TE\r\n", b"1TEC\r\n")]) as stage:
        with pytest.raises(DeviceFault, match="C \\(Parameter missing or out of range\\)"):
            stage.set_velocity(50e-3)


def test_soft_limits_read_and_set():
    script = [
        (b"1SL?\r\n", b"1SL-50\r\n"),  # read on open (no configured limits)
        (b"1SR?\r\n", b"1SR50\r\n"),
        (b"1SL?\r\n", b"1SL-50\r\n"),
        (b"1SR?\r\n", b"1SR50\r\n"),
        (b"1SL-10\r\n", None),
        OK,
        (b"1SR12.5\r\n", None),
        OK,
    ]
    with smc100(script, limits_m=None) as stage:
        assert stage.soft_limits_m() == pytest.approx((-50e-3, 50e-3))
        stage.set_soft_limits(-10e-3, 12.5e-3)
        assert stage.limits_m == pytest.approx((-10e-3, 12.5e-3))


def test_motion_time_query():
    with smc100([(b"1PT10\r\n", b"1PT2.25\r\n")]) as stage:
        assert stage.motion_time_s(10e-3) == pytest.approx(2.25)


def test_error_letter_read_back():
    with smc100([(b"1TE\r\n", b"1TEG\r\n")]) as stage:
        assert stage.error_letter() == "G"


@pytest.mark.parametrize(
    "reply,message",
    [
        (b"2TP1\r\n", "does not echo"),
        (b"1TPabc\r\n", "not a number"),
        (b"\x8f\xfe\x81\r\n", "unreadable reply"),
    ],
)
def test_bad_replies_are_protocol_errors(reply, message):
    with smc100([(b"1TP\r\n", reply)]) as stage, pytest.raises(DeviceProtocolError, match=message):
        stage.position_m()


def test_ts_with_unknown_state_is_a_protocol_error():
    with smc100([(b"1TS\r\n", b"1TS000099\r\n")]) as stage, pytest.raises(DeviceProtocolError, match="TS"):
        stage.status()


def test_silence_is_a_timeout_within_the_driver_timeout():
    clock = VirtualClock()
    with smc100([(b"1TP\r\n", None)], clock=clock, timeout_s=0.25) as stage:
        with pytest.raises(DeviceTimeout, match="stage: no reply to '1TP' within 0.25 s"):
            stage.position_m()
    assert clock.now_s() == pytest.approx(0.25)


def test_command_gap_is_waited_on_the_clock():
    clock = VirtualClock()
    script = [(b"1TP\r\n", b"1TP0\r\n"), (b"1TP\r\n", b"1TP0\r\n")]
    with smc100(script, clock=clock, command_gap_s=0.06) as stage:
        stage.position_m()
        stage.position_m()
    assert clock.now_s() == pytest.approx(0.06)


def test_driver_is_a_stage():
    from hamr_bench.interfaces import Stage

    with smc100([]) as stage:
        assert isinstance(stage, Stage)


@settings(max_examples=200, deadline=None)
@given(state=st.sampled_from([code for code, _ in MANUAL_STATES]), bits=st.integers(0, 0x03FF))
def test_any_documented_status_decodes_to_its_bits(state, bits):
    status = parse_status(f"{bits:04X}{state}")
    assert status.state_code == int(state, 16)
    assert len(status.errors) == bin(bits).count("1")


@settings(max_examples=100, deadline=None)
@given(text=st.text(max_size=8))
def test_status_parser_accepts_only_six_hex_digits_with_a_known_state(text):
    try:
        status = parse_status(text)
    except ValueError:
        return
    assert len(text) == 6 and status.state_code in dict(MANUAL_STATES_BY_CODE)


@settings(max_examples=100, deadline=None)
@given(target_m=st.floats(allow_nan=True, allow_infinity=True))
def test_no_target_outside_the_limits_ever_reaches_the_wire(target_m):
    inside = -0.025 <= target_m <= 0.025
    sent = f"1PA{format_mm(target_m)}\r\n".encode() if inside else b""
    script = [(sent, None), OK, (b"1TS\r\n", b"1TS000033\r\n")] if inside else []
    with smc100(script) as stage:
        if inside:
            stage.move_to(target_m)
        else:
            with pytest.raises(SafetyLimitError):
                stage.move_to(target_m)
