"""Displacement from images: sub-pixel tracking of a bright round marker (on the leg or the actuator tip) and
the pixel-to-metre calibration. The same functions take a live `Frame` from a camera driver or a recorded
image array.

Estimator, in two stages inside a small window around the previous position:
1. a matched-filter (Gaussian-weighted) centroid. For a Gaussian spot of width s (pixel integration adds
   1/12 px^2 to s^2) weighted by a Gaussian of the same width, the weighted centroid moves only half way from the
   guess to the true centre each pass (the product of two Gaussians), so each pass extrapolates by
   (s^2 + w^2) / w^2. Its fixed point is the maximum-likelihood position for a Gaussian spot in white noise;
   two or three passes converge. The background is the mean of the window's border.
2. `ml_passes` Gauss-Newton steps (default 1: from stage 1's answer one suffices) of the full maximum-
   likelihood fit of (x, y, amplitude, background) with the exact pixel-integrated Gaussian, weighting each
   pixel by 1 / (gain x signal + background variance) when the camera's `gain_DN_per_e` is given (shot noise
   dominates a bright spot), else uniformly.
Work per frame is a few products over the (2k+1)^2 window, independent of the image size, which is what gives
thousands of frames/s on one core; a global search (blur + arg max) runs only for the first frame or when the
marker is lost.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import ndtr

from hamr_bench.errors import ConfigError
from hamr_bench.interfaces import Frame


_INV_SQRT_2PI = 1.0 / math.sqrt(2.0 * math.pi)
# A matched-filter pass that moves the estimate less than this has converged: further passes change it by less
# again (each pass contracts the error), far below the ~0.02 px the shot noise allows, and the maximum-likelihood
# step that follows starts from it anyway. From a predicted position on a still or steady marker this saves passes.
_CONVERGED_PX = 1e-3


@dataclass(frozen=True)
class MarkerFix:
    """A marker position in full-frame pixel coordinates (pixel centres at integers), its fitted peak
    amplitude above background (image units), the window noise (std of the border), and whether the fix is
    trusted."""

    x_px: float
    y_px: float
    amplitude: float
    noise: float
    ok: bool


@dataclass(frozen=True)
class TrackedPoint:
    time_s: float
    index: int
    x_px: float
    y_px: float
    ok: bool


class MarkerTracker:
    """Tracks one marker frame to frame; `locate` works on any single image."""

    def __init__(
        self,
        sigma_px: float = 2.0,
        *,
        window_half_px: int | None = None,
        passes: int = 3,
        min_snr: float = 5.0,
        offset_px: tuple[int, int] = (0, 0),
        ml_passes: int = 1,
        gain_DN_per_e: float | None = None,
    ) -> None:
        if not (math.isfinite(sigma_px) and 0.3 <= sigma_px <= 50):
            raise ConfigError(f"MarkerTracker: sigma_px={sigma_px!r} outside [0.3, 50]")
        self._s2 = sigma_px**2 + 1.0 / 12.0  # spot width as pixel-integrated
        self._w = math.sqrt(self._s2)  # matched weight width
        self._gain = (self._s2 + self._w**2) / self._w**2
        self._half = int(window_half_px if window_half_px is not None else math.ceil(4 * math.sqrt(self._s2)))
        if self._half < 2:
            raise ConfigError(f"MarkerTracker: window_half_px={self._half} too small")
        self._passes = int(passes)
        self._min_snr = float(min_snr)
        self._sigma = float(sigma_px)
        self._offset = (int(offset_px[0]), int(offset_px[1]))
        self._ml_passes = int(ml_passes)
        if gain_DN_per_e is not None and not (math.isfinite(gain_DN_per_e) and gain_DN_per_e > 0):
            raise ConfigError(f"MarkerTracker: gain_DN_per_e={gain_DN_per_e!r} must be positive")
        self._gain_DN_per_e = gain_DN_per_e
        self._last: tuple[float, float] | None = None
        self._previous: tuple[float, float] | None = None  # the fix before `_last`, for the velocity

    def reset(self) -> None:
        self._last = None
        self._previous = None

    def update(self, image: np.ndarray) -> MarkerFix:
        """Track in `image` starting from where the last two fixes say the marker is now (constant velocity),
        then from the last fix; searches the whole image when there is none or the marker is lost. Coordinates
        include `offset_px` (an ROI's corner)."""
        fix = None
        for guess in self._guesses():
            fix = self._refine(image, guess[0] - self._offset[0], guess[1] - self._offset[1])
            if fix is not None and fix.ok:
                break
        if (fix is None or not fix.ok) and self._last is not None:
            fix = self._search_near(image, self._last)
        if fix is None or not fix.ok:
            fix = self.locate(image)
        self._previous = self._last if fix.ok else None
        self._last = (fix.x_px, fix.y_px) if fix.ok else None
        return fix

    def _guesses(self) -> list[tuple[float, float]]:
        # A leg on a drive ramp moves up to tens of pixels a frame, more than the search window's half-width:
        # from the last fix alone the marker would be lost (a global search, ~5x the cost of a refine) on every
        # ramp frame. Its velocity is nearly constant along a ramp, so the extrapolated position is tried first.
        if self._last is None:
            return []
        if self._previous is None:
            return [self._last]
        (x1, y1), (x0, y0) = self._last, self._previous
        predicted = (2.0 * x1 - x0, 2.0 * y1 - y0)
        if abs(predicted[0] - x1) < 0.5 and abs(predicted[1] - y1) < 0.5:
            return [self._last]  # at rest: one guess
        return [predicted, self._last]

    def locate(self, image: np.ndarray, guess_px: tuple[float, float] | None = None) -> MarkerFix:
        """One image, no history: from `guess_px` (full-frame coordinates) or a global search."""
        if image.ndim != 2:
            raise ConfigError(f"MarkerTracker: needs a 2-D grey image, got shape {image.shape}")
        if guess_px is None:
            gx, gy = self._global_peak(image)
        else:
            gx, gy = guess_px[0] - self._offset[0], guess_px[1] - self._offset[1]
        fix = self._refine(image, gx, gy)
        return fix if fix is not None else MarkerFix(math.nan, math.nan, 0.0, math.nan, False)

    def track_frame(self, frame: Frame) -> TrackedPoint:
        fix = self.update(frame.image)
        return TrackedPoint(frame.time_s, frame.index, fix.x_px, fix.y_px, fix.ok)

    def track(self, images: Iterable[np.ndarray]) -> np.ndarray:
        """Positions (n, 2) in pixels over a sequence of images (recorded or live); NaN where the fix
        failed."""
        out = [(f.x_px, f.y_px) if f.ok else (math.nan, math.nan) for f in map(self.update, images)]
        return np.array(out, dtype=float).reshape(-1, 2)

    # ---- internals -----------------------------------------------------------------------------------------
    def _global_peak(self, image: np.ndarray) -> tuple[float, float]:
        blurred = cv2.GaussianBlur(image.astype(np.float32), (0, 0), self._sigma)
        _, _, _, (x, y) = cv2.minMaxLoc(blurred)
        return float(x), float(y)

    def _search_near(self, image: np.ndarray, last_px: tuple[float, float]) -> MarkerFix | None:
        """The peak search of `locate`, on a region of 4 window half-widths around the last fix only: where a
        drive ramp starts the marker jumps further than the window in one frame but stays near, and the region
        costs a small fraction of a full-frame search."""
        h, w = image.shape
        reach = 4 * self._half
        cx, cy = int(round(last_px[0] - self._offset[0])), int(round(last_px[1] - self._offset[1]))
        x0, x1 = max(cx - reach, 0), min(cx + reach + 1, w)
        y0, y1 = max(cy - reach, 0), min(cy + reach + 1, h)
        if x1 - x0 < 5 or y1 - y0 < 5:
            return None
        gx, gy = self._global_peak(image[y0:y1, x0:x1])
        return self._refine(image, gx + x0, gy + y0)

    def _refine(self, image: np.ndarray, gx: float, gy: float) -> MarkerFix | None:
        h, w = image.shape
        half = self._half
        cx, cy = int(round(gx)), int(round(gy))
        x0, x1 = max(cx - half, 0), min(cx + half + 1, w)
        y0, y1 = max(cy - half, 0), min(cy + half + 1, h)
        if x1 - x0 < 5 or y1 - y0 < 5 or not (math.isfinite(gx) and math.isfinite(gy)):
            return None
        win = image[y0:y1, x0:x1].astype(np.float64)
        border = np.concatenate((win[0], win[-1], win[1:-1, 0], win[1:-1, -1]))
        background = border.mean()
        noise = float(border.std())
        win -= background
        xs = np.arange(x0, x1, dtype=np.float64)
        ys = np.arange(y0, y1, dtype=np.float64)
        x, y = gx, gy
        inv2w2 = 0.5 / self._w**2
        for _ in range(self._passes):
            wx = np.exp(-((xs - x) ** 2) * inv2w2)
            wy = np.exp(-((ys - y) ** 2) * inv2w2)
            row = wy @ win  # weighted over y: a function of x
            col = win @ wx  # weighted over x: a function of y
            total = row @ wx
            if total <= 0:
                return MarkerFix(math.nan, math.nan, 0.0, noise, False)
            x_new = x + self._gain * ((row @ (wx * xs)) / total - x)
            y_new = y + self._gain * ((col @ (wy * ys)) / total - y)
            converged = abs(x_new - x) < _CONVERGED_PX and abs(y_new - y) < _CONVERGED_PX
            x, y = x_new, y_new
            if abs(x - cx) > half or abs(y - cy) > half:
                return MarkerFix(math.nan, math.nan, 0.0, noise, False)
            if converged:
                break
        wx = np.exp(-((xs - x) ** 2) * inv2w2)
        wy = np.exp(-((ys - y) ** 2) * inv2w2)
        amplitude = float((wy @ win @ wx) / ((wx @ wx) * (wy @ wy)))
        ok = amplitude > self._min_snr * max(noise, 1e-12)
        if ok and self._ml_passes > 0:
            x, y = self._ml_refine(win, background, noise**2, xs, ys, x, y)
        return MarkerFix(x + self._offset[0], y + self._offset[1], amplitude, noise, ok)

    def _ml_refine(self, win: np.ndarray, background: float, var_bg: float, xs: np.ndarray, ys: np.ndarray,
                   x: float, y: float) -> tuple[float, float]:
        """Gauss-Newton steps of the maximum-likelihood fit of (x, y, amplitude, background) with the exact
        pixel-integrated Gaussian; pixel variance `gain x signal + var_bg` when the camera gain (DN per
        electron) is known (shot noise), else constant. Keeps the matched-filter answer if a step misbehaves."""
        inv_sigma = 1.0 / self._sigma
        x_edges = xs[0] - 0.5 + np.arange(xs.size + 1)
        y_edges = ys[0] - 0.5 + np.arange(ys.size + 1)
        data = win.ravel()  # already background-subtracted
        n = data.size
        jac = np.empty((4, n))
        jac[3] = 1.0
        amp, offset = 0.0, 0.0
        x_new, y_new = x, y
        for k in range(self._ml_passes):
            ux, uy = (x_edges - x_new) * inv_sigma, (y_edges - y_new) * inv_sigma
            cx, cy = ndtr(ux), ndtr(uy)
            px, py = cx[1:] - cx[:-1], cy[1:] - cy[:-1]
            gx, gy = np.exp(-0.5 * ux * ux), np.exp(-0.5 * uy * uy)
            dpx = (gx[:-1] - gx[1:]) * (inv_sigma * _INV_SQRT_2PI)
            dpy = (gy[:-1] - gy[1:]) * (inv_sigma * _INV_SQRT_2PI)
            spot = (py[:, None] * px[None, :]).ravel()
            if k == 0:
                amp = float(data @ spot / (spot @ spot))
                if amp <= 0:
                    return x, y
            jac[0] = (amp * py[:, None] * dpx[None, :]).ravel()
            jac[1] = (amp * dpy[:, None] * px[None, :]).ravel()
            jac[2] = spot
            residual = data - offset - amp * spot
            if self._gain_DN_per_e is not None:
                weights = 1.0 / (self._gain_DN_per_e * np.maximum(amp * spot, 0.0) + max(var_bg, 1e-12))
                jw = jac * weights
            else:
                jw = jac
            try:
                step = np.linalg.solve(jw @ jac.T, jw @ residual)
            except np.linalg.LinAlgError:
                return x, y
            if not np.all(np.isfinite(step)) or abs(step[0]) > 1.0 or abs(step[1]) > 1.0:
                return x, y
            x_new, y_new = x_new + step[0], y_new + step[1]
            amp, offset = amp + step[2], offset + step[3]
        return float(x_new), float(y_new)


def estimate_spot_sigma_px(image: np.ndarray, x_px: float, y_px: float, half_px: int = 12) -> float:
    """Spot width (the `sigma_px` a tracker needs) from a least-squares fit of a pixel-integrated Gaussian
    plus offset to the window's row and column sums around (x, y)."""
    from scipy.optimize import curve_fit

    h, w = image.shape
    cx, cy = int(round(x_px)), int(round(y_px))
    x0, x1 = max(cx - half_px, 0), min(cx + half_px + 1, w)
    y0, y1 = max(cy - half_px, 0), min(cy + half_px + 1, h)
    win = image[y0:y1, x0:x1].astype(np.float64)

    def model(u, area, centre, sigma, offset):
        return area * (ndtr((u + 0.5 - centre) / sigma) - ndtr((u - 0.5 - centre) / sigma)) + offset

    sigmas = []
    axes = ((win.sum(axis=0), np.arange(x0, x1), x_px), (win.sum(axis=1), np.arange(y0, y1), y_px))
    for profile, coords, guess in axes:
        start = (float(profile.sum() - profile.min() * len(profile)), guess, 2.0, float(profile.min()))
        try:
            params, _ = curve_fit(model, coords.astype(float), profile, p0=start, maxfev=2000)
        except RuntimeError:
            raise ConfigError(f"estimate_spot_sigma_px: no spot fits at ({x_px:g}, {y_px:g})") from None
        sigmas.append(abs(params[2]))
    return float(np.mean(sigmas))


@dataclass(frozen=True)
class PixelCalibration:
    """Image pixels to metres along the measured axis: the axis points along `angle_rad` in the image (x
    right, y down), `origin_px` is where displacement is 0, `metre_per_px` the scale; `residual_rms_m` is the
    fit residual when the calibration was fitted."""

    metre_per_px: float
    angle_rad: float = 0.0
    origin_px: tuple[float, float] = (0.0, 0.0)
    residual_rms_m: float = 0.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.metre_per_px) and self.metre_per_px > 0):
            raise ConfigError(f"PixelCalibration.metre_per_px: must be positive, got {self.metre_per_px!r}")

    def displacement_m(self, x_px: np.ndarray | float, y_px: np.ndarray | float) -> np.ndarray | float:
        """Signed displacement along the axis, in metres (vectorised)."""
        along, _ = self.to_metres(x_px, y_px)
        return along

    def to_metres(self, x_px, y_px):
        """(along-axis, across-axis) positions in metres relative to `origin_px`."""
        dx = np.asarray(x_px, dtype=float) - self.origin_px[0]
        dy = np.asarray(y_px, dtype=float) - self.origin_px[1]
        c, s = math.cos(self.angle_rad), math.sin(self.angle_rad)
        along = (dx * c + dy * s) * self.metre_per_px
        across = (-dx * s + dy * c) * self.metre_per_px
        if along.ndim == 0:
            return float(along), float(across)
        return along, across

    @classmethod
    def from_scale_bar(cls, start_px: tuple[float, float], end_px: tuple[float, float], length_m: float):
        """Two image points a known distance apart; the axis points from `start_px` to `end_px`."""
        dx, dy = end_px[0] - start_px[0], end_px[1] - start_px[1]
        dist = math.hypot(dx, dy)
        if dist == 0 or not (math.isfinite(length_m) and length_m > 0):
            raise ConfigError(
                "PixelCalibration.from_scale_bar: needs two distinct points and a positive length"
            )
        return cls(length_m / dist, math.atan2(dy, dx), (float(start_px[0]), float(start_px[1])))


