"""The simulated DAQ and what hangs off it: HV amplifiers (TREK-style) on its analog outputs and an ATI
Nano17's six strain-gauge channels on its analog inputs.

`SimDaq` implements `hamr_bench.interfaces.DaqBackend`, so the real amplifier and Nano17 drivers run on it
unchanged. Everything is timed on the injected clock:

- Analog output is a zero-order hold of what was written: scalar writes and hardware-timed waveform samples at
  `t0 + k / rate` (the last sample holds). The amplifier output is `gain x AO` (clipped at its rail) through a
  first-order low-pass of the configured bandwidth, solved exactly for the piecewise-constant input, so
  `output_voltage_V(channel, time_s)` is computable at any time the bench asks (within `history_s`).
- The monitor AI channel reads `output / monitor_scale` plus noise.
- Gauge AI channels read `inv(C) @ wrench(t) + bias` plus noise, clipped at the DAQ range;
  `wrench_source(time_s)` is a callback returning (Fx, Fy, Fz in N, Tx, Ty, Tz in N m) and `C` the
  calibration matrix in SI. A callback with the attribute `vectorised = True` is called once per block with an
  array of times and returns shape (n, 6). A `force_z_source(times_s)` (Fz alone, the other components zero, as the
  bench's tip presses; the bench gives this one) is used instead when given: the same volts without the 6x6
  product.

Not modelled: amplifier slew-rate limit and current limit, output impedance and the PZT's capacitive load, DAQ
quantisation and range settings, AI/AO settling, buffer overflow of a stream read too rarely.

Faults (names shared with `sim_devices.faults`): 'amp_trip' (an amplifier's output collapses to 0 V and stays
there until the fault is cleared), 'disconnect' (every call raises DeviceFault), 'no_reply' (reads wait out
their timeout and raise DeviceTimeout; writes raise DeviceTimeout), 'overload' (the Nano17's gauges pin at the
input range). Each can be scheduled at a clock time (`at_s`). Noise comes from the `numpy.random.Generator`
given.
"""

from __future__ import annotations

import bisect
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import cast

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import AiBlock
from sim_devices.faults import AMPLIFIER_FAULTS, FORCE_SENSOR_FAULTS, FaultInjector

DAQ_FAULTS = AMPLIFIER_FAULTS + FORCE_SENSOR_FAULTS
_AXES = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
_TORQUE_TO_N_M = {"N-m": 1.0, "Nm": 1.0, "N-mm": 1e-3, "Nmm": 1e-3}


@dataclass(frozen=True)
class SimAmplifierSpec:
    """One HV amplifier channel between a DAQ analog output and the actuator. Defaults are placeholders
    (UNVERIFIED for the PZD350A): give the rig's values in the rig file."""

    ao_channel: str
    monitor_channel: str
    gain_V_per_V: float = 35.0
    bandwidth_Hz: float = 5_000.0
    monitor_scale_V_per_V: float = 100.0  # output volts per monitor volt
    rail_V: float = 350.0
    monitor_noise_V: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("gain_V_per_V", "bandwidth_Hz", "monitor_scale_V_per_V", "rail_V"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"SimAmplifierSpec.{name}: must be a positive finite number, got {value!r}")


@dataclass(frozen=True, eq=False)
class SimNano17Spec:
    """A six-gauge F/T sensor on six AI channels. `calibration_SI` maps gauge volts to
    (N, N, N, N m, N m, N m)."""

    gauge_channels: tuple[str, ...]
    calibration_SI: np.ndarray
    bias_V: tuple[float, ...] = (0.1, -0.2, 0.05, 0.15, -0.1, 0.02)
    noise_V: float = 1e-3
    range_V: float = 10.0

    def __post_init__(self) -> None:
        if len(self.gauge_channels) != 6 or np.shape(self.calibration_SI) != (6, 6) or len(self.bias_V) != 6:
            raise ConfigError("SimNano17Spec: needs 6 gauge channels, a 6x6 calibration and 6 bias voltages")


