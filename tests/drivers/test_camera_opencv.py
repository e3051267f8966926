"""OpenCV camera driver against the simulated camera (the VideoCapture surface), a minimal fake capture, and a
real `cv2.VideoCapture` on a recorded image sequence."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers.camera_opencv import OpenCvCamera
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import Camera
from sim_devices.camera_sim import SimCamera, SimCameraSpec


def sim(seed=0, **kw):
    clock = VirtualClock()
    source = SimCamera(clock, np.random.default_rng(seed), lambda t: (320.0, 240.0), SimCameraSpec())
    camera = OpenCvCamera(source, clock, device_time_is_rig_time=True, **kw)
    return clock, source, camera


def test_settings_applied_and_frames_stamped_on_the_rig_clock() -> None:
    clock, source, camera = sim(frame_rate_Hz=50.0, exposure_s=3e-3)
    assert isinstance(camera, Camera)
    assert camera.frame_rate_Hz == 50.0 and camera.exposure_s == pytest.approx(3e-3)
    frames = [camera.grab() for _ in range(3)]
    assert [f.index for f in frames] == [0, 1, 2]
    np.testing.assert_allclose([f.time_s for f in frames], np.arange(3) / 50.0 + 1.5e-3)
    assert clock.now_s() == pytest.approx(2 / 50.0 + 3e-3)


def test_settings_that_do_not_stick_are_config_errors() -> None:
    with pytest.raises(ConfigError, match="width_px set to 1000 but the camera reads back 640"):
        sim(width_px=1000)
    with pytest.raises(ConfigError, match="exposure_s"):
        sim(frame_rate_Hz=60.0, exposure_s=0.05)  # longer than a frame: the camera clamps it


def test_roi_crops_and_is_checked() -> None:
    _, _, camera = sim(roi=(300, 220, 40, 30))
    assert camera.grab().image.shape == (30, 40)
    with pytest.raises(ConfigError, match="does not fit"):
        camera.set_roi(620, 0, 40, 10)


class BareCapture:
    """A VideoCapture-like source that gives neither frame counters nor time stamps, in colour."""

    def __init__(self, clock: VirtualClock) -> None:
        self.clock, self.open, self.props = clock, True, {cv2.CAP_PROP_FPS: 30.0, cv2.CAP_PROP_EXPOSURE: 50.0}

    def read(self):
        self.clock.sleep(1 / 30)
        return True, np.full((4, 6, 3), (10, 20, 30), dtype=np.uint8)

    def set(self, prop, value):
        return False

    def get(self, prop):
        return self.props.get(prop, 0.0)

    def release(self):
        self.open = False

    def isOpened(self):  # noqa: N802
        return self.open


def test_bare_capture_uses_own_counter_and_clock_times_and_grey() -> None:
    clock = VirtualClock()
    camera = OpenCvCamera(BareCapture(clock), clock)
    f0, f1 = camera.grab(), camera.grab()
    assert (f0.index, f1.index) == (0, 1)
    assert f1.time_s == pytest.approx(2 / 30 - 50 * 1e-4 / 2)
    assert f0.image.shape == (4, 6)
    assert f0.image[0, 0] == cv2.cvtColor(np.array([[[10, 20, 30]]], np.uint8), cv2.COLOR_BGR2GRAY)[0, 0]


class OtherEpochCamera(SimCamera):
    """The simulated camera with its time stamps on a device clock 1000 s ahead of the rig clock."""

    def get(self, prop):
        value = super().get(prop)
        return value + 1e6 if prop == cv2.CAP_PROP_POS_MSEC else value


def test_device_time_base_is_aligned_to_the_rig_clock_once() -> None:
    clock = VirtualClock()
    camera = OpenCvCamera(OtherEpochCamera(clock, np.random.default_rng(0), lambda t: (10.0, 10.0)), clock,
                          exposure_s=2e-3)
    frames = [camera.grab() for _ in range(3)]
    # the first frame arrives as its exposure ends, so alignment recovers the true mid-exposure times
    np.testing.assert_allclose([f.time_s for f in frames], np.arange(3) / 60.0 + 1e-3, atol=1e-9)


def test_dropped_frames_show_as_gaps_and_bursts_raise() -> None:
    clock, source, camera = sim(seed=4)
    source.inject_fault("dropped_frames", 0.3)
    indices = []
    with pytest.raises(DeviceFault, match="frames dropped before frame") as info:
        for _ in range(500):
            indices.append(camera.grab().index)
    assert "\n" not in str(info.value)
    assert np.any(np.diff(indices) > 1)
    assert camera.dropped_frames == source.frames_lost


def test_disconnect_and_no_reply() -> None:
    clock, source, camera = sim(timeout_s=0.3)
    source.inject_fault("no_reply")
    t0 = clock.now_s()
    with pytest.raises(DeviceTimeout):
        camera.grab()
    assert clock.now_s() - t0 <= 0.3 + 1e-9
    source.clear_fault("no_reply")
    source.inject_fault("disconnect")
    with pytest.raises(DeviceFault, match="disconnected"):
        camera.grab()


def test_cannot_open_is_device_fault(tmp_path: Path) -> None:
    with pytest.raises(DeviceFault, match="cannot open"):
        OpenCvCamera(str(tmp_path / "absent_%03d.png"), VirtualClock())


def test_real_videocapture_on_a_recorded_image_sequence(tmp_path: Path) -> None:
    for i in range(5):
        image = np.full((48, 64), i * 10, dtype=np.uint8)
        cv2.imwrite(str(tmp_path / f"f_{i:03d}.png"), image)
    clock = VirtualClock()
    camera = OpenCvCamera(str(tmp_path / "f_%03d.png"), clock)
    frames = [camera.grab() for _ in range(5)]
    assert [f.index for f in frames] == list(range(5))
    assert [int(f.image[0, 0]) for f in frames] == [0, 10, 20, 30, 40]
    camera.close()


def test_a_pause_between_tracked_drives_is_not_a_drop() -> None:
    clock, source, camera = sim()
    camera.grab()
    clock.sleep(0.5)                # ~30 frames at 60 Hz go by unread (a slow bias ramp)
    with pytest.raises(DeviceFault, match="frames dropped"):
        camera.grab()
    clock.sleep(0.5)
    camera.skip_to_live()
    before = camera.dropped_frames
    frames = [camera.grab() for _ in range(3)]
    assert camera.dropped_frames == before
    assert np.all(np.diff([f.index for f in frames]) == 1)
