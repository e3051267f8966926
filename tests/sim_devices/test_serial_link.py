"""The in-process serial link (`hamrsim://NAME`): reads on a virtual clock jump to the modelled due time or to
the timeout, never hang, lose bytes sent before open, fail like a pulled adapter on disconnect; wire faults
change the bytes as documented."""

import itertools

import numpy as np
import pytest
import serial

from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError
from sim_devices.faults import FAULT_NAMES, SERIAL_FAULTS, FaultInjector, parse_fault_spec
from sim_devices.serial_link import LineEndpoint, register_endpoint, unregister_endpoint

_names = itertools.count()
BAUD = 9600
LATENCY_S = 0.01


class Echo(LineEndpoint):
    """Answers each line with the same text after the latency."""

    def __init__(self, clock):
        super().__init__(
            clock, FaultInjector(SERIAL_FAULTS), device="echo", baudrate=BAUD, reply_latency_s=LATENCY_S,
            input_terminator=b"\n",
        )

    def handle_line(self, line, time_s):
        self.send(line, time_s)


@pytest.fixture
def link():
    clock = VirtualClock()
    endpoint = Echo(clock)
    name = f"echo-{next(_names)}"
    url = register_endpoint(name, endpoint)
    port = serial.serial_for_url(url, timeout=1.0)
    yield port, endpoint, clock
    port.close()
    unregister_endpoint(name)


def test_read_lands_on_the_reply_due_time(link):
    port, endpoint, clock = link
    port.write(b"hello\n")
    assert port.read(7) == b"hello\r\n"
    assert clock.now_s() == pytest.approx(LATENCY_S + 7 * 10 / BAUD, abs=1e-12)


def test_read_with_nothing_due_waits_out_the_timeout(link):
    port, endpoint, clock = link
    port.timeout = 0.25
    assert port.read(1) == b""
    assert clock.now_s() == pytest.approx(0.25)


def test_read_returns_what_arrived_by_the_timeout(link):
    port, endpoint, clock = link
    port.write(b"ab\n")
    port.timeout = 0.5
    assert port.read(100) == b"ab\r\n"
    assert clock.now_s() == pytest.approx(0.5)


def test_blocking_read_with_nothing_coming_raises_instead_of_hanging(link):
    port, endpoint, clock = link
    port.timeout = None
    with pytest.raises(serial.SerialException, match="nothing will arrive"):
        port.read(1)


def test_in_waiting_does_not_move_time(link):
    port, endpoint, clock = link
    port.write(b"x\n")
    assert port.in_waiting == 0
    assert clock.now_s() == 0.0


def test_bytes_sent_before_open_are_lost():
    clock = VirtualClock()
    endpoint = Echo(clock)
    endpoint.receive(b"early\n")
    clock.sleep(1.0)
    url = register_endpoint(f"echo-{next(_names)}", endpoint)
    port = serial.serial_for_url(url, timeout=0.1)
    assert port.read(10) == b""


def test_unknown_name_and_bad_names():
    with pytest.raises(serial.SerialException, match="no simulated device"):
        serial.serial_for_url("hamrsim://nobody-here", timeout=0.1)
    with pytest.raises(ConfigError):
        register_endpoint("bad name", Echo(VirtualClock()))
    url = register_endpoint("dup-test", Echo(VirtualClock()))
    with pytest.raises(ConfigError, match="already registered"):
        register_endpoint("dup-test", Echo(VirtualClock()))
    assert url == "hamrsim://dup-test"
    unregister_endpoint("dup-test")


def test_disconnect_fails_reads_writes_and_open(link):
    port, endpoint, clock = link
    endpoint.faults.inject("disconnect", at_s=0.5)
    port.write(b"still here\n")
    assert port.read(12) == b"still here\r\n"
    clock.sleep(1.0)
    with pytest.raises(serial.SerialException, match="disconnected"):
        port.read(1)
    with pytest.raises(serial.SerialException, match="disconnected"):
        port.write(b"x\n")
    with pytest.raises(serial.SerialException):
        serial.serial_for_url(port.port, timeout=0.1)


def test_disconnect_during_a_wait_is_noticed(link):
    port, endpoint, clock = link
    endpoint.faults.inject("disconnect", at_s=0.2)
    port.timeout = 1.0
    with pytest.raises(serial.SerialException):
        port.read(1)


def test_no_reply_garbage_and_dropped_bytes(link):
    port, endpoint, clock = link
    port.timeout = 0.2
    endpoint.faults.inject("no_reply")
    port.write(b"abc\n")
    assert port.read(100) == b""
    endpoint.faults.clear()
    endpoint.faults.inject("garbage_bytes")
    port.write(b"abcdef\n")
    garbage = port.read(100)
    assert garbage.endswith(b"\r\n") and len(garbage) == 8
    body = garbage[:-2]
    assert all(b >= 0x80 for b in body)  # never ASCII, never XON/XOFF
    endpoint.faults.clear()
    endpoint.faults.inject("dropped_bytes")
    port.write(b"abcdef\n")
    dropped = port.read(100)
    assert len(dropped) == len(b"abcdef\r\n") - 2 and not dropped.endswith(b"\n")


def test_replies_stay_in_order(link):
    port, endpoint, clock = link
    endpoint.send("slow", 0.0, extra_delay_s=0.5)
    endpoint.send("fast", 0.0)
    assert port.read(12) == b"slow\r\nfast\r\n"


def test_fault_vocabulary():
    assert set(SERIAL_FAULTS) <= set(FAULT_NAMES)
    for name in ("following_error", "end_of_run", "overload", "amp_trip", "dropped_frames"):
        assert name in FAULT_NAMES
    assert parse_fault_spec("overload@2.5") == ("overload", 2.5)
    assert parse_fault_spec("no_reply") == ("no_reply", float("-inf"))
    with pytest.raises(ConfigError):
        parse_fault_spec("overload@soon")


def test_same_seed_same_garbage():
    def garbage(seed):
        clock = VirtualClock()
        endpoint = Echo(clock)
        endpoint.rng = np.random.default_rng(seed)
        endpoint.faults.inject("garbage_bytes")
        endpoint.receive(b"abcdef\n")
        return endpoint.output_until(1.0)

    assert garbage(1) == garbage(1) != garbage(2)
