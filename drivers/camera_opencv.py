"""Camera driver on OpenCV's `VideoCapture` surface; implements `hamr_bench.interfaces.Camera`.

Takes a device index or path (opened with `cv2.VideoCapture`), or any object with VideoCapture's surface
(`read`, `set`, `get`, `release`, `isOpened`), such as the simulated camera or a recorded video file. Owns:
- settings that are read back after `set()` (OpenCV silently ignores values a backend does not accept): a
  value that does not stick is a ConfigError naming the property, the value asked and the value read;
- ROI as a software crop (OpenCV has no portable hardware ROI);
- frame time stamps: the device's `CAP_PROP_POS_MSEC` (exposure mid-time), either on the rig clock already
  (`device_time_is_rig_time`, the simulated bench) or aligned to it once at the first frame; the rig clock at
  arrival minus half the exposure when the device gives none;
- frame indices from `CAP_PROP_POS_FRAMES` (the next frame's index) when the device counts, so a dropped frame
  shows as a gap; a gap wider than `max_gap_frames` raises DeviceFault. `dropped_frames` counts every frame
  missed.
"""

from __future__ import annotations

import math
from typing import Any, Protocol

import cv2
import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import Frame


class CaptureLike(Protocol):
    def read(self) -> tuple[bool, Any]: ...
    def set(self, prop: int, value: float) -> bool: ...
    def get(self, prop: int) -> float: ...
    def release(self) -> None: ...
    def isOpened(self) -> bool: ...  # noqa: N802


