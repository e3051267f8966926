"""Benchmark: marker-tracking precision against the Cramer-Rao bound of the rendered image model, and tracking
speed on 640x480 frames on one core. Prints the figures.

    python3 -m benchmarks.bench_tracking [--quick] [--json]

Precision: frames of a static marker at uniformly random sub-pixel positions are rendered by the simulated
camera's model (`sim_devices.camera_sim`: pixel-integrated Gaussian spot, Poisson shot noise, Gaussian read
noise, rounding); the tracker (`drivers.tracking.MarkerTracker`, no prior position) estimates each. The bound
comes from the Fisher information of that model for the unknowns (x, y, spot electrons, background): F =
sum_pixels grad(mu) grad(mu)^T / var, with var = mu + read^2 + 1/(12 gain^2) (the Gaussian approximation of
the Poisson-Gaussian-rounding noise; exact for pure shot noise without rounding loss), grad(mu) by central
differences of `expected_electrons` in x and y. ratio = RMS error / sqrt(mean CRB^2) over the frames, both
axes pooled; its statistical uncertainty is about 1 / sqrt(2 x 2 x frames).

Speed: `MarkerTracker.update` (windowed refinement around the previous fix) over pre-rendered 640x480 frames
of a moving marker; `locate` without a guess (a full-frame blur and arg max) for comparison.
"""

from __future__ import annotations

import json
import sys
import time
from dataclasses import replace

import cv2
import numpy as np


def crb_px(spec, x: float, y: float, shape: tuple[int, int], h_px: float = 1e-4) -> tuple[float, float]:
    from sim_devices.camera_sim import expected_electrons, pixel_variance_e2

    exposure = spec.exposure_s

    def mu(px: float, py: float) -> np.ndarray:
        return expected_electrons(spec, np.array([[px, py]]), exposure, shape)

    mean = mu(x, y)
    background = spec.background_e_per_pixel_per_s * exposure
    signal = spec.spot_e_per_s * exposure
    grads = [
        (mu(x + h_px, y) - mu(x - h_px, y)) / (2 * h_px),
        (mu(x, y + h_px) - mu(x, y - h_px)) / (2 * h_px),
        (mean - background) / signal,  # d mu / d signal electrons
        np.ones_like(mean),  # d mu / d background
    ]
    var = pixel_variance_e2(spec, mean)
    g = np.stack([d.ravel() for d in grads])
    fisher = (g / var.ravel()) @ g.T
    cov = np.linalg.inv(fisher)
    return float(np.sqrt(cov[0, 0])), float(np.sqrt(cov[1, 1]))


def precision(spec, frames: int, seed: int = 0, size: int = 48) -> dict:
    from drivers.tracking import MarkerTracker
    from sim_devices.camera_sim import render_frame

    rng = np.random.default_rng(seed)
    trackers = {
        "matched_filter": MarkerTracker(spec.spot_sigma_px, ml_passes=0),
        "ml_uniform": MarkerTracker(spec.spot_sigma_px),
        "ml_gain_known": MarkerTracker(spec.spot_sigma_px, gain_DN_per_e=spec.gain_DN_per_e),
    }
    truth = size / 2 + rng.uniform(-0.5, 0.5, (frames, 2))
    est = {name: np.empty_like(truth) for name in trackers}
    crb = np.empty_like(truth)
    for i, (x, y) in enumerate(truth):
        image = render_frame(spec, np.array([[x, y]]), spec.exposure_s, (size, size), rng)
        for name, tracker in trackers.items():
            fix = tracker.locate(image)
            est[name][i] = fix.x_px, fix.y_px
        crb[i] = crb_px(spec, x, y, (size, size))
    bound = float(np.sqrt(np.mean(crb**2)))
    out = {
        "signal_e": spec.spot_e_per_s * spec.exposure_s,
        "background_e_per_px": spec.background_e_per_pixel_per_s * spec.exposure_s,
        "read_noise_e": spec.read_noise_e,
        "bits": spec.bit_depth,
        "frames": frames,
        "crb_px": bound,
    }
    for name in trackers:
        err = est[name] - truth
        rms = float(np.sqrt(np.mean(err**2)))
        out[name] = {
            "rms_error_px": rms,
            "ratio": rms / bound,
            "ratio_stat_uncertainty": rms / bound / np.sqrt(4 * frames),
            "bias_px": [float(err[:, 0].mean()), float(err[:, 1].mean())],
            "failed_fixes": int(np.sum(~np.isfinite(est[name]).all(axis=1))),
        }
    return out


def speed(spec, n_frames: int, passes: int) -> dict:
    from drivers.tracking import MarkerTracker
    from sim_devices.camera_sim import render_frame

    cv2.setNumThreads(1)
    rng = np.random.default_rng(1)
    # a closed path moving < 2 px per frame (the window follows it; a wider jump costs a full search)
    phase = 2 * np.pi * np.arange(n_frames) / n_frames
    path = np.column_stack([320 + 30 * np.sin(phase), 240 + 20 * np.cos(phase)])
    images = [render_frame(spec, p[None, :], spec.exposure_s, (480, 640), rng) for p in path]
    tracker = MarkerTracker(spec.spot_sigma_px, gain_DN_per_e=spec.gain_DN_per_e)
    tracker.update(images[0])
    t0 = time.perf_counter()
    fixes = [tracker.update(image) for _ in range(passes) for image in images]
    windowed = passes * n_frames / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    for image in images:
        MarkerTracker(spec.spot_sigma_px, gain_DN_per_e=spec.gain_DN_per_e).locate(image)
    full = n_frames / (time.perf_counter() - t0)
    err = np.array([[f.x_px, f.y_px] for f in fixes[-n_frames:]]) - path
    return {"frame": "640x480", "tracked_fps": windowed, "full_search_fps": full,
            "max_error_px": float(np.max(np.abs(err)))}


def run(quick: bool = False) -> dict:
    from sim_devices.camera_sim import SimCameraSpec

    frames = 300 if quick else 2000
    base = SimCameraSpec(spot_e_per_s=1e7)
    cases = {
        "bright_8bit": base,
        "dim_8bit": replace(base, spot_e_per_s=2e6),
        "shot_limited_16bit": replace(base, read_noise_e=0.0, gain_DN_per_e=1.0, bit_depth=16),
    }
    out = {name: precision(spec, frames, seed=i) for i, (name, spec) in enumerate(cases.items())}
    out["speed"] = speed(base, 100, 5 if quick else 30)
    return out


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    r = run(quick="--quick" in argv)
    if "--json" in argv:
        print(json.dumps(r))
        return 0
    for name, v in r.items():
        if name == "speed":
            print(f"speed ({v['frame']}, one core): tracked {v['tracked_fps']:.0f} frames/s, "
                  f"full-frame search {v['full_search_fps']:.0f} frames/s, "
                  f"max error {v['max_error_px']:.3f} px")
        else:
            print(f"{name}: signal {v['signal_e']:.0f} e, bg {v['background_e_per_px']:.0f} e/px, "
                  f"read {v['read_noise_e']:.0f} e, {v['bits']} bit, {v['frames']} frames, "
                  f"CRB {v['crb_px']:.4f} px")
            for est in ("matched_filter", "ml_uniform", "ml_gain_known"):
                e = v[est]
                print(f"  {est:15s} RMS {e['rms_error_px']:.4f} px  ratio {e['ratio']:.3f} "
                      f"+/- {e['ratio_stat_uncertainty']:.3f}  bias ({e['bias_px'][0]:+.4f}, "
                      f"{e['bias_px'][1]:+.4f}) px  failed {e['failed_fixes']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
