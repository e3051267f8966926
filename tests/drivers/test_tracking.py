"""Marker tracking on rendered frames with known sub-pixel positions (loose precision; the Cramer-Rao ratio is
a benchmark figure), live through camera driver + simulated camera, on recorded images, and pixel
calibration."""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivers.camera_opencv import OpenCvCamera
from drivers.tracking import MarkerTracker, PixelCalibration, estimate_spot_sigma_px, fit_pixel_calibration
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError
from sim_devices.camera_sim import SimCamera, SimCameraSpec, render_frame

SPEC = SimCameraSpec(spot_e_per_s=1e7)  # ~20 000 signal electrons per frame: good SNR


def render(x: float, y: float, rng, shape=(64, 64)) -> np.ndarray:
    return render_frame(SPEC, np.array([[x, y]]), SPEC.exposure_s, shape, rng)


@pytest.mark.parametrize("gain", [None, SPEC.gain_DN_per_e])
def test_subpixel_precision_and_no_phase_bias(gain) -> None:
    rng = np.random.default_rng(0)
    tracker = MarkerTracker(SPEC.spot_sigma_px, gain_DN_per_e=gain)
    phases = np.column_stack([np.repeat(np.linspace(0, 0.95, 20), 10), np.tile(np.linspace(0, 0.9, 10), 20)])
    truth = 30 + phases
    est = np.array([[f.x_px, f.y_px] for f in (tracker.locate(render(x, y, rng)) for x, y in truth)])
    err = est - truth
    assert np.sqrt(np.mean(err**2)) < 0.1
    # no systematic error tied to where the centre falls within a pixel
    for axis in (0, 1):
        phase_bins = np.floor((truth[:, axis] % 1) * 4)
        means = [err[phase_bins == b, axis].mean() for b in range(4)]
        assert max(abs(m) for m in means) < 0.02


def test_tracks_across_frames_and_reacquires_a_jump() -> None:
    rng = np.random.default_rng(1)
    tracker = MarkerTracker(2.0)
    path = [(50 + 0.7 * i, 60 + 0.3 * i) for i in range(20)] + [(200.4, 30.2)]
    fixes = [tracker.update(render(x, y, rng, (120, 240))) for x, y in path]
    assert all(f.ok for f in fixes)
    assert np.max(np.abs([[f.x_px - x, f.y_px - y] for f, (x, y) in zip(fixes, path)])) < 0.15


def test_fast_ramp_is_tracked_without_a_full_frame_search(monkeypatch) -> None:
    # A leg on a drive ramp: still, then 4 px/frame growing to 25 px/frame (more than the 8 px window
    # half-width), steady, then still again. The fixes must follow it, and only the first frame may search
    # the whole image: the rest come from the predicted or last position, or the search near the last fix.
    rng = np.random.default_rng(3)
    tracker = MarkerTracker(2.0)
    steps = [0.0] * 3 + [4.0, 12.0, 25.0, 25.0, 25.0, 25.0, 18.0, 6.0] + [0.0] * 3
    ys = 20.0 + np.cumsum(steps)
    full_frame_searches = []
    monkeypatch.setattr(tracker, "locate", lambda image, guess=None: full_frame_searches.append(1)
                        or MarkerTracker.locate(tracker, image, guess))
    fixes = [tracker.update(render(40.3, y, rng, (220, 80))) for y in ys]
    assert all(f.ok for f in fixes)
    assert np.max(np.abs([f.y_px - y for f, y in zip(fixes, ys)])) < 0.15
    assert len(full_frame_searches) == 1


def test_no_marker_is_not_ok_and_roi_offset_is_added() -> None:
    rng = np.random.default_rng(2)
    blank = render_frame(SimCameraSpec(spot_e_per_s=0.0), np.array([[10.0, 10.0]]), 2e-3, (40, 40), rng)
    assert not MarkerTracker(2.0).locate(blank).ok
    roi_image = render(20.3, 25.6, rng, (50, 50))  # as if cropped at (100, 200) from a larger frame
    fix = MarkerTracker(2.0, offset_px=(100, 200)).update(roi_image)
    assert fix.x_px == pytest.approx(120.3, abs=0.1) and fix.y_px == pytest.approx(225.6, abs=0.1)


