"""Byte-exact tests of the Loadstar driver on both command sets, written from the Loadstar command lists
(command + CR; replies end CR LF; CR alone answers `A`; W / O0W1 one reading, WC / O0W0 stream until CR; the
driver tares in software and never sends the sensor's CT0) and the unit definitions (1 lbf = 4.4482216152605 N,
1 kgf = 9.80665 N)."""

import pytest

from drivers.loadstar import LoadstarSensor
from drivers.testing import expected_protocol, scripted_port
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceProtocolError, DeviceTimeout

LBF_N = 4.4482216152605
KGF_N = 9.80665
READY = [(b"\r", b"A\r\n"), (b"\r", b"A\r\n")]  # CR (stops any stream, drained), CR -> A
OPEN_DI1000 = READY + [(b"UNITS\r", b"LB\r\n"), (b"LC\r", b"10.000\r\n")]  # DI-100U/DI-1000U page
OPEN_ILOAD = READY + [(b"SLC\r", b"10.000\r\n")]  # iLoad page: capacity in lb, readings in millipounds


def test_port_settings_9600_8n1_no_flow_control():
    with expected_protocol(LoadstarSensor, OPEN_DI1000) as sensor:
        settings = scripted_port(sensor).settings
    assert settings["baudrate"] == 9600 and settings["xonxoff"] is False


def test_open_reads_units_and_capacity():
    with expected_protocol(LoadstarSensor, OPEN_DI1000) as sensor:
        assert sensor.capacity_N == pytest.approx(10 * LBF_N)
        assert sensor.reading_unit == "LB"


def test_open_drains_a_sensor_left_streaming():
    script = [
        (None, b"0.512\r\n0.513\r\n0.5"),  # already in the port buffer when we open
        (b"\r", b"14\r\n0.515\r\n"),  # the stream ends with the CR; a line was still in flight
        (b"\r", b"A\r\n"),
        (b"UNITS\r", b"LB\r\n"),
        (b"LC\r", b"10.000\r\n"),
    ]
    with expected_protocol(LoadstarSensor, script) as sensor:
        assert sensor.capacity_N == pytest.approx(10 * LBF_N)


def test_open_without_ready_answer_is_a_protocol_error():
    with pytest.raises(DeviceProtocolError, match="expected 'A'"):
        with expected_protocol(LoadstarSensor, [(b"\r", None), (b"\r", b"?\r\n")]):
            pass


def test_identify():
    script = OPEN_DI1000 + [(b"MODEL\r", b"FCM DI-1000\r\n"), (b"ID\r", b"W1234-5678\r\n")]
    with expected_protocol(LoadstarSensor, script) as sensor:
        assert sensor.identify() == ("FCM DI-1000", "W1234-5678")


def test_single_reading_in_pounds():
    with expected_protocol(LoadstarSensor, OPEN_DI1000 + [(b"W\r", b"1.250\r\n")]) as sensor:
        assert sensor.read_N() == pytest.approx(1.25 * LBF_N)


def test_single_reading_in_kilograms():
    script = READY + [(b"UNITS\r", b"KG\r\n"), (b"LC\r", b"5.000\r\n"), (b"W\r", b"-0.2\r\n")]
    with expected_protocol(LoadstarSensor, script) as sensor:
        assert sensor.capacity_N == pytest.approx(5 * KGF_N)
        assert sensor.read_N() == pytest.approx(-0.2 * KGF_N)


def test_single_reading_in_newtons():
    script = READY + [(b"UNITS\r", b"N\r\n"), (b"LC\r", b"50\r\n"), (b"W\r", b"3.5\r\n")]
    with expected_protocol(LoadstarSensor, script) as sensor:
        assert sensor.read_N() == pytest.approx(3.5)


def test_unknown_unit_is_a_protocol_error():
    script = [(b"\r", b"A\r\n"), (b"\r", b"A\r\n"), (b"UNITS\r", b"STONE\r\n")]
    with pytest.raises(DeviceProtocolError, match="unknown unit 'STONE'"):
        with expected_protocol(LoadstarSensor, script):
            pass


def test_iload_reads_millipounds_and_capacity_in_pounds():
    script = OPEN_ILOAD + [(b"O0W1\r", b"2500\r\n"), (b"SS0\r", b"iLoad Pro\r\n"), (b"SS1\r", b"A1B2\r\n")]
    with expected_protocol(LoadstarSensor, script, command_set="iload") as sensor:
        assert sensor.capacity_N == pytest.approx(10 * LBF_N)
        assert sensor.read_N() == pytest.approx(2.5 * LBF_N)
        assert sensor.identify() == ("iLoad Pro", "A1B2")


