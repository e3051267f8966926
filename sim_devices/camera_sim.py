"""The simulated camera: a frame source with the surface of OpenCV's `cv2.VideoCapture` (read / grab /
retrieve / set / get / isOpened / release) that renders the tracking marker where the bench says it is.

Image model (in electrons, then digitised), chosen so that its Fisher information, hence the Cramer-Rao bound
of any position estimate, is computable exactly (`expected_electrons`, `pixel_variance_e2`):
- the marker's image is a 2-D Gaussian spot of width `spot_sigma_px` (marker and optics together), integrated
  over each pixel (pixel centres at integer coordinates, OpenCV's convention), with `spot_e_per_s x exposure`
  electrons in total, on a uniform background of `background_e_per_pixel_per_s x exposure`;
- motion blur: the spot is averaged over `motion_samples` positions spread across the exposure, asked of the
  bench's `marker_px(time_s) -> (x, y)` callback (or, if the callback has `vectorised = True`, with the array of
  those times at once, returning shape (n, 2));
- shot noise (Poisson), read noise (Gaussian, `read_noise_e`), then `gain_DN_per_e`, rounding and clipping to
  `bit_depth` (uint8 or uint16).

Background noise: a full frame of exact draws costs more than the rest of a frame together, so the camera draws a
pool of `BACKGROUND_POOL_FRAMES` frames' worth of background pixels (from `background_dn_table`, the exact
distribution) once per exposure setting, and each frame's background is a window into it at a random offset. Every
pixel's distribution is exact and pixels within a frame are independent; two frames share values only as a copy
shifted by the difference of their offsets. The patch around the marker (out to `spot_reach_px`, where the spot
adds less than a thousandth of an electron to a pixel) is drawn afresh for every frame with `digitise`, so what
tracking sees is unaffected.

Timing on the bench's clock: frame k is exposed over [k / fps, k / fps + exposure]; `read()` returns the next
frame and, if its exposure has not ended, waits (through the clock) until it has. A reader that falls more
than `buffer_frames` behind loses the oldest frames, as a driver's ring buffer does. `get(CAP_PROP_POS_MSEC)`
is the exposure mid-time of the last frame in ms on the bench clock; `get(CAP_PROP_POS_FRAMES)` is its index +
1 (the next frame, as for a video file), so a lost frame shows as an index gap.

Not modelled: rolling shutter, pixel response non-uniformity, dark-current growth with exposure beyond the
background term, lens distortion, colour, hardware ROI (the driver crops), auto exposure.

Faults (`inject_fault`): 'dropped_frames' (each frame lost with probability `strength`), 'disconnect' (read
fails and isOpened() turns false), 'no_reply' (read waits out the read timeout, then fails).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from scipy.special import ndtr, ndtri

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError
from sim_devices.faults import CAMERA_FAULTS, FaultInjector


@dataclass(frozen=True)
class SimCameraSpec:
    """Sensor, optics and light. Defaults: a PL-B741F-like mono sensor (modes and rates UNVERIFIED) looking at
    a bright marker."""

    width_px: int = 640
    height_px: int = 480
    frame_rate_Hz: float = 60.0
    exposure_s: float = 2e-3
    # (width, height, max frame rate)
    modes: tuple[tuple[int, int, float], ...] = ((1280, 1024, 27.0), (640, 480, 60.0), (320, 240, 120.0))
    spot_sigma_px: float = 2.0
    spot_e_per_s: float = 2.0e6
    background_e_per_pixel_per_s: float = 1.0e4
    read_noise_e: float = 5.0
    gain_DN_per_e: float = 0.1
    bit_depth: int = 8
    motion_samples: int = 5
    buffer_frames: int = 4
    read_timeout_s: float = 1.0
    exposure_unit_s: float = 1e-4  # CAP_PROP_EXPOSURE unit (V4L2 exposure_absolute is in 100 us)

    def __post_init__(self) -> None:
        if (self.width_px, self.height_px) not in [(w, h) for w, h, _ in self.modes]:
            raise ConfigError(
                f"SimCameraSpec: {self.width_px}x{self.height_px} is not one of the modes {self.modes}"
            )
        for name in ("frame_rate_Hz", "exposure_s", "spot_sigma_px", "gain_DN_per_e", "read_timeout_s"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ConfigError(f"SimCameraSpec.{name}: must be positive, got {getattr(self, name)!r}")
        if self.bit_depth not in (8, 10, 12, 16):
            raise ConfigError(f"SimCameraSpec.bit_depth: 8, 10, 12 or 16, got {self.bit_depth}")


def pixel_profile(n_px: int, centre_px: np.ndarray, sigma_px: float, start_px: int = 0) -> np.ndarray:
    """Fraction of a 1-D Gaussian (centres `centre_px`, shape (k,)) falling in each of the pixels
    `start_px .. start_px + n_px - 1`, pixel i spanning [i - 1/2, i + 1/2): shape (k, n_px)."""
    edges = np.arange(start_px, start_px + n_px + 1) - 0.5
    edges = edges[None, :] - np.asarray(centre_px, dtype=float)[:, None]
    cdf = ndtr(edges / sigma_px)
    return np.diff(cdf, axis=1)


def expected_electrons(
    spec: SimCameraSpec,
    positions_px: np.ndarray,
    exposure_s: float,
    shape: tuple[int, int] | None = None,
    origin_px: tuple[int, int] = (0, 0),
) -> np.ndarray:
    """Mean electrons per pixel for a spot averaged over `positions_px` (k, 2) = (x, y) during `exposure_s`,
    on the pixels of a `shape` = (height, width) patch whose top-left pixel is `origin_px` = (x, y)."""
    height, width = shape if shape is not None else (spec.height_px, spec.width_px)
    pos = np.atleast_2d(np.asarray(positions_px, dtype=float))
    px = pixel_profile(width, pos[:, 0], spec.spot_sigma_px, origin_px[0])
    py = pixel_profile(height, pos[:, 1], spec.spot_sigma_px, origin_px[1])
    spot = py.T @ px / len(pos)  # (h, w): the motion samples' outer products, averaged
    return spec.background_e_per_pixel_per_s * exposure_s + spec.spot_e_per_s * exposure_s * spot


def pixel_variance_e2(spec: SimCameraSpec, mean_e: np.ndarray) -> np.ndarray:
    """Per-pixel noise variance in electrons^2: shot + read + quantisation (uniform, step 1/gain)."""
    return mean_e + spec.read_noise_e**2 + 1.0 / (12.0 * spec.gain_DN_per_e**2)


def digitise(spec: SimCameraSpec, mean_e: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Exact noise model on a patch: Poisson electrons + Gaussian read noise, x gain, rounded, clipped."""
    electrons = rng.poisson(mean_e).astype(np.float64)
    if spec.read_noise_e > 0:
        electrons += rng.normal(0.0, spec.read_noise_e, mean_e.shape)
    dn = np.clip(np.rint(electrons * spec.gain_DN_per_e), 0, 2**spec.bit_depth - 1)
    return dn.astype(np.uint8 if spec.bit_depth == 8 else np.uint16)


