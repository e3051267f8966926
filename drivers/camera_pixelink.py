"""Camera driver for PixeLINK cameras (the paper's PL-B741F) through the vendor's `pixelinkWrapper` package
(optional extra `pip install hamr-bench[pixelink]`; needs the PixeLINK SDK). Implements
`hamr_bench.interfaces.Camera`.

Importing this module never needs the package; constructing `PixelinkCamera` without it raises ConfigError
naming the extra. Every SDK call returns a tuple whose first item is a return code checked with
`PxLApi.apiSuccess`; a failure becomes DeviceTimeout (the SDK's time-out codes) or DeviceFault, one line.
Settings are read back after being set. ROI is the camera's hardware ROI (FeatureId.ROI: left, top, width,
height), so smaller ROIs run faster.

UNVERIFIED against a real camera here: the unit of FeatureId.EXPOSURE (`exposure_unit_s`, default 1 ms), the
frame descriptor's field names (`fFrameTime` in s since stream start, `uFrameNumber`), and MONO16 byte order
(`mono16_big _endian`). Frame time stamps are aligned to the rig clock once, at the first frame.
"""

from __future__ import annotations

import ctypes
import importlib
import math
from typing import Any

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import Frame


def _import_pxlapi() -> Any:
    try:
        return importlib.import_module("pixelinkWrapper").PxLApi
    except ImportError:
        raise ConfigError(
            "the PixeLINK camera backend needs pixelinkWrapper: pip install hamr-bench[pixelink] (and the "
            "PixeLINK SDK)"
        ) from None


class PixelinkCamera:
    """One PixeLINK camera by serial number (0 = the first found)."""

    def __init__(
        self,
        clock: Clock,
        *,
        serial_number: int = 0,
        exposure_s: float | None = None,
        frame_rate_Hz: float | None = None,
        roi: tuple[int, int, int, int] | None = None,
        mono16: bool = False,
        mono16_big_endian: bool = True,
        exposure_unit_s: float = 1e-3,
        max_gap_frames: int = 3,
        readback_tolerance: float = 0.02,
        name: str = "camera",
    ) -> None:
        self._api = _import_pxlapi()
        self._clock = clock
        self._name = name
        self._unit_s = exposure_unit_s
        self._tol = readback_tolerance
        self._max_gap = max_gap_frames
        self._big_endian = mono16_big_endian
        self._streaming = False
        self._time_offset_s: float | None = None
        self._last_index = -1
        self.dropped_frames = 0
        self._handle = self._check("initialize", self._api.initialize(serial_number))[1]
        fmt = self._api.PixelFormat.MONO16 if mono16 else self._api.PixelFormat.MONO8
        self._set("PIXEL_FORMAT", [fmt])
        self._dtype = np.uint16 if mono16 else np.uint8
        if roi is not None:
            self.set_roi(*roi)
        if frame_rate_Hz is not None:
            self._set("FRAME_RATE", [float(frame_rate_Hz)], checked=True)
        if exposure_s is not None:
            self.set_exposure(exposure_s)

    # ---- SDK plumbing --------------------------------------------------------------------------------------
    def _check(self, what: str, ret: tuple) -> tuple:
        rc = ret[0]
        if self._api.apiSuccess(rc):
            return ret
        codes = self._api.ReturnCode
        timeouts = {getattr(codes, n, None) for n in ("ApiCameraTimeoutError", "ApiStreamStopped")} - {None}
        cls = DeviceTimeout if rc in timeouts else DeviceFault
        raise cls(f"{self._name}: PixeLINK {what} failed (return code {rc})", device=self._name)

    def _get(self, feature: str) -> list[float]:
        ret = self._api.getFeature(self._handle, getattr(self._api.FeatureId, feature))
        return list(self._check(f"get {feature}", ret)[2])

    def _set(self, feature: str, params: list[float], checked: bool = False) -> None:
        fid = getattr(self._api.FeatureId, feature)
        self._check(f"set {feature}", self._api.setFeature(self._handle, fid, self._api.FeatureFlags.MANUAL,
                                                           params))
        if checked:
            got = self._get(feature)
            if any(abs(g - p) > self._tol * max(abs(p), 1e-12) for g, p in zip(got, params)):
                raise ConfigError(f"{self._name}: {feature} set to {params} but the camera reads back {got}")

    # ---- Camera surface ------------------------------------------------------------------------------------
    @property
    def frame_rate_Hz(self) -> float:
        return float(self._get("FRAME_RATE")[0])

    @property
    def exposure_s(self) -> float:
        return float(self._get("EXPOSURE")[0]) * self._unit_s

    def set_exposure(self, exposure_s: float) -> None:
        if not (math.isfinite(exposure_s) and exposure_s > 0):
            raise ConfigError(f"{self._name}: exposure_s={exposure_s!r} must be positive")
        self._set("EXPOSURE", [exposure_s / self._unit_s], checked=True)

    def set_roi(self, x: int, y: int, width: int, height: int) -> None:
        was_streaming = self._streaming
        if was_streaming:  # the SDK wants the stream stopped to change the ROI
            self._stream(False)
        self._set("ROI", [float(x), float(y), float(width), float(height)], checked=True)
        if was_streaming:
            self._stream(True)

    def skip_to_live(self) -> None:
        """Frames exposed while nobody grabbed are not drops: the next grab starts the gap count afresh."""
        self._last_index = -1

    def grab(self) -> Frame:
        if not self._streaming:
            self._stream(True)
        left, top, width, height = (int(v) for v in self._get("ROI")[:4])
        itemsize = np.dtype(self._dtype).itemsize
        buffer = ctypes.create_string_buffer(width * height * itemsize)
        desc = self._check("getNextFrame", self._api.getNextFrame(self._handle, buffer))[1]
        arrival_s = self._clock.now_s()
        dtype = np.dtype(self._dtype).newbyteorder(">" if self._big_endian and itemsize == 2 else "=")
        image = np.frombuffer(buffer.raw, dtype=dtype, count=width * height).reshape(height, width)
        image = image.astype(self._dtype)
        device_s = float(getattr(desc, "fFrameTime", math.nan))
        number = getattr(desc, "uFrameNumber", None)
        index = int(number) if number is not None else self._last_index + 1
        gap = index - self._last_index - 1
        if self._last_index >= 0 and gap > 0:
            self.dropped_frames += gap
            if gap > self._max_gap:
                self._last_index = index
                message = f"{self._name}: {gap} frames dropped before frame {index}"
                raise DeviceFault(message, device=self._name)
        self._last_index = index
        half_exposure = self.exposure_s / 2
        if math.isfinite(device_s):
            if self._time_offset_s is None:
                self._time_offset_s = arrival_s - half_exposure - device_s
            time_s = device_s + self._time_offset_s
        else:
            time_s = arrival_s - half_exposure
        return Frame(image=image, time_s=time_s, index=index)

    def close(self) -> None:
        if self._streaming:
            self._stream(False)
        self._check("uninitialize", self._api.uninitialize(self._handle))

    def _stream(self, on: bool) -> None:
        state = self._api.StreamState.START if on else self._api.StreamState.STOP
        self._check("setStreamState", self._api.setStreamState(self._handle, state))
        self._streaming = on
