"""TREK amplifier driver: clamp and slew limit (property-based, against a recording fake DAQ that knows
nothing of the driver's rules), ramps, waveforms, zero, and every injected fault through the simulated DAQ."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from drivers.trek_amplifier import TrekAmplifier
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout, SafetyLimitError
from hamr_bench.interfaces import AiBlock, Amplifier, DaqBackend
from sim_devices.daq_sim import SimAmplifierSpec, SimDaq

GAIN = 35.0
SLEW = 20_000.0
MAX_V = 250.0
STEP_S = 1e-3  # ramp_update_rate_Hz = 1 kHz


class RecordingDaq:
    """Records what reaches the DAQ as a time line of (time_s, value_V) output changes (zero-order hold)."""

    def __init__(self, clock: VirtualClock) -> None:
        self.clock = clock
        self.scalars: list[tuple[float, float]] = []
        self.waves: list[list] = []  # [t0, rate, samples, stop_time]

    def _truncate(self) -> None:
        now = self.clock.now_s()
        if self.waves and self.waves[-1][3] is None:
            t0, rate, samples, _ = self.waves[-1]
            self.waves[-1][3] = min(now, t0 + (len(samples) - 1) / rate + 1e-12)

    def write_ao_scalar(self, channel: str, value_V: float) -> None:
        self._truncate()
        self.scalars.append((self.clock.now_s(), float(value_V)))

    def write_ao_waveform(self, channel: str, samples_V: np.ndarray, sample_rate_Hz: float) -> float:
        self._truncate()
        t0 = self.clock.now_s()
        self.waves.append([t0, sample_rate_Hz, np.array(samples_V, dtype=float), None])
        return t0

    def wait_ao_done(self, channel: str, timeout_s: float) -> None:
        t0, rate, samples, _ = self.waves[-1]
        self.clock.advance_to(t0 + len(samples) / rate)

    def stop_ao(self, channel: str) -> float:
        t0, rate, samples, _ = self.waves[-1]
        now = self.clock.now_s()
        k = min(int((now - t0) * rate), len(samples) - 1)
        self._truncate()
        return float(samples[k])

    def read_ai(self, channels, n_samples, sample_rate_Hz, timeout_s=10.0) -> AiBlock:
        t0 = self.clock.now_s()
        self.clock.sleep(n_samples / sample_rate_Hz)
        return AiBlock(t0, sample_rate_Hz, np.zeros((len(channels), n_samples)))

    def start_ai_stream(self, channels, sample_rate_Hz):
        raise NotImplementedError

    def read_ai_stream(self):
        raise NotImplementedError

    def stop_ai_stream(self):
        raise NotImplementedError

    def close(self) -> None:
        pass

    def timeline(self) -> list[tuple[float, float]]:
        self._truncate()
        events = list(self.scalars)
        for t0, rate, samples, stop in self.waves:
            stop = math.inf if stop is None else stop
            k = np.arange(len(samples))
            keep = t0 + k / rate <= stop + 1e-12
            events += list(zip((t0 + k[keep] / rate).tolist(), samples[keep].tolist(), strict=True))
        # stable sort on time: at equal times the later write wins, which is the order they were recorded in
        return sorted(events, key=lambda e: e[0])


def make(clock, daq, **kw):
    return TrekAmplifier(
        daq, clock, ao_channel="ao0", monitor_channel="ai0", gain_V_per_V=GAIN, monitor_scale_V_per_V=100.0,
        slew_rate_V_per_s=SLEW, max_voltage_V=MAX_V, check_monitor_after_set=False, **kw,
    )


def assert_safe(timeline: list[tuple[float, float]]) -> None:
    prev_t, prev_v = 0.0, 0.0
    for t, v in timeline:
        assert 0.0 <= v <= MAX_V / GAIN + 1e-12, (t, v)
        allowed = SLEW / GAIN * min(t - prev_t, STEP_S)
        assert abs(v - prev_v) <= allowed * (1 + 1e-9) + 1e-15, (prev_t, prev_v, t, v, allowed)
        prev_t, prev_v = t, v


def test_is_an_amplifier() -> None:
    clock = VirtualClock()
    assert isinstance(make(clock, RecordingDaq(clock)), Amplifier)
    assert isinstance(RecordingDaq(clock), DaqBackend)


voltages = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.floats(min_value=-50, max_value=400),
)
rates = st.one_of(st.floats(min_value=0.5, max_value=1e5), st.sampled_from([0.0, -10.0, math.nan, math.inf]))
ops = st.one_of(
    st.tuples(st.just("set"), voltages),
    st.tuples(st.just("wave"), st.lists(voltages, min_size=1, max_size=40), rates),
    st.tuples(st.just("sleep"), st.floats(min_value=0, max_value=0.05)),
    st.tuples(st.just("wait"),),
    st.tuples(st.just("zero"),),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(ops, max_size=12))
def test_nothing_reaches_the_daq_beyond_clamp_or_slew(sequence) -> None:
    clock = VirtualClock()
    daq = RecordingDaq(clock)
    amp = make(clock, daq)
    for op in sequence:
        try:
            if op[0] == "set":
                amp.set_voltage(op[1])
            elif op[0] == "wave":
                amp.play_waveform(np.array(op[1]), op[2])
            elif op[0] == "sleep":
                clock.sleep(op[1])
            elif op[0] == "wait":
                amp.wait_done()
            else:
                amp.zero()
        except (SafetyLimitError, ConfigError) as exc:
            assert "\n" not in str(exc)
            bad = [op[1]] if op[0] == "set" else list(op[1]) + [op[2]] if op[0] == "wave" else []
            assert any(not math.isfinite(x) or x <= 0 or x > 1e5 for x in bad), exc
    amp.zero()
    timeline = daq.timeline()
    assert_safe(timeline)
    assert timeline[-1][1] == 0.0


def test_non_finite_refused_and_never_written() -> None:
    clock = VirtualClock()
    daq = RecordingDaq(clock)
    amp = make(clock, daq)
    for bad in (math.nan, math.inf, -math.inf):
        with pytest.raises(SafetyLimitError):
            amp.set_voltage(bad)
        with pytest.raises(SafetyLimitError):
            amp.play_waveform(np.array([1.0, bad]), 1000.0)
    assert all(math.isfinite(v) for _, v in daq.timeline())


def test_set_voltage_ramps_at_the_slew_limit_and_clamps() -> None:
    clock = VirtualClock()
    daq = RecordingDaq(clock)
    amp = make(clock, daq)
    amp.set_voltage(1_000.0)  # clamped to 250 V
    assert amp.commanded_voltage_V() == pytest.approx(MAX_V)
    # 250 V at 20 kV/s takes 12.5 ms: the ramp cannot be faster, and at 1 kHz updates it is not much slower
    assert 0.0125 <= clock.now_s() <= 0.0125 + 2 * STEP_S
    amp.set_voltage(-5.0)
    assert amp.commanded_voltage_V() == 0.0
    assert_safe(daq.timeline())


def test_zero_stops_a_waveform_and_ramps_down() -> None:
    clock = VirtualClock()
    daq = RecordingDaq(clock)
    amp = make(clock, daq)
    rate = 10_000.0
    t = np.arange(20_000) / rate
    wave = 125.0 - 125.0 * np.cos(2 * np.pi * 20.0 * t)  # 20 Hz, 0-250 V: peak slope 15.7 kV/s < slew
    t0 = amp.play_waveform(wave, rate)
    clock.sleep(0.0126)  # near the crest
    on_crest = amp.commanded_voltage_V()
    assert on_crest == pytest.approx(wave[int(0.0126 * rate)], abs=1e-9)
    amp.zero()
    assert amp.commanded_voltage_V() == 0.0
    # ramp-down time at the slew limit
    assert clock.now_s() - t0 - 0.0126 >= on_crest / SLEW
    assert_safe(daq.timeline())
    assert daq.waves[-1][3] is not None and daq.waves[-1][3] < t0 + 0.02


def test_compliant_waveform_passes_unchanged_and_wait_done_ends_it() -> None:
    clock = VirtualClock()
    daq = RecordingDaq(clock)
    amp = make(clock, daq)
    rate = 5_000.0
    wave = np.linspace(0.0, 100.0, 100)  # 1 V per 0.2 ms = 5 kV/s
    t0 = amp.play_waveform(wave, rate)
    np.testing.assert_allclose(daq.waves[-1][2] * GAIN, wave)
    amp.wait_done()
    assert clock.now_s() == pytest.approx(t0 + 100 / rate)
    assert amp.commanded_voltage_V() == pytest.approx(100.0)


def test_a_step_waveform_is_slew_limited() -> None:
    clock = VirtualClock()
    daq = RecordingDaq(clock)
    amp = make(clock, daq)
    amp.play_waveform(np.full(100, 200.0), 10_000.0)
    sent = daq.waves[-1][2] * GAIN
    assert np.max(np.diff(sent, prepend=0.0)) <= SLEW / 10_000.0 * (1 + 1e-9)
    assert sent[-1] == pytest.approx(200.0)  # 200 V / 2 V per sample = 100 samples: just reaches it


def test_bad_configuration_is_one_line_config_error() -> None:
    clock = VirtualClock()
    with pytest.raises(ConfigError, match="gain_V_per_V"):
        TrekAmplifier(RecordingDaq(clock), clock, ao_channel="ao0", monitor_channel="ai0", gain_V_per_V=-1,
                      monitor_scale_V_per_V=100, slew_rate_V_per_s=1e4)
    with pytest.raises(ConfigError, match="daq_range_V"):
        TrekAmplifier(RecordingDaq(clock), clock, ao_channel="ao0", monitor_channel="ai0", gain_V_per_V=10,
                      monitor_scale_V_per_V=100, slew_rate_V_per_s=1e4, max_voltage_V=250)


# ---- against the simulated DAQ / amplifier -----------------------------------------------------------------

def sim_rig(seed: int = 1):
    clock = VirtualClock()
    spec = SimAmplifierSpec("Dev1/ao0", "Dev1/ai0", gain_V_per_V=GAIN, bandwidth_Hz=5_000.0,
                            monitor_scale_V_per_V=100.0)
    daq = SimDaq(clock, np.random.default_rng(seed), amplifiers=[spec])
    amp = TrekAmplifier(daq, clock, ao_channel="Dev1/ao0", monitor_channel="Dev1/ai0", gain_V_per_V=GAIN,
                        monitor_scale_V_per_V=100.0, slew_rate_V_per_s=SLEW, timeout_s=0.5, name="drive")
    return clock, daq, amp


def test_monitor_follows_output_on_the_sim() -> None:
    clock, daq, amp = sim_rig()
    assert isinstance(daq, DaqBackend)  # the simulated DAQ has the whole backend surface
    amp.set_voltage(150.0)
    clock.sleep(0.01)
    # monitor noise 1 mV x 100 V/V / sqrt(20 samples) = 22 mV rms
    assert amp.monitor_voltage_V() == pytest.approx(150.0, abs=0.2)
    assert daq.output_voltage_V("Dev1/ao0", clock.now_s()) == pytest.approx(150.0, abs=1e-6)


def test_amp_trip_raises_device_fault_on_next_monitor_check() -> None:
    clock, daq, amp = sim_rig()
    amp.set_voltage(100.0)
    daq.inject_fault("amp_trip", "Dev1/ao0")
    with pytest.raises(DeviceFault, match="trip") as info:
        amp.monitor_voltage_V()
    assert "\n" not in str(info.value)
    amp.zero()  # the safe state is still reachable after a trip
    assert amp.commanded_voltage_V() == 0.0


def test_amp_trip_during_set_voltage_is_caught_on_arrival() -> None:
    clock, daq, amp = sim_rig()
    daq.inject_fault("amp_trip")
    with pytest.raises(DeviceFault):
        amp.set_voltage(80.0)


def test_disconnect_raises_device_fault() -> None:
    clock, daq, amp = sim_rig()
    daq.inject_fault("disconnect")
    with pytest.raises(DeviceFault, match="disconnected"):
        amp.set_voltage(50.0)
    with pytest.raises(DeviceFault):
        amp.monitor_voltage_V()


def test_no_reply_times_out_within_driver_timeout() -> None:
    clock, daq, amp = sim_rig()
    daq.inject_fault("no_reply")
    t0 = clock.now_s()
    with pytest.raises(DeviceTimeout):
        amp.monitor_voltage_V()
    assert clock.now_s() - t0 <= 0.5 + 1e-9


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(min_value=0, max_value=10), min_size=1, max_size=80),
       st.floats(min_value=0, max_value=10), st.floats(min_value=1e-3, max_value=2.0))
def test_slew_limiter_matches_the_plain_sample_loop(samples, start, max_step) -> None:
    from drivers.trek_amplifier import slew_limit

    expected, prev = [], start
    for target in samples:  # the textbook limiter, one sample at a time
        prev += min(max(target - prev, -max_step), max_step)
        expected.append(prev)
    got = slew_limit(np.array(samples), start, max_step)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    assert np.all(np.abs(np.diff(got, prepend=start)) <= max_step * (1 + 1e-12))  # up to rounding in diff


def test_no_reply_on_write_is_device_timeout() -> None:
    clock, daq, amp = sim_rig()
    daq.inject_fault("no_reply")
    with pytest.raises(DeviceTimeout):
        amp.set_voltage(20.0)