def load_calibration_SI(path: Path | str) -> np.ndarray:
    """The 6x6 `UserAxis` matrix of an ATI calibration XML file, with torque rows converted to N m per volt.
    (A small reader of its own so that the simulated sensor does not depend on the driver it is used to
    test.)"""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f"{path}: cannot read ATI calibration ({exc})") from None
    cal = root.find("Calibration")
    if cal is None:
        raise ConfigError(f"{path}: no <Calibration> element")
    torque_scale = _TORQUE_TO_N_M.get(cal.get("TorqueUnits", "N-m"))
    if torque_scale is None or cal.get("ForceUnits", "N") != "N":
        raise ConfigError(f"{path}: sim supports ForceUnits N and TorqueUnits N-m/N-mm only")
    rows = {
        ax.get("Name"): [float(v) for v in ax.get("values", "").split()] for ax in cal.findall("UserAxis")
    }
    matrix = np.array([rows[name] for name in _AXES], dtype=float)
    matrix[3:] *= torque_scale
    return matrix


def _first_order_response(target: np.ndarray, a: float, y0: float) -> np.ndarray:
    """z[n] = a z[n-1] + (1 - a) target[n], z[-1] = y0: the exact sampled response of a first-order lag to a
    staircase. (A plain loop: importing scipy.signal for this costs over a second at every start-up.)"""
    out = np.empty(len(target))
    z = y0
    b = 1.0 - a
    for n, x in enumerate(target.tolist()):
        z = a * z + b * x
        out[n] = z
    return out


@dataclass
class _Segment:
    """Output written at `t0_s`: samples `target_V` (amplifier output targets) every `dt_s` (inf for a
    scalar)."""

    t0_s: float
    dt_s: float
    daq_V: np.ndarray
    target_V: np.ndarray
    y_V: np.ndarray  # amplifier output at each sample's start time

    @property
    def end_s(self) -> float:
        return self.t0_s + len(self.daq_V) * self.dt_s if math.isfinite(self.dt_s) else math.inf


@dataclass
class _AoChannel:
    amp: SimAmplifierSpec | None
    tau_s: float
    segments: list[_Segment] = field(default_factory=list)
    starts_s: list[float] = field(default_factory=list)
    tripped_at_s: float | None = None



def _segment_output(seg: _Segment, t: np.ndarray, tau_s: float) -> np.ndarray:
    """Output at times `t` that all fall in segment `seg`: each sample's target, approached from the output at that
    sample's update time with the amplifier's time constant `tau_s` (held when `tau_s` is 0)."""
    if math.isfinite(seg.dt_s):
        k = ((t - seg.t0_s) / seg.dt_s).astype(int)
        np.minimum(np.maximum(k, 0, out=k), len(seg.target_V) - 1, out=k)
        tk = seg.t0_s + k * seg.dt_s
    else:
        k = np.zeros(t.shape, dtype=int)
        tk = np.full(t.shape, seg.t0_s)
    target = seg.target_V[k]
    if tau_s > 0:
        return target + (seg.y_V[k] - target) * np.exp(-(t - tk) / tau_s)
    return target

