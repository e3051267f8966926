"""PixeLINK camera driver: import guard, and its SDK calls against a stand-in `pixelinkWrapper` (the real one
needs the vendor SDK and a camera)."""

from __future__ import annotations

import importlib
import sys
import types
from types import SimpleNamespace

import pytest

from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import Camera


def test_import_guard(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "pixelinkWrapper", None)
    module = importlib.import_module("drivers.camera_pixelink")
    with pytest.raises(ConfigError, match=r"pip install hamr-bench\[pixelink\]"):
        module.PixelinkCamera(VirtualClock())


def fake_api(clock: VirtualClock, frames: list[int], fail: dict):
    features = {"PIXEL_FORMAT": [0.0], "ROI": [0.0, 0.0, 8.0, 4.0], "FRAME_RATE": [30.0], "EXPOSURE": [5.0]}

    class PxLApi:
        FeatureId = SimpleNamespace(**{k: k for k in features})
        FeatureFlags = SimpleNamespace(MANUAL=1)
        PixelFormat = SimpleNamespace(MONO8=0, MONO16=1)
        StreamState = SimpleNamespace(START=0, STOP=1)
        ReturnCode = SimpleNamespace(ApiCameraTimeoutError=-2, ApiStreamStopped=-3)

        @staticmethod
        def apiSuccess(rc):  # noqa: N802
            return rc >= 0

        @staticmethod
        def initialize(serial):
            return (0, 77)

        @staticmethod
        def getFeature(h, fid):  # noqa: N802
            return (0, 1, features[fid])

        @staticmethod
        def setFeature(h, fid, flags, params):  # noqa: N802
            if fid == "FRAME_RATE":
                params = [min(params[0], 60.0)]  # the camera caps it
            features[fid] = list(params)
            return (0,)

        @staticmethod
        def setStreamState(h, state):  # noqa: N802
            return (0,)

        @staticmethod
        def getNextFrame(h, buffer):  # noqa: N802
            if "next" in fail:
                return (fail["next"],)
            n = frames.pop(0)
            clock.sleep(1 / 30)
            buffer.raw = bytes([n]) * len(buffer.raw)
            return (0, SimpleNamespace(fFrameTime=n / 30.0, uFrameNumber=n))

        @staticmethod
        def uninitialize(h):
            return (0,)

    return PxLApi


@pytest.fixture
def camera_env(monkeypatch):
    clock = VirtualClock()
    frames = [0, 1, 2, 7]
    fail: dict = {}
    wrapper = types.SimpleNamespace(PxLApi=fake_api(clock, frames, fail))
    monkeypatch.setitem(sys.modules, "pixelinkWrapper", wrapper)
    from drivers.camera_pixelink import PixelinkCamera

    return PixelinkCamera, clock, fail


def test_settings_read_back_frames_indices_and_gaps(camera_env) -> None:
    PixelinkCamera, clock, fail = camera_env
    cam = PixelinkCamera(clock, exposure_s=2e-3, frame_rate_Hz=30.0, roi=(0, 0, 8, 4))
    assert isinstance(cam, Camera)
    assert cam.exposure_s == pytest.approx(2e-3)
    with pytest.raises(ConfigError, match="FRAME_RATE"):
        PixelinkCamera(clock, frame_rate_Hz=100.0)
    f0, f1 = cam.grab(), cam.grab()
    assert f0.image.shape == (4, 8) and f1.image[0, 0] == 1
    assert f1.time_s - f0.time_s == pytest.approx(1 / 30)
    cam.grab()
    with pytest.raises(DeviceFault, match="4 frames dropped"):
        cam.grab()
    fail["next"] = -2
    with pytest.raises(DeviceTimeout):
        cam.grab()
    cam.close()


def test_frames_missed_while_away_on_purpose_are_not_drops(camera_env) -> None:
    PixelinkCamera, clock, fail = camera_env
    cam = PixelinkCamera(clock, exposure_s=2e-3, frame_rate_Hz=30.0, roi=(0, 0, 8, 4))
    assert [cam.grab().index for _ in range(3)] == [0, 1, 2]
    cam.skip_to_live()              # frames 3-6 go by while the runner ramps the bias
    assert cam.grab().index == 7 and cam.dropped_frames == 0
    cam.close()
