"""Simulated camera: frame timing on the clock, the image model's photometry and noise, settings read-back,
faults, determinism."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from hamr_bench.clock import VirtualClock
from sim_devices import camera_sim
from sim_devices.camera_sim import (
    SimCamera,
    SimCameraSpec,
    background_dn_table,
    digitise,
    expected_electrons,
    render_frame,
    spot_reach_px,
)


def cam(marker=lambda t: (320.3, 240.6), seed=0, **spec_kw):
    clock = VirtualClock()
    return clock, SimCamera(clock, np.random.default_rng(seed), marker, SimCameraSpec(**spec_kw))


def test_read_waits_for_exposure_end_and_stamps_mid_exposure() -> None:
    clock, c = cam(frame_rate_Hz=50.0, exposure_s=4e-3)
    ok, img = c.read()
    assert ok and img.shape == (480, 640) and img.dtype == np.uint8
    assert clock.now_s() == pytest.approx(4e-3)
    assert c.get(cv2.CAP_PROP_POS_MSEC) == pytest.approx(2.0)
    assert c.get(cv2.CAP_PROP_POS_FRAMES) == 1.0
    c.read()
    assert clock.now_s() == pytest.approx(0.02 + 4e-3)
    clock.advance_to(1.0)  # reader far behind: the ring buffer kept only the newest 4 frames
    c.read()
    assert c.get(cv2.CAP_PROP_POS_FRAMES) - 1 == 49 - 4 + 1
    assert c.frames_lost == 49 - 4 + 1 - 2


def test_expected_image_photometry() -> None:
    spec = SimCameraSpec(spot_e_per_s=1e7, background_e_per_pixel_per_s=1e4)
    mu = expected_electrons(spec, np.array([[100.25, 80.75]]), 2e-3, (200, 200))
    bg = 1e4 * 2e-3
    assert (mu - bg).sum() == pytest.approx(1e7 * 2e-3, rel=1e-9)  # all of the spot lands on the patch
    ys, xs = np.mgrid[0:200, 0:200]
    assert ((mu - bg) * xs).sum() / (mu - bg).sum() == pytest.approx(100.25, abs=1e-9)
    assert ((mu - bg) * ys).sum() / (mu - bg).sum() == pytest.approx(80.75, abs=1e-9)
    # pixel-integrated Gaussian variance: sigma^2 + 1/12
    var_x = ((mu - bg) * (xs - 100.25) ** 2).sum() / (mu - bg).sum()
    assert var_x == pytest.approx(spec.spot_sigma_px**2 + 1 / 12, rel=1e-6)


def test_noise_matches_shot_plus_read_plus_quantisation() -> None:
    spec = SimCameraSpec(read_noise_e=5.0, gain_DN_per_e=0.1, bit_depth=12)
    rng = np.random.default_rng(1)
    mean_e = np.full((400, 400), 900.0)
    dn = digitise(spec, mean_e, rng).astype(float)
    assert dn.mean() == pytest.approx(90.0, abs=0.05)
    expected_var_dn = (900 + 25) * 0.01 + 1 / 12
    assert dn.var() == pytest.approx(expected_var_dn, rel=0.03)


def test_background_table_matches_exact_draws() -> None:
    spec = SimCameraSpec()
    rng = np.random.default_rng(2)
    table = background_dn_table(spec, 37.0)
    fast = table[rng.integers(0, 2**16, size=200_000, dtype=np.uint16)].astype(float)
    exact = digitise(spec, np.full(200_000, 37.0), rng).astype(float)
    assert fast.mean() == pytest.approx(exact.mean(), abs=0.01)
    assert fast.var() == pytest.approx(exact.var(), rel=0.03)


def test_camera_background_from_its_pool_is_exact_and_uncorrelated_between_frames() -> None:
    # Frames come from a pool of background draws at random offsets: each frame's background must still have the
    # exact per-pixel distribution, and a pixel must not repeat its value from frame to frame.
    spec = SimCameraSpec(width_px=320, height_px=240, exposure_s=2e-3)
    clock, camera = cam(marker=lambda t: (10.0, 10.0), seed=4, **spec.__dict__)
    frames = np.array([camera.read()[1] for _ in range(40)], dtype=float)[:, 60:, 60:]
    exact = digitise(spec, np.full(frames[0].size, 20.0), np.random.default_rng(9)).astype(float)
    assert frames.mean() == pytest.approx(exact.mean(), abs=0.02)
    assert frames.var() == pytest.approx(exact.var(), rel=0.03)
    a, b = frames[:-1].ravel() - frames.mean(), frames[1:].ravel() - frames.mean()
    correlation = float(np.mean(a * b) / np.sqrt(np.mean(a * a) * np.mean(b * b)))
    assert abs(correlation) < 0.01  # 1.5 M pixel pairs: the standard error is ~0.001
    assert not any(np.array_equal(frames[i], frames[i + 1]) for i in range(len(frames) - 1))


def test_rendered_frame_is_background_far_from_the_spot_and_bright_on_it() -> None:
    spec = SimCameraSpec(spot_e_per_s=1e7)
    img = render_frame(spec, np.array([[50.0, 40.0]]), 2e-3, (120, 160), np.random.default_rng(3))
    peak_e = 1e7 * 2e-3 * (math.erf(0.5 / (2 * math.sqrt(2))) ** 2)  # central pixel share of a sigma-2 spot
    assert img[40, 50] == pytest.approx((peak_e + 20) * 0.1, abs=6)
    assert img[100:, 100:].mean() == pytest.approx(2.0, abs=0.1)


def test_settings_are_clamped_and_read_back() -> None:
    clock, c = cam()
    assert c.set(cv2.CAP_PROP_FRAME_WIDTH, 1280) and c.get(cv2.CAP_PROP_FRAME_HEIGHT) == 1024
    assert c.get(cv2.CAP_PROP_FPS) == 27.0  # the mode's maximum
    assert not c.set(cv2.CAP_PROP_FRAME_WIDTH, 1000)
    c.set(cv2.CAP_PROP_EXPOSURE, 1000)  # 100 ms asked, longer than a frame: clamped
    assert c.get(cv2.CAP_PROP_EXPOSURE) * 1e-4 == pytest.approx(1 / 27.0)


def test_marker_motion_blurs_along_its_path() -> None:
    clock, c = cam(marker=lambda t: (100.0 + 4000.0 * t, 100.0), exposure_s=5e-3, spot_e_per_s=1e7)
    _, img = c.read()  # moves 20 px during the exposure, from x = 100 to 120
    row = img[100].astype(float)
    assert row[105:116].min() > 0.3 * row.max()
    # 10 px (5 sigma) beyond either end only background: 1e4 e/s x 5 ms = 50 e, noise sqrt(50 + 25 + 8.3) e,
    # x 0.1 DN/e: 5 +- 0.9 DN; 6 noise sigmas above it is still far below the streak's ~55 DN
    background_DN, noise_DN = 5.0, 0.1 * np.sqrt(50 + 25 + 1 / (12 * 0.1**2))
    assert row[90] < background_DN + 6 * noise_DN and row[130] < background_DN + 6 * noise_DN


def test_faults_and_determinism() -> None:
    _, a = cam(seed=5)
    _, b = cam(seed=5)
    assert np.array_equal(a.read()[1], b.read()[1])
    clock, c = cam()
    c.inject_fault("no_reply")
    assert c.read() == (False, None) and clock.now_s() == pytest.approx(1.0)
    c.clear_fault("no_reply")
    c.inject_fault("dropped_frames", 0.5)
    indices = []
    for _ in range(50):
        c.read()
        indices.append(c.get(cv2.CAP_PROP_POS_FRAMES) - 1)
    assert np.max(np.diff(indices)) > 1 and c.frames_lost > 10
    c.inject_fault("disconnect")
    assert c.read() == (False, None) and not c.isOpened()


def test_scheduled_disconnect() -> None:
    clock, c = cam()
    c.inject_fault("disconnect", at_s=0.05)
    assert c.read()[0] and c.isOpened()
    clock.advance_to(0.06)
    assert c.read() == (False, None) and not c.isOpened()


@pytest.mark.parametrize("exposure_s", [2e-3, 1 / 60])
def test_spot_outside_its_patch_adds_under_the_tail_tolerance(exposure_s) -> None:
    # The exact expected image of a spot moving 10 px during the exposure, on a patch much larger than the one
    # render_frame draws: every pixel outside the drawn patch (reach beyond the path's pixel bounds) must get
    # less than SPOT_TAIL_E electrons from the spot.
    spec = SimCameraSpec()
    path = np.column_stack([np.linspace(50.3, 60.3, spec.motion_samples), np.full(spec.motion_samples, 50.7)])
    reach = spot_reach_px(spec, exposure_s)
    spot_e = expected_electrons(spec, path, exposure_s, (101, 111)) - spec.background_e_per_pixel_per_s * exposure_s
    inside = np.zeros(spot_e.shape, dtype=bool)
    inside[50 - reach:51 + reach + 1, 50 - reach:61 + reach + 1] = True  # floor(min) - reach .. ceil(max) + reach
    assert spot_e[~inside].max() < camera_sim.SPOT_TAIL_E