class SimDaq:
    """A simulated DAQ device with HV amplifiers and an optional Nano17 attached (surface: `DaqBackend`)."""

    def __init__(
        self,
        clock: Clock,
        rng: np.random.Generator,
        *,
        amplifiers: Sequence[SimAmplifierSpec] = (),
        nano17: SimNano17Spec | None = None,
        wrench_source: Callable[[float], Sequence[float]] | None = None,
        force_z_source: Callable[[np.ndarray], np.ndarray] | None = None,
        ai_channels: Sequence[str] = (),
        ao_channels: Sequence[str] = (),
        ai_noise_V: float = 1e-3,
        history_s: float = 60.0,
        max_ao_rate_Hz: float = 1e6,
        max_ai_rate_Hz: float = 1e6,
    ) -> None:
        self._clock = clock
        self._rng = rng
        # The Nano17's gauge noise has its own stream, drawn sample by sample in time order: a force stream read in
        # other blocks, or amplifier monitors read more or less often, must not change the force noise.
        self._gauge_rng = np.random.default_rng(rng.integers(2**63))
        self._history_s = history_s
        self._max_ao_rate_Hz = max_ao_rate_Hz
        self._max_ai_rate_Hz = max_ai_rate_Hz
        self._ai_noise_V = ai_noise_V
        self._ao: dict[str, _AoChannel] = {}
        self._monitors: dict[str, str] = {}
        for amp in amplifiers:
            self._ao[amp.ao_channel] = _AoChannel(amp, 1.0 / (2 * math.pi * amp.bandwidth_Hz))
            self._monitors[amp.monitor_channel] = amp.ao_channel
        for name in ao_channels:  # bare outputs (nothing attached): output = AO volts, no lag
            self._ao.setdefault(name, _AoChannel(None, 0.0))
        self._nano17 = nano17
        self._wrench_source = wrench_source
        # Optional: Fz at an array of times, for a wrench that is Fz alone (the bench's tip presses along z).
        self._force_z_source = force_z_source
        self._gauge_index: dict[str, int] = {}
        if nano17 is not None:
            if wrench_source is None and force_z_source is None:
                raise ConfigError("SimDaq: a Nano17 needs a wrench_source(time_s) or force_z_source(times_s) callback")
            self._gauge_index = {ch: i for i, ch in enumerate(nano17.gauge_channels)}
            self._inverse_cal = np.linalg.inv(np.asarray(nano17.calibration_SI, dtype=float))
            self._bias_column = np.asarray(nano17.bias_V, dtype=float)[:, None]
        self._plain_ai = set(ai_channels)
        self._faults = FaultInjector(DAQ_FAULTS, "sim DAQ", clock)
        self._stream: tuple[tuple[str, ...], float, float] | None = None  # channels, rate, next sample time
        self.ao_write_count = 0
        # Called with the time from which an amplifier's output changes (a write, a trip): the simulated bench
        # recomputes its physics from there.
        self.output_listeners: list[Callable[[float], None]] = []

    def _outputs_change(self, time_s: float) -> None:
        for listener in self.output_listeners:
            listener(time_s)

    # ---- fault injection -----------------------------------------------------------------------------------
    def inject_fault(self, name: str, channel: str | None = None, at_s: float | None = None) -> None:
        """Switch a fault on now (or at `at_s` on the clock). 'amp_trip' takes the amplifier's AO channel (all
        amplifiers if None)."""
        at = self._clock.now_s() if at_s is None else float(at_s)
        self._faults.inject(name, at)  # validates the name
        if name == "amp_trip":
            for ch_name, ch in self._ao.items():
                if ch.amp is not None and channel in (None, ch_name):
                    ch.tripped_at_s = at if ch.tripped_at_s is None else min(ch.tripped_at_s, at)
            self._outputs_change(at)

    def clear_fault(self, name: str) -> None:
        if name == "amp_trip":
            for ch in self._ao.values():
                ch.tripped_at_s = None
            self._outputs_change(self._clock.now_s())
        self._faults.clear(name)

    def _active(self, name: str) -> bool:
        return self._faults.is_active(name, self._clock.now_s())

    def _check_link(self, what: str) -> None:
        if self._active("disconnect"):
            raise DeviceFault(f"sim DAQ: device disconnected during {what}", device="daq")
        if self._active("no_reply"):
            raise DeviceTimeout(f"sim DAQ: no response to {what}", device="daq")

    # ---- analog output -------------------------------------------------------------------------------------
    def _channel(self, channel: str) -> _AoChannel:
        try:
            return self._ao[channel]
        except KeyError:
            known = ", ".join(self._ao)
            raise ConfigError(f"sim DAQ: no analog output {channel!r} (known: {known})") from None

    def _append(self, ch: _AoChannel, t0_s: float, dt_s: float, daq_V: np.ndarray) -> None:
        y0 = float(self._output(ch, np.array([t0_s]), apply_trip=False)[0])
        if ch.amp is not None:
            target = np.clip(daq_V * ch.amp.gain_V_per_V, -ch.amp.rail_V, ch.amp.rail_V)
        else:
            target = daq_V.copy()
        if ch.tau_s == 0.0 or len(target) == 1:
            y = np.concatenate([[y0], target[:-1]]) if ch.tau_s == 0.0 else np.array([y0])
        else:
            a = math.exp(-dt_s / ch.tau_s)
            y = np.concatenate([[y0], _first_order_response(target[:-1], a, y0)])
        # a new write replaces everything scheduled from t0 on
        cut = bisect.bisect_left(ch.starts_s, t0_s)
        del ch.segments[cut:], ch.starts_s[cut:]
        ch.segments.append(_Segment(t0_s, dt_s, daq_V, target, y))
        ch.starts_s.append(t0_s)
        self._outputs_change(t0_s)
        horizon = t0_s - self._history_s
        drop = bisect.bisect_left(ch.starts_s, horizon) - 1  # keep the segment in force at the horizon
        if drop > 0:
            del ch.segments[:drop], ch.starts_s[:drop]

    def write_ao_scalar(self, channel: str, value_V: float) -> None:
        self._check_link("an analog output write")
        ch = self._channel(channel)
        if not math.isfinite(value_V):
            raise ConfigError(f"sim DAQ: non-finite value {value_V!r} written to {channel}")
        self.ao_write_count += 1
        self._append(ch, self._clock.now_s(), math.inf, np.array([float(value_V)]))

    def write_ao_waveform(self, channel: str, samples_V: np.ndarray, sample_rate_Hz: float) -> float:
        self._check_link("a waveform write")
        ch = self._channel(channel)
        samples = np.asarray(samples_V, dtype=float).ravel()
        if samples.size == 0 or not np.all(np.isfinite(samples)):
            raise ConfigError(f"sim DAQ: waveform for {channel} is empty or not finite")
        if not (math.isfinite(sample_rate_Hz) and 0 < sample_rate_Hz <= self._max_ao_rate_Hz):
            raise ConfigError(
                f"sim DAQ: AO sample rate {sample_rate_Hz!r} Hz outside (0, {self._max_ao_rate_Hz}]"
            )
        self.ao_write_count += 1
        t0 = self._clock.now_s()
        self._append(ch, t0, 1.0 / sample_rate_Hz, samples)
        return t0

    def wait_ao_done(self, channel: str, timeout_s: float) -> None:
        self._check_link("a wait for waveform end")
        ch = self._channel(channel)
        now = self._clock.now_s()
        end = ch.segments[-1].end_s if ch.segments else now
        if not math.isfinite(end):  # a scalar write: nothing is running
            return
        if end - now > timeout_s:
            self._clock.sleep(timeout_s)
            message = f"sim DAQ: waveform on {channel} still running after {timeout_s:g} s"
            raise DeviceTimeout(message, device="daq")
        self._clock.sleep(end - now)

    def stop_ao(self, channel: str) -> float:
        self._check_link("an analog output stop")
        ch = self._channel(channel)
        now = self._clock.now_s()
        held = self.ao_value_V(channel, now)
        if ch.segments and ch.segments[-1].end_s > now:
            self._append(ch, now, math.inf, np.array([held]))
        return held

    # ---- what the bench and tests can see ------------------------------------------------------------------
    def ao_value_V(self, channel: str, time_s: float) -> float:
        """The DAQ output volts on `channel` at `time_s` (zero-order hold; 0 before the first write)."""
        ch = self._channel(channel)
        i = bisect.bisect_right(ch.starts_s, time_s) - 1
        if i < 0:
            return 0.0
        seg = ch.segments[i]
        k = 0 if not math.isfinite(seg.dt_s) else min(int((time_s - seg.t0_s) / seg.dt_s), len(seg.daq_V) - 1)
        return float(seg.daq_V[k])

    def _output_at(self, ch: _AoChannel, t: float, apply_trip: bool = True) -> float:
        """`_output` for one time, without array machinery (the bench asks this thousands of times a second)."""
        if apply_trip and ch.tripped_at_s is not None and t >= ch.tripped_at_s:
            return 0.0
        i = bisect.bisect_right(ch.starts_s, t) - 1
        if i < 0:
            return 0.0
        seg = ch.segments[i]
        if math.isfinite(seg.dt_s):
            k = min(max(int((t - seg.t0_s) / seg.dt_s), 0), len(seg.target_V) - 1)
            tk = seg.t0_s + k * seg.dt_s
        else:
            k, tk = 0, seg.t0_s
        target, yk = float(seg.target_V[k]), float(seg.y_V[k])
        if ch.tau_s > 0:
            return target + (yk - target) * math.exp(-(t - tk) / ch.tau_s)
        return target

    def _output(self, ch: _AoChannel, t: np.ndarray, apply_trip: bool = True,
                span: tuple[float, float] | None = None) -> np.ndarray:
        """Output at times `t`; `span` is (t.min(), t.max()) when the caller has it already."""
        if t.size == 1:
            return np.array([self._output_at(ch, float(t.flat[0]), apply_trip)])
        if t.size == 0:
            return np.zeros_like(t, dtype=float)
        first_s, last_s = span if span is not None else (float(t.min()), float(t.max()))
        if ch.segments and ch.tau_s > 0:
            lo = bisect.bisect_right(ch.starts_s, first_s) - 1
            if lo >= 0 and bisect.bisect_right(ch.starts_s, last_s) - 1 == lo:
                # every time in one segment (a monitor read): the loop below without its index bookkeeping
                out = _segment_output(ch.segments[lo], t, ch.tau_s)
                if apply_trip and ch.tripped_at_s is not None:
                    out[t >= ch.tripped_at_s] = 0.0
                return out
        out = np.zeros_like(t, dtype=float)
        if ch.segments:
            # Only the segments between the first and last time asked matter: converting the whole history (tens
            # of thousands of ramp steps) to an array on every monitor read dominated the bench's cost. (One time
            # alone took the scalar path above.)
            lo = max(bisect.bisect_right(ch.starts_s, first_s) - 1, 0)
            hi = bisect.bisect_right(ch.starts_s, last_s)
            idx = np.searchsorted(np.asarray(ch.starts_s[lo:hi]), t, side="right") - 1 + lo
            for i in np.unique(idx[idx >= 0]):
                sel = idx == i
                out[sel] = _segment_output(ch.segments[i], t[sel], ch.tau_s)
        if apply_trip and ch.tripped_at_s is not None:
            out[t >= ch.tripped_at_s] = 0.0
        return out

    def output_voltage_V(self, channel: str, time_s: float | np.ndarray) -> float | np.ndarray:
        """The amplifier's output (volts on the actuator) at `time_s` for the amplifier on AO `channel`."""
        ch = self._channel(channel)
        if type(time_s) is float:  # the bench's per-sample question: no array machinery (same value)
            if time_s < self._clock.now_s() - self._history_s:
                raise ConfigError(f"sim DAQ: output at t={time_s:g} s is older than history_s={self._history_s:g}")
            return self._output_at(ch, time_s)
        t = np.atleast_1d(np.asarray(time_s, dtype=float))
        span = (float(t.min()), float(t.max())) if t.size else None
        if span and span[0] < self._clock.now_s() - self._history_s:
            raise ConfigError(
                f"sim DAQ: output at t={span[0]:g} s is older than history_s={self._history_s:g}"
            )
        out = self._output(ch, t, span=span)
        return float(out[0]) if np.ndim(time_s) == 0 else out

    # ---- analog input --------------------------------------------------------------------------------------
    def _ai_values(self, channels: Sequence[str], times_s: np.ndarray) -> np.ndarray:
        data = np.empty((len(channels), times_s.size))
        gauges = None
        for c, name in enumerate(channels):
            if name in self._monitors:
                ch = self._ao[self._monitors[name]]
                assert ch.amp is not None
                noise = self._rng.normal(0.0, ch.amp.monitor_noise_V, times_s.size)
                data[c] = self._output(ch, times_s) / ch.amp.monitor_scale_V_per_V + noise
            elif name in self._gauge_index:
                if gauges is None:
                    gauges = self._gauge_volts(times_s)
                data[c] = gauges[self._gauge_index[name]]
            elif name in self._plain_ai:
                data[c] = self._rng.normal(0.0, self._ai_noise_V, times_s.size)
            else:
                known = [*self._monitors, *self._gauge_index, *self._plain_ai]
                raise ConfigError(f"sim DAQ: no analog input {name!r} (known: {', '.join(known)})")
        return data

    def _gauge_volts(self, times_s: np.ndarray) -> np.ndarray:
        spec = self._nano17
        assert spec is not None
        force_z = self._force_z_source
        if force_z is not None:
            # A source that presses along z only (the bench's tip): the calibration's z column times Fz is what
            # the full product gives when the other five components are zero, bit for bit, for a fifth of its cost.
            fz = np.asarray(force_z(times_s), dtype=float)
            volts = self._inverse_cal[:, 2:3] * fz + self._bias_column
        else:
            assert self._wrench_source is not None
            if getattr(self._wrench_source, "vectorised", False):  # one call for the whole block
                many = cast(Callable[[np.ndarray], np.ndarray], self._wrench_source)  # takes the array of times
                wrench = np.asarray(many(times_s), dtype=float).reshape(-1, 6)
            else:
                wrench = np.array([np.asarray(self._wrench_source(float(t)), dtype=float) for t in times_s])
                wrench = wrench.reshape(-1, 6)
            volts = self._inverse_cal @ wrench.T + self._bias_column
        volts += self._gauge_rng.normal(0.0, spec.noise_V, volts.shape[::-1]).T  # one row of 6 per sample
        if times_s.size and self._faults.is_active("overload", float(times_s[-1])):
            # the sensor is pushed far past its range: every gauge pins at the input limit
            overloaded = np.array([self._faults.is_active("overload", float(t)) for t in times_s], dtype=bool)
            volts[:, overloaded] = np.where(volts[:, overloaded] >= 0, spec.range_V, -spec.range_V)
        return np.minimum(np.maximum(volts, -spec.range_V, out=volts), spec.range_V, out=volts)

    def read_ai(
        self, channels: Sequence[str], n_samples: int, sample_rate_Hz: float, timeout_s: float = 10.0
    ) -> AiBlock:
        if self._active("no_reply") and not self._active("disconnect"):
            self._clock.sleep(timeout_s)  # a read that never completes waits out its timeout
        self._check_link("an analog input read")
        if not (math.isfinite(sample_rate_Hz) and 0 < sample_rate_Hz <= self._max_ai_rate_Hz):
            raise ConfigError(
                f"sim DAQ: AI sample rate {sample_rate_Hz!r} Hz outside (0, {self._max_ai_rate_Hz}]"
            )
        if n_samples < 1:
            raise ConfigError(f"sim DAQ: n_samples must be >= 1, got {n_samples}")
        duration_s = n_samples / sample_rate_Hz
        if duration_s > timeout_s:
            self._clock.sleep(timeout_s)
            raise DeviceTimeout(
                f"sim DAQ: {n_samples} samples at {sample_rate_Hz:g} Hz exceed timeout {timeout_s:g} s",
                device="daq",
            )
        t0 = self._clock.now_s()
        times = t0 + np.arange(n_samples) / sample_rate_Hz
        data = self._ai_values(tuple(channels), times)
        self._clock.sleep(duration_s)
        return AiBlock(t0, float(sample_rate_Hz), data)

    def start_ai_stream(self, channels: Sequence[str], sample_rate_Hz: float) -> float:
        self._check_link("an analog input stream start")
        self._ai_values(tuple(channels), np.empty(0))  # validates the channel names
        if not (math.isfinite(sample_rate_Hz) and 0 < sample_rate_Hz <= self._max_ai_rate_Hz):
            raise ConfigError(
                f"sim DAQ: AI sample rate {sample_rate_Hz!r} Hz outside (0, {self._max_ai_rate_Hz}]"
            )
        t0 = self._clock.now_s()
        self._stream = (tuple(channels), float(sample_rate_Hz), t0)
        return t0

    def read_ai_stream(self) -> AiBlock:
        self._check_link("an analog input stream read")
        if self._stream is None:
            raise ConfigError("sim DAQ: read_ai_stream() without start_ai_stream()")
        channels, rate, t_next = self._stream
        now = self._clock.now_s()
        n = int(math.floor((now - t_next) * rate + 1e-9)) + 1 if now >= t_next else 0
        times = t_next + np.arange(n) / rate
        self._stream = (channels, rate, t_next + n / rate)
        return AiBlock(t_next, rate, self._ai_values(channels, times))

    def stop_ai_stream(self) -> None:
        self._stream = None

    def close(self) -> None:
        self._stream = None