class OpenCvCamera:
    """A grey-scale camera through OpenCV (see the module docstring)."""

    def __init__(
        self,
        source: int | str | CaptureLike,
        clock: Clock,
        *,
        width_px: int | None = None,
        height_px: int | None = None,
        frame_rate_Hz: float | None = None,
        exposure_s: float | None = None,
        roi: tuple[int, int, int, int] | None = None,
        exposure_unit_s: float = 1e-4,
        manual_exposure_value: float | None = 1.0,
        device_time_is_rig_time: bool = False,
        max_gap_frames: int = 3,
        timeout_s: float = 1.0,
        readback_tolerance: float = 0.02,
        api_preference: int = cv2.CAP_ANY,
        name: str = "camera",
    ) -> None:
        self._name = name
        self._clock = clock
        cap: CaptureLike
        if isinstance(source, (int, str)):
            cap = cv2.VideoCapture(source, api_preference)
            if not cap.isOpened():
                raise DeviceFault(f"{name}: cannot open camera {source!r} with OpenCV", device=name)
        else:
            cap = source
            if not cap.isOpened():
                raise DeviceFault(f"{name}: the capture object given is not open", device=name)
        self._cap = cap
        self._unit_s = float(exposure_unit_s)
        self._tol = float(readback_tolerance)
        self._device_time_is_rig_time = device_time_is_rig_time
        self._max_gap = int(max_gap_frames)
        self._timeout_s = float(timeout_s)
        self._time_offset_s: float | None = 0.0 if device_time_is_rig_time else None
        self._last_index = -1
        self._own_counter = -1
        self.dropped_frames = 0
        # best effort: backends without a read timeout ignore it (then their own timeout applies)
        cap.set(cv2.CAP_PROP_READ_TIMEOUT_MSEC, self._timeout_s * 1e3)
        if width_px is not None:
            self._set_checked(cv2.CAP_PROP_FRAME_WIDTH, float(width_px), "width_px")
        if height_px is not None:
            self._set_checked(cv2.CAP_PROP_FRAME_HEIGHT, float(height_px), "height_px")
        if frame_rate_Hz is not None:
            self._set_checked(cv2.CAP_PROP_FPS, float(frame_rate_Hz), "frame_rate_Hz")
        if exposure_s is not None:
            if manual_exposure_value is not None:
                cap.set(cv2.CAP_PROP_AUTO_EXPOSURE, manual_exposure_value)
            self.set_exposure(exposure_s)
        self._roi: tuple[int, int, int, int] | None = None
        if roi is not None:
            self.set_roi(*roi)

    # ---- Camera surface ------------------------------------------------------------------------------------
    @property
    def frame_rate_Hz(self) -> float:
        return float(self._cap.get(cv2.CAP_PROP_FPS))

    @property
    def exposure_s(self) -> float:
        return float(self._cap.get(cv2.CAP_PROP_EXPOSURE)) * self._unit_s

    @property
    def frame_size_px(self) -> tuple[int, int]:
        """(width, height) of the full frame delivered by the device."""
        return int(self._cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self._cap.get(cv2.CAP_PROP_FRAME_HEIGHT))

    @property
    def roi(self) -> tuple[int, int, int, int] | None:
        """(x, y, width, height) of the crop, or None; a tracker adds (x, y) to get full-frame pixels."""
        return self._roi

    def set_exposure(self, exposure_s: float) -> None:
        if not (isinstance(exposure_s, (int, float)) and math.isfinite(exposure_s) and exposure_s > 0):
            raise ConfigError(f"{self._name}: exposure_s={exposure_s!r} must be positive")
        self._set_checked(cv2.CAP_PROP_EXPOSURE, exposure_s / self._unit_s, "exposure_s", scale=self._unit_s)

    def set_roi(self, x: int, y: int, width: int, height: int) -> None:
        full_w, full_h = self.frame_size_px
        fits = x >= 0 and y >= 0 and width > 0 and height > 0 and x + width <= full_w and y + height <= full_h
        if not fits:
            raise ConfigError(
                f"{self._name}: roi=({x}, {y}, {width}, {height}) does not fit the {full_w}x{full_h} frame"
            )
        self._roi = (int(x), int(y), int(width), int(height))

    def skip_to_live(self) -> None:
        """Frames exposed while nobody grabbed are not drops: the next grab starts the gap count afresh."""
        self._last_index = -1

    def grab(self) -> Frame:
        t_call = self._clock.now_s()
        ok, image = self._cap.read()
        if not ok or image is None:
            if not self._cap.isOpened():
                raise DeviceFault(f"{self._name}: camera disconnected (read failed, device closed)",
                                  device=self._name)
            waited = self._clock.now_s() - t_call
            raise DeviceTimeout(
                f"{self._name}: no frame after {waited:.3g} s (timeout {self._timeout_s:g} s)",
                device=self._name,
            )
        arrival_s = self._clock.now_s()
        if image.ndim == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        if self._roi is not None:
            x, y, w, h = self._roi
            image = image[y:y + h, x:x + w]
        index = self._frame_index()
        time_s = self._frame_time(arrival_s)
        return Frame(image=np.ascontiguousarray(image), time_s=time_s, index=index)

    def close(self) -> None:
        self._cap.release()

    # ---- internals -----------------------------------------------------------------------------------------
    def _set_checked(self, prop: int, value: float, label: str, scale: float = 1.0) -> None:
        self._cap.set(prop, value)
        got = float(self._cap.get(prop))
        if not abs(got - value) <= self._tol * max(abs(value), 1e-12):
            raise ConfigError(
                f"{self._name}: {label} set to {value * scale:g} but the camera reads back {got * scale:g}"
            )

    def _frame_index(self) -> int:
        self._own_counter += 1
        next_pos = float(self._cap.get(cv2.CAP_PROP_POS_FRAMES))
        index = int(round(next_pos)) - 1 if next_pos >= 1 else self._own_counter
        gap = index - self._last_index - 1
        if self._last_index >= 0 and gap > 0:
            self.dropped_frames += gap
            if gap > self._max_gap:
                self._last_index = index
                message = f"{self._name}: {gap} frames dropped before frame {index}"
                raise DeviceFault(message, device=self._name)
        self._last_index = index
        return index

    def _frame_time(self, arrival_s: float) -> float:
        device_ms = float(self._cap.get(cv2.CAP_PROP_POS_MSEC))
        if device_ms <= 0:
            return arrival_s - self.exposure_s / 2
        if self._time_offset_s is None:  # align the device's time base to the rig clock once
            self._time_offset_s = arrival_s - self.exposure_s / 2 - device_ms / 1e3
        return device_ms / 1e3 + self._time_offset_s