def test_tare_is_the_mean_of_readings_kept_in_the_driver_and_sends_no_sensor_tare():
    # CT0 is never sent (a sensor saturated while it tares would read ~0 ever after); the zero is the readings'
    # mean, taken off every later reading
    script = OPEN_DI1000 + [(b"W\r", b"0.010\r\n"), (b"W\r", b"0.014\r\n"), (b"W\r", b"1.012\r\n")]
    with expected_protocol(LoadstarSensor, script, tare_readings=2) as sensor:
        sensor.tare()
        assert sensor.zero_N == pytest.approx(0.012 * LBF_N)
        assert sensor.read_N() == pytest.approx(1.0 * LBF_N)
    script = OPEN_ILOAD + [(b"O0W1\r", b"12\r\n"), (b"O0W1\r", b"1012\r\n")]  # millipounds
    with expected_protocol(LoadstarSensor, script, command_set="iload", tare_readings=1) as sensor:
        sensor.tare()
        assert sensor.read_N() == pytest.approx(1.0 * LBF_N)


def test_a_sensor_that_saturates_during_the_tare_is_an_overload_fault():
    script = OPEN_DI1000 + [(b"W\r", b"0.000\r\n"), (b"W\r", b"15.000\r\n")]
    with expected_protocol(LoadstarSensor, script, tare_readings=3) as sensor:
        with pytest.raises(DeviceFault, match="overload"):
            sensor.tare()


def test_overload_is_checked_on_the_load_before_the_tare_is_taken_off():
    # tared at 9 lb of a 10 lb sensor: 10.5 lb on it is an overload though it reads 1.5 lb above the zero
    script = OPEN_DI1000 + [(b"W\r", b"9.000\r\n"), (b"W\r", b"10.500\r\n")]
    with expected_protocol(LoadstarSensor, script, tare_readings=1) as sensor:
        sensor.tare()
        with pytest.raises(DeviceFault, match="overload"):
            sensor.read_N()


@pytest.mark.parametrize("count", [0, -2, 1.5, "3"])
def test_tare_readings_must_be_a_positive_whole_number(count):
    with pytest.raises(ConfigError, match="tare_readings"):
        LoadstarSensor("loop://", VirtualClock(), tare_readings=count)


def test_reading_beyond_capacity_is_an_overload_fault():
    with expected_protocol(LoadstarSensor, OPEN_DI1000 + [(b"W\r", b"10.500\r\n")]) as sensor:
        with pytest.raises(DeviceFault, match="overload: 46.71 N .*capacity 44.48 N"):
            sensor.read_N()


def test_garbage_reading_is_a_protocol_error():
    with expected_protocol(LoadstarSensor, OPEN_DI1000 + [(b"W\r", b"1.2.3\r\n")]) as sensor:
        with pytest.raises(DeviceProtocolError, match="not a number"):
            sensor.read_N()


def test_silent_sensor_times_out_within_the_timeout():
    clock = VirtualClock()
    script = OPEN_DI1000 + [(b"W\r", None)]
    with expected_protocol(LoadstarSensor, script, clock=clock, timeout_s=0.3) as sensor:
        start_s = clock.now_s()
        with pytest.raises(DeviceTimeout, match="force_sensor: no reply to 'W' within 0.3 s"):
            sensor.read_N()
        assert clock.now_s() - start_s == pytest.approx(0.3)


def test_stream_then_clean_stop():
    clock = VirtualClock()
    script = OPEN_DI1000 + [
        (b"WC\r", b"0.100\r\n0.200\r\n0.3"),
        (b"\r", b"00\r\n"),
        (b"\r", b"A\r\n"),
        (b"W\r", b"0.400\r\n"),
    ]
    with expected_protocol(LoadstarSensor, script, clock=clock, stream_rate_Hz=100.0) as sensor:
        sensor.start_stream()
        samples = sensor.read_stream()
        assert [s.force_N for s in samples] == pytest.approx([0.1 * LBF_N, 0.2 * LBF_N])
        # stamped back from arrival at the stream rate
        assert samples[1].time_s - samples[0].time_s == pytest.approx(0.01)
        assert samples[1].time_s == pytest.approx(clock.now_s())
        sensor.stop_stream()
        assert sensor.read_N() == pytest.approx(0.4 * LBF_N)


def test_iload_stream_command():
    script = OPEN_ILOAD + [(b"O0W0\r", b"1000\r\n"), (b"\r", None), (b"\r", b"A\r\n")]
    with expected_protocol(LoadstarSensor, script, command_set="iload") as sensor:
        sensor.start_stream()
        assert sensor.read_stream()[0].force_N == pytest.approx(LBF_N)
        sensor.stop_stream()


def test_silent_stream_times_out():
    clock = VirtualClock()
    script = OPEN_DI1000 + [(b"WC\r", None)]
    with expected_protocol(LoadstarSensor, script, clock=clock, timeout_s=0.5) as sensor:
        sensor.start_stream()
        assert sensor.read_stream() == []
        clock.sleep(0.6)
        with pytest.raises(DeviceTimeout, match="stream silent"):
            sensor.read_stream()


def test_overload_in_stream():
    script = OPEN_DI1000 + [(b"WC\r", b"1.000\r\n12.000\r\n")]
    with expected_protocol(LoadstarSensor, script) as sensor:
        sensor.start_stream()
        with pytest.raises(DeviceFault, match="overload"):
            sensor.read_stream()


def test_driver_is_a_force_sensor():
    from hamr_bench.interfaces import ForceSensor

    with expected_protocol(LoadstarSensor, OPEN_DI1000) as sensor:
        assert isinstance(sensor, ForceSensor)
