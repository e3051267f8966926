"""Driver for one channel of a TREK PZD350A-style high-voltage amplifier driven by a DAQ analog output, with
its monitor output read back on a DAQ analog input. Implements `hamr_bench.interfaces.Amplifier`.

Output volts = DAQ AO volts x `gain_V_per_V`; output volts = monitor AI volts x `monitor_scale_V_per_V`.
Neither the gain, the monitor scale nor the amplifier's own slew rate are verified for the PZD350A here, so
they are required constructor parameters (the rig file states them).

Safety lives here, between every caller and the DAQ: each scalar and each waveform sample is (1) refused if
not finite, (2) clamped to [0, max_voltage_V], (3) slew-limited so that no step of the DAQ output exceeds
`slew_rate_V_per_s x min(interval, 1 / ramp_update_rate_Hz) / gain`, measured from the last value the DAQ was
given. The bound on the step (not only on step/interval) matters because the DAQ output is a staircase: a long
pause must not license a jump. The driver assumes the output is at 0 V when constructed and writes 0 V to make
it so.

Trip detection: a monitor reading below `trip_fraction` of the voltage commanded over the same samples (when
that is above `trip_check_min_V`) raises DeviceFault; `set_voltage` checks the monitor when it arrives.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout, SafetyLimitError
from hamr_bench.interfaces import DaqBackend


def _positive(name: str, value: float) -> float:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ConfigError(f"TrekAmplifier: {name} must be a positive finite number, got {value!r}")
    return float(value)


def slew_limit(samples: np.ndarray, start: float, max_step: float) -> np.ndarray:
    """Causal slew limiter: each output moves toward its input sample by at most `max_step` from the previous
    output (the first from `start`). Only the stretches where the limiter is active are looped over: a sample
    loop runs from the first violation until the output has caught up with the input, then the rest is checked
    vectorised again, because most waveforms comply almost everywhere."""
    out = np.array(samples, dtype=float)
    prev = float(start)
    i = 0
    n = out.size
    while i < n:
        steps = np.abs(np.diff(out[i:], prepend=prev))
        bad = np.flatnonzero(steps > max_step)
        if bad.size == 0:
            break
        i += int(bad[0])
        prev = float(out[i - 1]) if i > 0 else float(start)
        while i < n:  # limiting: follow the input at the maximum rate until caught up
            target = float(samples[i])
            delta = target - prev
            if -max_step <= delta <= max_step:
                prev = target
                out[i] = target
                i += 1
                break
            prev = prev + (max_step if delta > 0 else -max_step)
            out[i] = prev
            i += 1
        # out[i-1] == samples[i-1] again: the remainder starts from there unchanged
    return out


class TrekAmplifier:
    """One HV output channel (`bias` or `drive`) on a DAQ backend; the module docstring gives the safety
    rules."""

    def __init__(
        self,
        daq: DaqBackend,
        clock: Clock,
        *,
        ao_channel: str,
        monitor_channel: str,
        gain_V_per_V: float,
        monitor_scale_V_per_V: float,
        slew_rate_V_per_s: float,
        max_voltage_V: float = 250.0,
        daq_range_V: float = 10.0,
        ramp_update_rate_Hz: float = 1_000.0,
        max_sample_rate_Hz: float = 100_000.0,
        monitor_samples: int = 20,
        monitor_sample_rate_Hz: float = 10_000.0,
        trip_fraction: float = 0.5,
        trip_check_min_V: float = 10.0,
        check_monitor_after_set: bool = True,
        timeout_s: float = 5.0,
        name: str = "amplifier",
    ) -> None:
        self._daq = daq
        self._clock = clock
        self._ao = ao_channel
        self._mon = monitor_channel
        self._name = name
        self._gain = _positive("gain_V_per_V", gain_V_per_V)
        self._mon_scale = _positive("monitor_scale_V_per_V", monitor_scale_V_per_V)
        self._slew = _positive("slew_rate_V_per_s", slew_rate_V_per_s)
        self._max_V = _positive("max_voltage_V", max_voltage_V)
        self._step_s = 1.0 / _positive("ramp_update_rate_Hz", ramp_update_rate_Hz)
        self._max_rate = _positive("max_sample_rate_Hz", max_sample_rate_Hz)
        self._mon_rate = _positive("monitor_sample_rate_Hz", monitor_sample_rate_Hz)
        self._timeout_s = _positive("timeout_s", timeout_s)
        if self._max_V / self._gain > _positive("daq_range_V", daq_range_V):
            raise ConfigError(
                f"TrekAmplifier {name}: max_voltage_V={max_voltage_V} needs "
                f"{max_voltage_V / gain_V_per_V:g} V "
                f"from the DAQ, beyond daq_range_V={daq_range_V}"
            )
        if int(monitor_samples) < 1:
            raise ConfigError(f"TrekAmplifier {name}: monitor_samples must be >= 1, got {monitor_samples!r}")
        self._mon_n = int(monitor_samples)
        self._trip_fraction = float(trip_fraction)
        self._trip_min_V = float(trip_check_min_V)
        self._check_after_set = check_monitor_after_set
        # the DAQ value the output holds when no waveform runs, and when it got there (last write, clock time)
        self._held_daq_V = 0.0
        self._held_since_s = clock.now_s()
        self._wave: tuple[float, float, np.ndarray] | None = None  # (start time, rate, DAQ samples)
        self._daq.write_ao_scalar(self._ao, 0.0)
        self._held_since_s = clock.now_s()

    # ---- Amplifier surface ---------------------------------------------------------------------------------
    @property
    def max_voltage_V(self) -> float:
        return self._max_V

    @property
    def slew_rate_V_per_s(self) -> float:
        return self._slew

    @property
    def gain_V_per_V(self) -> float:
        return self._gain

    def set_voltage(self, voltage_V: float) -> None:
        target = self._clamp_scalar(voltage_V) / self._gain
        self._ramp_to(target)
        if self._check_after_set:
            self.monitor_voltage_V()

    def play_waveform(self, voltage_V: np.ndarray, sample_rate_Hz: float) -> float:
        try:
            rate = float(sample_rate_Hz)
        except (TypeError, ValueError):
            rate = math.nan
        if not (math.isfinite(rate) and 0 < rate <= self._max_rate):
            raise ConfigError(
                f"{self._name}: sample_rate_Hz={sample_rate_Hz!r} outside (0, {self._max_rate:g}]"
            )
        samples = np.asarray(voltage_V, dtype=float)
        if samples.ndim != 1 or samples.size == 0:
            raise ConfigError(
                f"{self._name}: waveform must be a non-empty 1-D array, got shape {samples.shape}"
            )
        if not np.all(np.isfinite(samples)):
            bad = int(np.flatnonzero(~np.isfinite(samples))[0])
            raise SafetyLimitError(f"{self._name}: waveform sample {bad} is {samples[bad]!r}; refused")
        self._stop_wave()
        step_s = min(1.0 / rate, self._step_s)
        self._wait_since_held(step_s)
        daq = np.clip(samples, 0.0, self._max_V) / self._gain
        daq = slew_limit(daq, self._held_daq_V, self._max_step(step_s))
        t0 = self._daq.write_ao_waveform(self._ao, daq, rate)
        self._wave = (float(t0), rate, daq)
        return float(t0)

    def wait_done(self) -> None:
        if self._wave is None:
            return
        t0, rate, daq = self._wave
        remaining = t0 + len(daq) / rate - self._clock.now_s()
        self._daq.wait_ao_done(self._ao, max(remaining, 0.0) + self._timeout_s)
        self._settle_wave()

    def commanded_voltage_V(self) -> float:
        return float(self._commanded_daq(np.array([self._clock.now_s()]))[0]) * self._gain

    def monitor_voltage_V(self) -> float:
        block = self._daq.read_ai([self._mon], self._mon_n, self._mon_rate, self._timeout_s)
        data = np.asarray(block.data_V, dtype=float)
        n = data.shape[1]
        if n == 0:
            raise DeviceTimeout(f"{self._name}: monitor {self._mon} returned no samples", device=self._name)
        # sum / n is np.mean's own arithmetic, without its dispatch (read twice per 20 ms poll of a run)
        monitor_V = float(np.add.reduce(data[0])) / n * self._mon_scale
        times = block.start_time_s + np.arange(n) / block.sample_rate_Hz
        commanded_V = float(np.add.reduce(self._commanded_daq(times))) / n * self._gain
        if commanded_V >= self._trip_min_V and monitor_V < self._trip_fraction * commanded_V:
            raise DeviceFault(
                f"{self._name}: amplifier trip: monitor {self._mon} reads {monitor_V:.1f} V "
                f"while {commanded_V:.1f} V is commanded on {self._ao}",
                device=self._name,
            )
        return monitor_V

    def zero(self) -> None:
        self._ramp_to(0.0)

    def close(self) -> None:
        self.zero()

    # ---- internals -----------------------------------------------------------------------------------------
    def _clamp_scalar(self, voltage_V: float) -> float:
        try:
            value = float(voltage_V)
        except (TypeError, ValueError):
            raise ConfigError(f"{self._name}: voltage_V={voltage_V!r} is not a number") from None
        if not math.isfinite(value):
            raise SafetyLimitError(f"{self._name}: voltage_V={voltage_V!r} is not finite; refused")
        return min(max(value, 0.0), self._max_V)

    def _max_step(self, interval_s: float) -> float:
        # the tiny shrink keeps rounding in prev + step from ever exceeding the bound
        return self._slew * min(interval_s, self._step_s) / self._gain * (1.0 - 1e-12)

    def _wait_since_held(self, interval_s: float) -> None:
        wait_s = self._held_since_s + interval_s - self._clock.now_s()
        if wait_s > 0:
            self._clock.sleep(wait_s)

    def _ramp_to(self, target_daq_V: float) -> None:
        self._stop_wave()
        while self._held_daq_V != target_daq_V:
            self._wait_since_held(self._step_s)
            interval_s = self._clock.now_s() - self._held_since_s
            step = self._max_step(interval_s)
            delta = min(max(target_daq_V - self._held_daq_V, -step), step)
            value = target_daq_V if abs(target_daq_V - self._held_daq_V) <= step else self._held_daq_V + delta
            self._daq.write_ao_scalar(self._ao, value)
            # time taken after the write returns: the next interval is measured conservatively
            self._held_daq_V = value
            self._held_since_s = self._clock.now_s()

    def _stop_wave(self) -> None:
        if self._wave is None:
            return
        t0, rate, daq = self._wave
        now = self._clock.now_s()
        if now >= t0 + len(daq) / rate:
            self._settle_wave()
            return
        # the backend knows which sample it stopped on; dating it "now" (not its true start) only makes
        # the next step smaller
        self._held_daq_V = float(self._daq.stop_ao(self._ao))
        self._held_since_s = self._clock.now_s()
        self._wave = None

    def _settle_wave(self) -> None:
        assert self._wave is not None
        t0, rate, daq = self._wave
        self._held_daq_V = float(daq[-1])
        self._held_since_s = t0 + (len(daq) - 1) / rate
        self._wave = None

    def _commanded_daq(self, times_s: np.ndarray) -> np.ndarray:
        out = np.full(times_s.shape, self._held_daq_V)
        if self._wave is not None:
            t0, rate, daq = self._wave
            k = np.clip(np.floor((times_s - t0) * rate).astype(int), 0, len(daq) - 1)
            out = np.where(times_s >= t0, daq[k], self._held_daq_V)
        return out


def describe_channels(amplifiers: Sequence[TrekAmplifier]) -> list[str]:
    """One line per amplifier for logs: gain, clamp and slew limit."""
    return [
        f"{a._name}: ao={a._ao} monitor={a._mon} gain={a.gain_V_per_V:g} V/V max={a.max_voltage_V:g} V "
        f"slew={a.slew_rate_V_per_s:g} V/s"
        for a in amplifiers
    ]
