"""The real DAQ backend: National Instruments DAQmx through the `nidaqmx` package (optional extra
`pip install hamr-bench[nidaq]`; needs NI-DAQmx installed). Implements the `hamr_bench.interfaces.DaqBackend` surface.

Importing this module never needs `nidaqmx`; constructing `NidaqmxDaq` without it raises ConfigError naming
the extra. One DAQmx task per analog output channel (on-demand for scalars, finite sample-clocked for
waveforms, which then hold their last sample), a finite task per AI read, and a continuous task for an AI
stream. DAQmx errors become DeviceTimeout (time-outs) or DeviceFault (everything else), one line each.

Times: the start of a waveform or an acquisition is read from the rig clock right after `start()` returns;
DAQmx does not report when its sample clock started, so the stamp can be late by the driver's start latency
(on the order of a millisecond). Limitations: boards with one AO timing engine (e.g. PCI-6052E) cannot run
waveforms on two AO channels in two tasks at once; DAQmx then reports a resource error (DeviceFault).
"""

from __future__ import annotations

import importlib
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import AiBlock

# DAQmx error codes that mean "it did not happen in time"
_TIMEOUT_CODES = {-200284, -200560, -200474, -200278}


def _import_nidaqmx() -> Any:
    try:
        return importlib.import_module("nidaqmx")
    except ImportError:
        raise ConfigError(
            "the NI DAQ backend needs the nidaqmx package: pip install hamr-bench[nidaq] "
            "(and NI-DAQmx itself)"
        ) from None