def fit_pixel_calibration(points_px: np.ndarray, positions_m: np.ndarray) -> PixelCalibration:
    """Fit the axis, scale and origin from marker positions (n, 2) seen at known displacements (n,), e.g. the
    stage moved in known steps: the axis is the points' principal direction, the scale a least-squares
    line."""
    pts = np.asarray(points_px, dtype=float).reshape(-1, 2)
    pos = np.asarray(positions_m, dtype=float).ravel()
    if len(pts) != len(pos) or len(pos) < 2 or np.ptp(pos) == 0:
        raise ConfigError("fit_pixel_calibration: needs >= 2 points at distinct known positions")
    if not (np.all(np.isfinite(pts)) and np.all(np.isfinite(pos))):
        raise ConfigError("fit_pixel_calibration: points and positions must be finite")
    mean = pts.mean(axis=0)
    _, _, vt = np.linalg.svd(pts - mean)
    direction = vt[0]
    proj = (pts - mean) @ direction
    slope, intercept = np.polyfit(proj, pos, 1)  # metres per pixel along `direction`
    if slope < 0:
        direction, slope = -direction, -slope
        proj = -proj
    residual = pos - (slope * proj + intercept)
    origin = mean - direction * intercept / slope
    return PixelCalibration(float(slope), float(math.atan2(direction[1], direction[0])),
                            (float(origin[0]), float(origin[1])), float(np.sqrt(np.mean(residual**2))))
