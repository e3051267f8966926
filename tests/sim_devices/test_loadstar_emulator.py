"""The Loadstar sensor model and interface: quantisation to the resolution, noise from the resolution (a
quantised Gaussian of sigma = 1 count has a standard deviation of sqrt(1 + 1/12) counts), saturation, tare,
drift, units, and lazy streaming at the interface's rate with each line computed when it is produced."""

import numpy as np
import pytest

from hamr_bench.clock import VirtualClock
from sim_devices.loadstar_emulator import LoadstarEmulator, LoadstarParams

LBF_N = 4.4482216152605


def make(force=lambda t: 0.0, seed=0, **params):
    clock = VirtualClock()
    return LoadstarEmulator(clock, force, np.random.default_rng(seed), LoadstarParams(**params)), clock


def ask(emu, clock, text: bytes, wait_s: float = 0.1) -> bytes:
    emu.receive(text)
    clock.sleep(wait_s)
    return emu.output_until(clock.now_s())


def test_readings_are_whole_counts_of_the_resolution():
    emu, clock = make(force=lambda t: 1.2345678 * LBF_N, noise_counts=0.0)
    assert emu.reading(0.0) == pytest.approx(1.235)
    assert ask(emu, clock, b"W\r") == b"1.235\r\n"


def test_noise_comes_from_the_resolution():
    emu, clock = make(force=lambda t: 3.0, noise_counts=1.0, seed=3)
    values = np.array([emu.reading(0.0) for _ in range(4000)])
    counts = values / 0.001
    assert np.allclose(counts, np.round(counts), atol=1e-6)
    assert values.std() == pytest.approx(0.001 * np.sqrt(1 + 1 / 12), rel=0.08)
    assert values.mean() == pytest.approx(3.0 / LBF_N, abs=0.0001)


def test_same_seed_same_readings():
    a, _ = make(force=lambda t: 1.0, seed=11)
    b, _ = make(force=lambda t: 1.0, seed=11)
    assert [a.reading(0.0) for _ in range(10)] == [b.reading(0.0) for _ in range(10)]


def test_saturates_beyond_capacity():
    emu, clock = make(force=lambda t: 100 * LBF_N, noise_counts=0.0)
    assert emu.reading(0.0) == pytest.approx(15.0)  # 1.5 x 10 lb
    emu2, _ = make(noise_counts=0.0)
    emu2.faults.inject("overload")
    assert emu2.reading(0.0) == pytest.approx(15.0)


def test_tare_zeroes_the_present_load_after_its_delay():
    emu, clock = make(force=lambda t: 2 * LBF_N, noise_counts=0.0)
    emu.receive(b"CT0\r")
    clock.sleep(0.2)
    assert emu.output_until(clock.now_s()) == b""  # tare takes 0.3 s
    clock.sleep(0.2)
    assert emu.output_until(clock.now_s()) == b"Tared\r\n"
    assert emu.reading(clock.now_s()) == 0.0


def test_linear_drift():
    emu, clock = make(noise_counts=0.0, drift="linear", drift_strength=0.01 * LBF_N)
    assert emu.reading(10.0) == pytest.approx(0.1)


def test_random_walk_drift_grows_like_sqrt_time():
    emu, clock = make(noise_counts=0.0, drift="random_walk", drift_strength=0.5, seed=5)
    drift = np.array([emu.drift_N(float(t)) for t in range(1, 2001)])
    steps = np.diff(drift)
    assert steps.std() == pytest.approx(0.5, rel=0.08)  # N per sqrt(1 s)
    assert abs(steps.mean()) < 4 * 0.5 / np.sqrt(len(steps))


def test_ready_and_identity_commands():
    emu, clock = make()
    assert ask(emu, clock, b"\r") == b"A\r\n"
    assert ask(emu, clock, b"MODEL\r") == b"FCM DI-1000\r\n"  # the DI-100U/DI-1000U page
    assert ask(emu, clock, b"ID\r") == b"LS-HAMRSIM-0001\r\n"
    assert ask(emu, clock, b"UNITS\r") == b"LB\r\n"
    assert ask(emu, clock, b"LC\r") == b"10.000\r\n"