_LUT_BITS = 16
BACKGROUND_POOL_FRAMES = 16


def background_dn_table(spec: SimCameraSpec, mean_e: float) -> np.ndarray:
    """Inverse CDF (2**16 equiprobable entries) of the digitised value of a pixel that sees only the
    background: the same distribution `digitise` draws from (Poisson * Gaussian read noise, then rounding and
    clipping), tabulated so that a full frame costs one integer draw per pixel instead of a Poisson and a
    Gaussian draw."""
    full_scale = 2**spec.bit_depth - 1
    kmax = int(mean_e + 12 * math.sqrt(mean_e + 1) + 20)
    k = np.arange(kmax + 1)
    pk = np.exp(k * math.log(max(mean_e, 1e-300)) - mean_e - np.array([math.lgamma(i + 1) for i in k]))
    dn = np.arange(full_scale + 1)
    if spec.read_noise_e > 0:
        lo = np.where(dn == 0, -np.inf, (dn - 0.5) / spec.gain_DN_per_e)
        hi = np.where(dn == full_scale, np.inf, (dn + 0.5) / spec.gain_DN_per_e)
        pd = (ndtr((hi[None, :] - k[:, None]) / spec.read_noise_e)
              - ndtr((lo[None, :] - k[:, None]) / spec.read_noise_e)).T @ pk
    else:
        dn_of_k = np.clip(np.rint(k * spec.gain_DN_per_e), 0, full_scale).astype(int)
        pd = np.bincount(dn_of_k, pk, full_scale + 1)
    cdf = np.cumsum(pd) / pd.sum()
    u = (np.arange(2**_LUT_BITS) + 0.5) / 2**_LUT_BITS
    table = np.minimum(np.searchsorted(cdf, u), full_scale)
    return table.astype(np.uint8 if spec.bit_depth == 8 else np.uint16)


def draw_background(table: np.ndarray, n_pixels: int, rng: np.random.Generator) -> np.ndarray:
    """`n_pixels` independent background values (flat) from a `background_dn_table`."""
    # np.take: the same lookup as table[indices], at about 60 % of the cost of fancy indexing on a full frame
    return np.take(table, rng.integers(0, 2**_LUT_BITS, size=n_pixels, dtype=np.uint16))


# Beyond the patch drawn with `digitise`, the spot may add at most this many electrons to a pixel: a thousandth of
# an electron is 1e-4 of a grey level at the default gain, against a background noise of ~13 electrons.
SPOT_TAIL_E = 1e-3