class NidaqmxDaq:
    """A DAQmx device seen through `DaqBackend`. Channel names are DAQmx physical channels (`Dev1/ao0`) or
    names on `device` (`ao0`), so a rig file can use the same short names as the simulated bench."""

    def __init__(
        self,
        device: str = "Dev1",
        clock: Clock | None = None,
        *,
        ao_range_V: tuple[float, float] = (-10.0, 10.0),
        ai_range_V: tuple[float, float] = (-10.0, 10.0),
        ai_terminal: str = "DIFF",
        stream_buffer_s: float = 10.0,
    ) -> None:
        self._nidaqmx = _import_nidaqmx()
        if clock is None:
            # a private RealClock would have its own epoch, and the drivers compare DAQ times with the rig's
            raise ConfigError("NidaqmxDaq: pass the rig's clock (clock=...) so DAQ time stamps share its time base")
        self._device = device
        self._constants = importlib.import_module("nidaqmx.constants")
        self._errors = importlib.import_module("nidaqmx.errors")
        self._clock = clock
        self._ao_range = ao_range_V
        self._ai_range = ai_range_V
        terminal_enum = self._constants.TerminalConfiguration
        try:
            self._terminal = getattr(terminal_enum, ai_terminal)
        except AttributeError:
            names = [n for n in dir(terminal_enum) if not n.startswith("_")]
            raise ConfigError(f"NidaqmxDaq: ai_terminal={ai_terminal!r} not one of {names}") from None
        self._stream_buffer_s = stream_buffer_s
        self._ao_tasks: dict[str, Any] = {}
        self._ao_timed: dict[str, tuple[float, float, np.ndarray]] = {}  # start, rate, samples
        # task, rate, time of the next sample to read, number of channels
        self._stream: tuple[Any, float, float, int] | None = None

    def _phys(self, channel: str) -> str:
        return channel if "/" in channel else f"{self._device}/{channel}"

    # ---- errors --------------------------------------------------------------------------------------------
    def _call(self, what: str, fn, *args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except self._errors.DaqError as exc:
            code = getattr(exc, "error_code", 0)
            first_line = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            cls = DeviceTimeout if code in _TIMEOUT_CODES else DeviceFault
            raise cls(f"NI DAQ: {what} failed (DAQmx error {code}: {first_line})", device="daq") from None

    # ---- analog output -------------------------------------------------------------------------------------
    def _new_ao_task(self, channel: str):
        self._close_ao(channel)
        task = self._call(f"creating an AO task on {channel}", self._nidaqmx.Task)
        self._call(f"adding {channel}", task.ao_channels.add_ao_voltage_chan, self._phys(channel),
                   min_val=self._ao_range[0], max_val=self._ao_range[1])
        self._ao_tasks[channel] = task
        return task

    def _close_ao(self, channel: str) -> None:
        task = self._ao_tasks.pop(channel, None)
        self._ao_timed.pop(channel, None)
        if task is not None:
            self._call(f"stopping AO on {channel}", task.close)

    def write_ao_scalar(self, channel: str, value_V: float) -> None:
        if not math.isfinite(value_V):
            raise ConfigError(f"NI DAQ: non-finite value {value_V!r} for {channel}")
        task = self._ao_tasks.get(channel)
        if task is None or channel in self._ao_timed:
            task = self._new_ao_task(channel)
        self._call(f"writing {channel}", task.write, float(value_V), auto_start=True)

    def write_ao_waveform(self, channel: str, samples_V: np.ndarray, sample_rate_Hz: float) -> float:
        samples = np.ascontiguousarray(samples_V, dtype=np.float64)
        task = self._new_ao_task(channel)
        finite = self._constants.AcquisitionType.FINITE
        self._call(f"timing {channel}", task.timing.cfg_samp_clk_timing, float(sample_rate_Hz),
                   sample_mode=finite, samps_per_chan=int(samples.size))
        self._call(f"loading the waveform on {channel}", task.write, samples, auto_start=False)
        self._call(f"starting {channel}", task.start)
        t0 = self._clock.now_s()
        self._ao_timed[channel] = (t0, float(sample_rate_Hz), samples)
        return t0

    def wait_ao_done(self, channel: str, timeout_s: float) -> None:
        task = self._ao_tasks.get(channel)
        if task is not None and channel in self._ao_timed:
            self._call(f"waiting for {channel}", task.wait_until_done, timeout=float(timeout_s))

    def stop_ao(self, channel: str) -> float:
        timed = self._ao_timed.get(channel)
        held = 0.0
        if timed is not None:
            t0, rate, samples = timed
            k = min(max(int((self._clock.now_s() - t0) * rate), 0), samples.size - 1)
            held = float(samples[k])
            task = self._ao_tasks[channel]
            self._call(f"stopping {channel}", task.stop)
        self._close_ao(channel)
        return held

    # ---- analog input --------------------------------------------------------------------------------------
    def _new_ai_task(self, channels: Sequence[str]):
        task = self._call("creating an AI task", self._nidaqmx.Task)
        for ch in channels:
            self._call(f"adding {ch}", task.ai_channels.add_ai_voltage_chan, self._phys(ch),
                       terminal_config=self._terminal, min_val=self._ai_range[0], max_val=self._ai_range[1])
        return task

    def read_ai(self, channels: Sequence[str], n_samples: int, sample_rate_Hz: float,
                timeout_s: float = 10.0) -> AiBlock:
        task = self._new_ai_task(channels)
        try:
            finite = self._constants.AcquisitionType.FINITE
            self._call("AI timing", task.timing.cfg_samp_clk_timing, float(sample_rate_Hz),
                       sample_mode=finite, samps_per_chan=int(n_samples))
            self._call("starting AI", task.start)
            t0 = self._clock.now_s()
            data = self._call("reading AI", task.read, number_of_samples_per_channel=int(n_samples),
                              timeout=float(timeout_s))
        finally:
            task.close()
        return AiBlock(t0, float(sample_rate_Hz), np.asarray(data, dtype=float).reshape(len(channels), -1))

    def start_ai_stream(self, channels: Sequence[str], sample_rate_Hz: float) -> float:
        self.stop_ai_stream()
        task = self._new_ai_task(channels)
        continuous = self._constants.AcquisitionType.CONTINUOUS
        buffer = int(sample_rate_Hz * self._stream_buffer_s)
        self._call("AI stream timing", task.timing.cfg_samp_clk_timing, float(sample_rate_Hz),
                   sample_mode=continuous, samps_per_chan=buffer)
        self._call("starting the AI stream", task.start)
        t0 = self._clock.now_s()
        self._stream = (task, float(sample_rate_Hz), t0, len(channels))
        return t0

    def read_ai_stream(self) -> AiBlock:
        if self._stream is None:
            raise ConfigError("NI DAQ: read_ai_stream() without start_ai_stream()")
        task, rate, t_next, n_ch = self._stream
        data = self._call("reading the AI stream", task.read,
                          number_of_samples_per_channel=self._constants.READ_ALL_AVAILABLE, timeout=0.0)
        block = np.asarray(data, dtype=float).reshape(n_ch, -1)
        self._stream = (task, rate, t_next + block.shape[1] / rate, n_ch)
        return AiBlock(t_next, rate, block)

    def stop_ai_stream(self) -> None:
        if self._stream is not None:
            task = self._stream[0]
            self._stream = None
            self._call("stopping the AI stream", task.close)

    def close(self) -> None:
        self.stop_ai_stream()
        for channel in list(self._ao_tasks):
            self._close_ao(channel)


# the name the rig builder asks for
NidaqmxBackend = NidaqmxDaq