def test_live_pipeline_sim_camera_driver_tracker() -> None:
    clock = VirtualClock()

    def marker(t: float) -> tuple[float, float]:
        return 320.0 + 30.0 * math.sin(2 * math.pi * 2.0 * t), 240.0

    source = SimCamera(clock, np.random.default_rng(3), marker, SPEC)
    camera = OpenCvCamera(source, clock, device_time_is_rig_time=True, exposure_s=1e-3)
    tracker = MarkerTracker(SPEC.spot_sigma_px)
    points = [tracker.track_frame(camera.grab()) for _ in range(30)]
    truth = np.array([marker(p.time_s)[0] for p in points])
    # exposure 1 ms: the marker moves < 0.4 px during it and the blur is symmetric about mid-exposure
    assert np.max(np.abs(np.array([p.x_px for p in points]) - truth)) < 0.15


def test_recorded_images_give_the_same_answer_as_live(tmp_path: Path) -> None:
    rng = np.random.default_rng(4)
    images = [render(30 + 0.25 * i, 32 - 0.1 * i, rng) for i in range(8)]
    live = MarkerTracker(2.0).track(images)
    for i, image in enumerate(images):
        cv2.imwrite(str(tmp_path / f"m_{i:03d}.png"), image)
    clock = VirtualClock()
    camera = OpenCvCamera(str(tmp_path / "m_%03d.png"), clock)
    tracker = MarkerTracker(2.0)
    recorded = np.array([[p.x_px, p.y_px] for p in (tracker.track_frame(camera.grab()) for _ in images)])
    np.testing.assert_array_equal(recorded, live)  # PNG is lossless: identical pixels, identical estimates


def test_fit_calibration_recovers_scale_axis_and_origin() -> None:
    rng = np.random.default_rng(5)
    scale, angle, origin = 6.7e-6 / 1.0, math.radians(-30.0), np.array([100.0, 200.0])  # 6.7 um per px
    positions_m = np.linspace(-50e-6, 50e-6, 11)
    direction = np.array([math.cos(angle), math.sin(angle)])
    points = origin + np.outer(positions_m / scale, direction) + rng.normal(0, 0.02, (11, 2))
    cal = fit_pixel_calibration(points, positions_m)
    assert cal.metre_per_px == pytest.approx(scale, rel=2e-3)
    assert cal.angle_rad == pytest.approx(angle, abs=2e-3)
    assert cal.displacement_m(*origin) == pytest.approx(0.0, abs=0.05 * scale)
    np.testing.assert_allclose(cal.displacement_m(points[:, 0], points[:, 1]), positions_m, atol=0.05 * scale)
    assert cal.residual_rms_m < 0.05 * scale
    with pytest.raises(ConfigError):
        fit_pixel_calibration(points[:1], positions_m[:1])


def test_scale_bar_calibration() -> None:
    # 1 mm over 100 px, pointing down the image
    cal = PixelCalibration.from_scale_bar((10.0, 10.0), (10.0, 110.0), 1e-3)
    assert cal.metre_per_px == pytest.approx(1e-5)
    assert cal.displacement_m(10.0, 60.0) == pytest.approx(0.5e-3)
    along, across = cal.to_metres(20.0, 10.0)
    assert along == pytest.approx(0.0, abs=1e-12) and abs(across) == pytest.approx(1e-4)


def test_estimate_spot_sigma() -> None:
    image = render(40.2, 30.7, np.random.default_rng(6), (80, 80))
    assert estimate_spot_sigma_px(image, 40.2, 30.7) == pytest.approx(SPEC.spot_sigma_px, rel=0.05)