def spot_reach_px(spec: SimCameraSpec, exposure_s: float) -> int:
    """Half-width of the patch around the spot's path, in pixels: a pixel outside it has its near edge at least
    `reach - 1` from every motion sample, so it holds at most the 1-D tail fraction Q((reach - 1) / sigma) of the
    spot's electrons; the reach makes that at most `SPOT_TAIL_E`."""
    total_e = spec.spot_e_per_s * exposure_s
    if total_e <= SPOT_TAIL_E:
        return 1
    return int(math.ceil(-ndtri(SPOT_TAIL_E / total_e) * spec.spot_sigma_px)) + 1


def render_frame(spec: SimCameraSpec, positions_px: np.ndarray, exposure_s: float, shape: tuple[int, int],
                 rng: np.random.Generator, table: np.ndarray | None = None,
                 background_pool: np.ndarray | None = None) -> np.ndarray:
    """A noisy frame: background pixels from `background_dn_table` (fresh draws, or a window at a random offset
    into `background_pool`, see the module docstring), and the patch where the spot (over its motion path, out to
    `spot_reach_px`, beyond which it adds < `SPOT_TAIL_E` electrons to a pixel) is drawn with `digitise`."""
    height, width = shape
    n = height * width
    if background_pool is not None and background_pool.size >= n:
        offset = int(rng.integers(0, background_pool.size - n + 1))
        image = background_pool[offset:offset + n].reshape(shape).copy()
    else:
        if table is None:
            table = background_dn_table(spec, spec.background_e_per_pixel_per_s * exposure_s)
        image = draw_background(table, n, rng).reshape(shape)
    pos = np.atleast_2d(np.asarray(positions_px, dtype=float))
    reach = spot_reach_px(spec, exposure_s)
    x0 = max(int(math.floor(pos[:, 0].min())) - reach, 0)
    x1 = min(int(math.ceil(pos[:, 0].max())) + reach + 1, width)
    y0 = max(int(math.floor(pos[:, 1].min())) - reach, 0)
    y1 = min(int(math.ceil(pos[:, 1].max())) + reach + 1, height)
    if x1 > x0 and y1 > y0:
        mean_e = expected_electrons(spec, pos, exposure_s, (y1 - y0, x1 - x0), (x0, y0))
        image[y0:y1, x0:x1] = digitise(spec, mean_e, rng)
    return image