def test_iload_reads_in_millipounds():
    emu, clock = make(force=lambda t: 0.25 * LBF_N, noise_counts=0.0, command_set="iload")
    assert ask(emu, clock, b"O0W1\r") == b"250\r\n"
    assert ask(emu, clock, b"SLC\r") == b"10.000\r\n"


def test_stream_rate_and_lines_computed_when_produced():
    baud = 230400  # fast enough that the 150 Hz sample rate is the limit
    emu, clock = make(force=lambda t: t * LBF_N, noise_counts=0.0, baudrate=baud)  # 1 lb per second ramp
    emu.receive(b"WC\r")
    clock.sleep(1.0)
    lines = emu.output_until(clock.now_s()).split(b"\r\n")[:-1]
    # sample k is produced at 3 ms + k/150 s and has arrived once its 7 bytes are through
    produced_s = 0.003 + np.arange(400) / 150
    arrived = produced_s + 7 * 10 / baud <= 1.0
    assert len(lines) == arrived.sum()
    values = np.array([float(v) for v in lines])
    assert values == pytest.approx(produced_s[arrived], abs=0.0005 + 1e-9)


def test_stream_rate_is_limited_by_the_baud_rate():
    emu, clock = make(force=lambda t: 0.5 * LBF_N, noise_counts=0.0, baudrate=9600)
    emu.receive(b"WC\r")
    clock.sleep(1.0)
    lines = emu.output_until(clock.now_s()).split(b"\r\n")[:-1]
    line_s = len(b"0.500\r\n") * 10 / 9600  # 7.3 ms > 1/150 s: the wire sets the pace
    produced_s = 0.003 + np.arange(400) * line_s
    assert len(lines) == (produced_s + line_s <= 1.0).sum()


def test_cr_stops_the_stream_and_nothing_more_is_produced():
    emu, clock = make()
    emu.receive(b"WC\r")
    clock.sleep(0.1)
    emu.receive(b"\r")
    emu.output_until(clock.now_s() + 1.0)
    assert emu.next_output_s() is None
    assert not emu.streaming


# Each family's spellings as Loadstar's pages give them, and that the other family's do not work on it.
DI1000_SPELLINGS = [b"MODEL", b"ID", b"UNITS", b"UNIT", b"LC", b"CT0", b"TARE", b"W"]
ILOAD_SPELLINGS = [b"SS0", b"SS1", b"SLC", b"CT0", b"O0W1", b"W"]


@pytest.mark.parametrize("command", DI1000_SPELLINGS)
def test_di1000_answers_its_commands_in_any_case(command):
    emu, clock = make(noise_counts=0.0)
    assert ask(emu, clock, command + b"\r", wait_s=1.0).endswith(b"\r\n")
    assert ask(emu, clock, command.lower() + b"\r", wait_s=1.0).endswith(b"\r\n")


@pytest.mark.parametrize("command", ILOAD_SPELLINGS)
def test_iload_answers_its_commands(command):
    emu, clock = make(noise_counts=0.0, command_set="iload")
    assert ask(emu, clock, command + b"\r", wait_s=1.0).endswith(b"\r\n")


FOREIGN = [("di1000", b"SLC"), ("di1000", b"SS1"), ("di1000", b"O0W1"), ("iload", b"LC"), ("iload", b"ID"),
           ("iload", b"UNITS"), ("iload", b"TARE"), ("iload", b"MODEL")]


@pytest.mark.parametrize(("command_set", "foreign"), FOREIGN)
def test_the_other_familys_commands_get_no_answer(command_set, foreign):
    emu, clock = make(command_set=command_set)
    assert ask(emu, clock, foreign + b"\r", wait_s=1.0) == b""


def test_tare_replies_per_family():
    emu, clock = make()
    assert ask(emu, clock, b"TARE\r", wait_s=1.0) == b"Tared\r\n"
    emu, clock = make(command_set="iload")
    assert ask(emu, clock, b"CT0\r", wait_s=1.0) == b"A\r\n"  # "wait for the 'A' for acknowledgment"


def test_an_iload_firmware_without_w():
    emu, clock = make(command_set="iload", refused_spellings=("W",), noise_counts=0.0)
    assert ask(emu, clock, b"W\r") == b""
    assert ask(emu, clock, b"O0W1\r") == b"0\r\n"
