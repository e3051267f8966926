"""The typed surfaces of the four bench devices: what protocols and the runner may ask of a stage, a force sensor,
an amplifier channel and a camera, whatever the backend (real driver or driver-on-emulator).

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
        """The next frame, blocking until it is exposed."""

    def close(self) -> None: ...