class SimCamera:
    """A `cv2.VideoCapture`-like camera on the bench clock (see the module docstring)."""

    def __init__(
        self,
        clock: Clock,
        rng: np.random.Generator,
        marker_px: Callable[[float], Sequence[float]] | Callable[[np.ndarray], np.ndarray],
        spec: SimCameraSpec = SimCameraSpec(),
    ) -> None:
        self._clock = clock
        self._rng = rng
        self._marker_px = marker_px
        self._spec = spec
        self._width, self._height = spec.width_px, spec.height_px
        self._fps = spec.frame_rate_Hz
        self._exposure_s = min(spec.exposure_s, 1.0 / self._fps)
        self._read_timeout_s = spec.read_timeout_s
        self._opened = True
        self._last_index = -1
        self._last_mid_s = 0.0
        self._pending: np.ndarray | None = None
        self._faults = FaultInjector(CAMERA_FAULTS, "sim camera", clock)
        self._drop_probability = 0.0
        self.frames_lost = 0
        self._table: np.ndarray | None = None
        self._pool: np.ndarray | None = None
        self._table_key: tuple[float, float, int, int] | None = None

    # ---- faults --------------------------------------------------------------------------------------------
    def inject_fault(self, name: str, strength: float = 1.0, at_s: float | None = None) -> None:
        """Switch a fault on now (or at `at_s`); for 'dropped_frames' `strength` is the per-frame loss
        probability (capped at 0.99)."""
        self._faults.inject(name, self._clock.now_s() if at_s is None else float(at_s))
        if name == "dropped_frames":
            self._drop_probability = min(max(float(strength), 0.0), 0.99)

    def clear_fault(self, name: str) -> None:
        self._faults.clear(name)

    def _active(self, name: str) -> bool:
        return self._faults.is_active(name, self._clock.now_s())

    # ---- VideoCapture surface ------------------------------------------------------------------------------
    def isOpened(self) -> bool:  # noqa: N802 (OpenCV's name)
        if self._active("disconnect"):
            self._opened = False  # a camera that went away stays away
        return self._opened

    def release(self) -> None:
        self._opened = False

    def grab(self) -> bool:
        if not self.isOpened():
            return False
        if self._active("no_reply"):
            self._clock.sleep(self._read_timeout_s)
            return False
        fps, exposure = self._fps, self._exposure_s
        k = self._last_index + 1
        now = self._clock.now_s()
        newest_done = math.floor((now - exposure) * fps + 1e-9)
        if newest_done - k >= self._spec.buffer_frames:  # overwritten in the ring buffer
            k = newest_done - self._spec.buffer_frames + 1
        p = self._drop_probability if self._active("dropped_frames") else 0.0
        while p > 0 and self._rng.random() < p:
            k += 1
        start_s = k / fps
        end_s = start_s + exposure
        if end_s - now > self._read_timeout_s:
            # A capture read gives up after its timeout (CAP_PROP_READ_TIMEOUT_MSEC) rather than block until a
            # camera that loses most frames delivers one: the caller must not be stuck longer than it asked.
            self._clock.sleep(self._read_timeout_s)
            return False
        self.frames_lost += k - self._last_index - 1
        if end_s > now:
            self._clock.sleep(end_s - now)
        m = self._spec.motion_samples
        times = start_s + (np.arange(m) + 0.5) / m * exposure
        if getattr(self._marker_px, "vectorised", False):  # one call for the exposure's motion samples
            many = cast(Callable[[np.ndarray], np.ndarray], self._marker_px)  # declared vectorised
            positions = np.asarray(many(times), dtype=float).reshape(m, 2)
        else:
            one = cast(Callable[[float], Sequence[float]], self._marker_px)
            positions = np.array([one(float(t)) for t in times], dtype=float).reshape(m, 2)
        key = (exposure, self._spec.background_e_per_pixel_per_s, self._height, self._width)
        if self._table_key != key:
            self._table = background_dn_table(self._spec, exposure * self._spec.background_e_per_pixel_per_s)
            self._pool = draw_background(self._table, BACKGROUND_POOL_FRAMES * self._height * self._width,
                                         self._rng)
            self._table_key = key
        self._pending = render_frame(self._spec, positions, exposure, (self._height, self._width), self._rng,
                                     self._table, self._pool)
        self._last_index = k
        self._last_mid_s = start_s + exposure / 2
        return True

    def retrieve(self, image=None, flag: int = 0):
        if self._pending is None:
            return False, None
        return True, self._pending

    def read(self, image=None):
        if not self.grab():
            return False, None
        return self.retrieve()

    def get(self, prop: int) -> float:
        values = {
            cv2.CAP_PROP_FRAME_WIDTH: float(self._width),
            cv2.CAP_PROP_FRAME_HEIGHT: float(self._height),
            cv2.CAP_PROP_FPS: float(self._fps),
            cv2.CAP_PROP_EXPOSURE: self._exposure_s / self._spec.exposure_unit_s,
            cv2.CAP_PROP_AUTO_EXPOSURE: 1.0,  # V4L2: 1 = manual
            cv2.CAP_PROP_POS_MSEC: self._last_mid_s * 1e3,
            cv2.CAP_PROP_POS_FRAMES: float(self._last_index + 1),
            cv2.CAP_PROP_READ_TIMEOUT_MSEC: self._read_timeout_s * 1e3,
        }
        return values.get(prop, 0.0)

    def set(self, prop: int, value: float) -> bool:
        """Like V4L2 through OpenCV: an unsupported value is ignored (read it back to know)."""
        if not self._opened or not math.isfinite(value):
            return False
        if prop == cv2.CAP_PROP_FRAME_WIDTH:
            return self._set_mode(int(value), self._height) or self._set_mode(int(value), None)
        if prop == cv2.CAP_PROP_FRAME_HEIGHT:
            return self._set_mode(self._width, int(value)) or self._set_mode(None, int(value))
        if prop == cv2.CAP_PROP_FPS:
            if 0 < value <= self._max_fps():
                self._fps = float(value)
                self._exposure_s = min(self._exposure_s, 1.0 / self._fps)
                return True
            return False
        if prop == cv2.CAP_PROP_EXPOSURE:
            exposure_s = value * self._spec.exposure_unit_s
            if exposure_s <= 0:
                return False
            self._exposure_s = min(exposure_s, 1.0 / self._fps)  # clamped, as cameras do: read it back
            return True
        if prop == cv2.CAP_PROP_AUTO_EXPOSURE:
            return value == 1.0
        if prop == cv2.CAP_PROP_READ_TIMEOUT_MSEC and value > 0:
            self._read_timeout_s = value / 1e3
            return True
        return False

    def _max_fps(self) -> float:
        return next(f for w, h, f in self._spec.modes if (w, h) == (self._width, self._height))

    def _set_mode(self, width: int | None, height: int | None) -> bool:
        for w, h, _ in self._spec.modes:
            if (width is None or w == width) and (height is None or h == height):
                self._width, self._height = w, h
                self._fps = min(self._fps, self._max_fps())
                self._exposure_s = min(self._exposure_s, 1.0 / self._fps)
                return True
        return False
