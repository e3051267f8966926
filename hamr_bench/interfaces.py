"""The typed surfaces of the four bench devices: what protocols and the runner may ask of a stage, a force sensor,
an amplifier channel and a camera, whatever the backend (real driver or driver-on-emulator); and the DAQ backend
surface the analog drivers stand on (`DaqBackend`, `AiBlock`), which a real DAQ and the simulated one both provide.

Units are SI everywhere (m, N, V, s). Every device takes a `Clock` at construction and does all its waiting through
it. Errors are the `DeviceError` family from `hamr_bench.errors`. Safety limits that protect hardware (voltage clamp,
slew limit, stage soft limits) are enforced inside the implementations, so no caller can bypass them; the runner
adds the limits that need several devices at once (force limit while the stage moves).

Sign conventions shared by the bench and the analysis:
- Stage position `position_m` is the controller's coordinate; in the rig file `sag_axis_sign` says whether raising
  the force sensor toward the leg is + or -.
- Force `force_N` is positive when the leg (or actuator tip) presses on the sensor.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import numpy as np


@dataclass(frozen=True)
class ForceSample:
    time_s: float
    force_N: float


@dataclass(frozen=True)
class Frame:
    """One camera frame: `image` is a 2-D array (uint8 or uint16, grey), `time_s` the exposure mid-time on the
    device's clock, `index` a frame counter (a gap in it is a dropped frame)."""

    image: np.ndarray
    time_s: float
    index: int


@runtime_checkable
class Stage(Protocol):
    """A single-axis motorised stage with soft limits."""

    @property
    def limits_m(self) -> tuple[float, float]: ...

    def home(self) -> None:
        """Reference the stage; blocks until READY."""

    def move_to(self, position_m: float) -> None:
        """Absolute move; blocks until READY. Raises SafetyLimitError outside `limits_m`."""

    def position_m(self) -> float: ...

    def is_moving(self) -> bool: ...

    def stop(self) -> None:
        """Stop any motion now (safe state)."""

    def close(self) -> None: ...


@runtime_checkable
class ForceSensor(Protocol):
    """A single-axis force reading (a 6-axis sensor exposes its Fz through this surface)."""

    @property
    def capacity_N(self) -> float: ...

    def tare(self) -> None: ...

    def read_N(self) -> float:
        """One reading, blocking."""

    def start_stream(self) -> None: ...

    def read_stream(self) -> list[ForceSample]:
        """Every sample that arrived since the last call (may be empty). Times are on the rig clock."""

    def stop_stream(self) -> None:
        """Stop streaming and drain; leaves the sensor ready for single readings."""

    def close(self) -> None: ...


@runtime_checkable
class Amplifier(Protocol):
    """One high-voltage output channel (the rig has two: `bias` and `drive`).

    `set_voltage` and `play_waveform` clamp to [0, max_voltage_V] and limit the slew rate inside the driver; a
    caller cannot get past either.
    """

    @property
    def max_voltage_V(self) -> float: ...

    @property
    def slew_rate_V_per_s(self) -> float: ...

    def set_voltage(self, voltage_V: float) -> None:
        """Ramp to `voltage_V` at no more than the slew limit; blocks until there."""

    def play_waveform(self, voltage_V: np.ndarray, sample_rate_Hz: float) -> float:
        """Start hardware-timed output of `voltage_V` samples now; returns the start time on the rig clock.
        Does not block; `wait_done` does."""

    def wait_done(self) -> None: ...

    def commanded_voltage_V(self) -> float:
        """The voltage the output is commanded to at the clock's present time (after clamp and slew limit)."""

    def monitor_voltage_V(self) -> float:
        """The amplifier's monitor output, scaled to output volts."""

    def zero(self) -> None:
        """Bring the output to 0 V (safe state) at the slew limit, stopping any waveform."""

    def close(self) -> None: ...


@runtime_checkable
class Camera(Protocol):
    """A grey-scale camera with ROI and exposure."""

    @property
    def frame_rate_Hz(self) -> float: ...

    @property
    def exposure_s(self) -> float: ...

    def set_exposure(self, exposure_s: float) -> None: ...

    def set_roi(self, x: int, y: int, width: int, height: int) -> None: ...

    def grab(self) -> Frame:
        """The next frame, blocking until it is exposed. Frames the caller missed between two grabs are drops
        (a gap wider than the driver allows is a DeviceFault)."""

    def skip_to_live(self) -> None:
        """The caller was away on purpose (between two tracked drives): the frames exposed since the last grab
        are not drops, and gap counting starts again at the next grab."""

    def close(self) -> None: ...


# ----------------------------------------------------------------- the DAQ backend under the analog drivers
# A backend owns one data-acquisition device and speaks in DAQ volts on named channels (`"Dev1/ao0"`,
# `"Dev1/ai3"`). The real one is `drivers.daq_nidaqmx.NidaqmxBackend`, the simulated bench's
# `sim_devices.daq_sim.SimDaq`; the analog drivers (TREK amplifier, ATI Nano17) run on either. Backends raise the
# `DeviceError` family with one-line messages; they never clamp or slew-limit: protecting the hardware is the job
# of the driver above them. Times are on the rig clock (the `Clock` the backend was built with), in seconds.


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
