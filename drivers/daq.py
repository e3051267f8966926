"""The DAQ backend surface the analog drivers need (TREK amplifier, ATI Nano17): a `typing.Protocol`, nothing
more.

A backend owns one data-acquisition device and speaks in DAQ volts on named channels (`"Dev1/ao0"`,
`"Dev1/ai3"`). The real backend is `drivers.daq_nidaqmx.NidaqmxDaq`; the simulated bench provides
`sim_devices.daq_sim.SimDaq` with the same surface (duck-typed, so `sim_devices` never imports `drivers`).
Backends raise the `hamr_bench.errors.DeviceError` family (`DeviceTimeout`, `DeviceFault`) with one-line
messages; they never clamp or slew-limit: protecting the hardware is the job of the driver above them.

Times are on the rig clock (the `Clock` the backend was built with), in seconds.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class AiBlock:
    """A block of analog-input samples: `data_V[c, k]` is channel `c` at time
    `start_time_s + k / sample_rate_Hz`."""

    start_time_s: float
    sample_rate_Hz: float
    data_V: np.ndarray

    @property
    def times_s(self) -> np.ndarray:
        return self.start_time_s + np.arange(self.data_V.shape[1]) / self.sample_rate_Hz


@runtime_checkable
class DaqBackend(Protocol):
    """What the analog drivers ask of a DAQ device."""

    def write_ao_scalar(self, channel: str, value_V: float) -> None:
        """Software-timed: set the analog output `channel` to `value_V` now (stops a waveform on it first)."""

    def write_ao_waveform(self, channel: str, samples_V: np.ndarray, sample_rate_Hz: float) -> float:
        """Hardware-timed finite output of `samples_V` at `sample_rate_Hz`, starting now; returns the time of
        the first sample on the rig clock. The output holds the last sample when the waveform ends. Does not
        block."""

    def wait_ao_done(self, channel: str, timeout_s: float) -> None:
        """Block (through the clock) until the waveform on `channel` has ended; DeviceTimeout after
        `timeout_s`."""

    def stop_ao(self, channel: str) -> float:
        """Stop any waveform on `channel` now; the output holds the sample being generated. Returns the held
        value in DAQ volts (the backend's best knowledge of it)."""

    def read_ai(
        self, channels: Sequence[str], n_samples: int, sample_rate_Hz: float, timeout_s: float = 10.0
    ) -> AiBlock:
        """Acquire `n_samples` per channel, hardware-timed, starting now; blocks until they are in.
        DeviceTimeout if they are not in within `timeout_s`."""

    def start_ai_stream(self, channels: Sequence[str], sample_rate_Hz: float) -> float:
        """Start continuous acquisition on `channels`; returns the time of the first sample."""

    def read_ai_stream(self) -> AiBlock:
        """Every sample acquired since the previous call (possibly none); does not block."""

    def stop_ai_stream(self) -> None: ...

    def close(self) -> None: ...
