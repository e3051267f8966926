"""Drive timing from a drive waveform alone: where each trapezoid cycle's low dwell, ramps and high dwell begin and
end, and its level. Used on a commanded waveform (exact samples: the corners come out exact) and on a measured
monitor (noise, a lag or an overshoot, ramps of any length, any number of cycles, data that start or end inside a
cycle), so that a recording without a command stream gets the same per-cycle windows as one with.

How (docs/log-format.md, "Drive timing"):
- noise: the robust scatter of successive differences (MAD / 0.6745 / sqrt 2); one-sample spikes and dropouts
  are removed by a 3-sample median, and noisy data are smoothed by a 5-sample moving average, before anything is
  detected (both leave ramps and flat tops unchanged; the line fits below use the raw samples);
- ground: the median of the samples near the lowest percentile; a burst is a run of smoothed samples above
  ground + max(6 x the smoothed signal's noise, 1 % of the range);
- a burst's level: the mean of the raw samples of its flat top, between the fitted corners less 5 % (and two
  samples) at each end, spikes left out; its standard error (noise / sqrt(samples)) is kept with it;
- each ramp: a least-squares line through its samples between 20 % and 80 % of the level (outliers of the raw
  signal from the filtered one left out), so a ramp of any length and a rounded or overshooting corner give the
  same corners; the corners are where the line meets ground and the level; a triangle (no flat top) gets its
  apex from the two lines' intersection; the standard error of each ramp's mid-level crossing time (from the
  noise and the samples the line rests on) is kept with the cycle;
- a burst whose rise or fall is cut by the start or end of the data is an incomplete cycle (it belongs to the
  drive's history, not to a measured cycle);
- a cycle's low dwell starts at the previous cycle's fall end, unless the pause is longer than 1.5 x the median
  pause between cycles (a pause between steps): then it is the median pause long.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

DETECT_NOISE_SIGMAS = 6.0
DETECT_FRACTION = 0.01       # of the range: a burst must rise this far above ground (and 6 noise sigmas)
EDGE_LO, EDGE_HI = 0.2, 0.8  # the part of a ramp its line is fitted to (fractions of the level above ground)
OUTLIER_SIGMAS = 5.0
PAUSE_FACTOR = 1.5           # a pause this many times the median pause is a pause between steps, not a low dwell
RINGING_FRACTION = 0.25      # a burst below this fraction of a neighbour's height, close to it, is its ringing
GAP_FACTOR = 20.0            # a sampling gap this many times the median spacing cuts the waveform
SMOOTH_SAMPLES = 5           # moving average of the detection signal on noisy data
FLAT_MARGIN = 0.05           # of the flat top, left out at each corner when its level is averaged


@dataclass(frozen=True)
class Cycle:
    """One trapezoid: low dwell [low_start, rise_start], ramp up, high dwell [high_start, fall_start], ramp down
    to fall_end. Times in s (absolute), `level_V` the high level above ground. An incomplete cycle (cut by the
    data's start or end) has the missing corners at the data's edge."""

    low_start_s: float
    rise_start_s: float
    high_start_s: float
    fall_start_s: float
    fall_end_s: float
    level_V: float
    complete: bool = True
    level_se_V: float = 0.0      # standard error of level_V (monitor noise / sqrt(samples of the flat top))
    level_samples: int = 0       # samples the level is the mean of
    rise_se_s: float = 0.0       # standard error of the rise's mid-level crossing time (0 on an exact waveform)
    fall_se_s: float = 0.0       # the same for the fall

    @property
    def dwell_low_s(self) -> float:
        return self.rise_start_s - self.low_start_s

    @property
    def ramp_up_s(self) -> float:
        return self.high_start_s - self.rise_start_s

    @property
    def dwell_high_s(self) -> float:
        return self.fall_start_s - self.high_start_s

    @property
    def ramp_down_s(self) -> float:
        return self.fall_end_s - self.fall_start_s


@dataclass(frozen=True)
class WaveformStats:
    """What the inference measured about the waveform as a whole."""

    ground_V: float
    noise_V: float
    range_V: float


def noise_sigma(x: np.ndarray) -> float:
    """White-noise sigma from successive differences (robust to the signal's own edges, which are few samples)."""
    if x.size < 3:
        return 0.0
    d = np.diff(x)
    return float(1.4826 * np.median(np.abs(d - np.median(d))) / math.sqrt(2.0))


def median3(x: np.ndarray) -> np.ndarray:
    """3-sample running median (ends kept): removes single-sample spikes and dropouts, keeps monotone runs."""
    if x.size < 3:
        return x.copy()
    out = x.copy()
    out[1:-1] = np.median(np.stack([x[:-2], x[1:-1], x[2:]]), axis=0)
    return out


def waveform_stats(v: np.ndarray) -> WaveformStats:
    """Ground level, noise and range of a drive waveform.

    Ground: on exact data the lowest level; on noisy data the 5th percentile corrected by 1.645 sigma (the 5th
    percentile of noise around ground, when the drive spends at least ~10 % of its time at ground), then the
    median of the raw samples within 2 sigma of that (a level a few sigma above ground barely reaches in)."""
    v = np.asarray(v, dtype=float)
    sigma = noise_sigma(v)
    hi = float(np.percentile(median3(v), 99.9))
    if sigma == 0.0:
        lo = float(np.min(v))
        ground = float(np.median(v[v <= lo + 1e-9 * max(hi - lo, 1.0)]))
    else:
        g0 = float(np.percentile(v, 5.0)) + 1.645 * sigma
        near = v[np.abs(v - g0) <= 2.0 * sigma]
        ground = float(np.median(near)) if near.size else g0
    return WaveformStats(ground, sigma, hi - ground)


def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    return list(zip(np.flatnonzero(d == 1).tolist(), np.flatnonzero(d == -1).tolist(), strict=True))


def _line(t: np.ndarray, v: np.ndarray) -> tuple[float, float] | None:
    """(a, b) of the least-squares line v = a + b t (fitted about t[0] for conditioning)."""
    if t.size < 2 or not np.ptp(t) > 0:
        return None
    b, a = np.polyfit(t - t[0], v, 1)
    if not (math.isfinite(a) and math.isfinite(b)) or b == 0:
        return None
    return float(a - b * t[0]), float(b)


def smoothed(v: np.ndarray, noisy: bool) -> np.ndarray:
    """The detection signal: a 3-sample median (spikes, dropouts) then, on noisy data, a SMOOTH_SAMPLES moving
    average (noise / sqrt(5), so a small step in a lot of noise is still found; a linear ramp is unchanged)."""
    vf = median3(v)
    if not noisy or vf.size < SMOOTH_SAMPLES:
        return vf
    k = SMOOTH_SAMPLES // 2
    padded = np.r_[np.full(k, vf[0]), vf, np.full(k, vf[-1])]
    return np.convolve(padded, np.ones(SMOOTH_SAMPLES) / SMOOTH_SAMPLES, mode="valid")


class _Edges:
    """Corner finding on one waveform (the smoothed signal for detection, the raw one for the line fits)."""

    def __init__(self, t: np.ndarray, v: np.ndarray, stats: WaveformStats) -> None:
        self.t, self.v = t, v
        self.vf = smoothed(v, stats.noise_V > 0)
        self.g = stats.ground_V
        self.sigma = stats.noise_V
        # a raw sample far from its neighbours' median is a spike: left out of the line fits
        self.ok = np.abs(v - median3(v)) <= max(OUTLIER_SIGMAS * self.sigma, 1e-12 * max(stats.range_V, 1.0))

    def _fit(self, i_lo: int, i_hi: int, level: float) -> tuple[float, float, float] | None:
        """Line v = c + s t through the ramp samples strictly between indices i_lo and i_hi (or through those
        two), and the standard error of the time it crosses mid-level (from the noise and the samples used)."""
        h = level - self.g
        idx = np.arange(i_lo + 1, i_hi) if i_hi > i_lo else np.arange(i_hi + 1, i_lo)
        if idx.size:
            frac = (self.vf[idx] - self.g) / h
            idx = idx[(frac > EDGE_LO - 0.05) & (frac < EDGE_HI + 0.05) & self.ok[idx]]
        fit = _line(self.t[idx], self.v[idx]) if idx.size >= 2 else None
        if fit is not None:
            tt = self.t[idx]
            t_mid = (self.g + 0.5 * h - fit[0]) / fit[1]
            sxx = float(np.sum((tt - tt.mean()) ** 2))
            se = self.sigma / abs(fit[1]) * math.sqrt(1.0 / tt.size + (t_mid - tt.mean()) ** 2 / sxx)
            return fit[0], fit[1], se
        a, b = sorted((i_lo, i_hi))
        fit = _line(self.t[[a, b]], self.vf[[a, b]])
        # two samples across the whole ramp: the crossing is known to about a sample spacing
        return None if fit is None else (fit[0], fit[1], float(self.t[b] - self.t[a]) / math.sqrt(12.0))

    def rise(self, a: int, b: int, lo_bound: int, level: float) -> tuple[float, float, float] | None:
        """(ramp start, ramp end, timing SE) of the rise into burst [a, b); None when cut by the data's start."""
        h = level - self.g
        above = np.flatnonzero(self.vf[a:b] >= self.g + EDGE_HI * h)
        if above.size == 0:
            return None
        i80 = a + int(above[0])
        below = np.flatnonzero(self.vf[lo_bound:i80 + 1] <= self.g + EDGE_LO * h)
        if below.size == 0:
            return None
        i20 = lo_bound + int(below[-1])
        fit = self._fit(i20, i80, level)
        if fit is None or fit[1] <= 0:
            return None
        c, s, se = fit
        return (self.g - c) / s, (level - c) / s, se

    def fall(self, a: int, b: int, hi_bound: int, level: float) -> tuple[float, float, float] | None:
        """(ramp start, ramp end, timing SE) of the fall out of burst [a, b); None when cut by the data's end."""
        h = level - self.g
        above = np.flatnonzero(self.vf[a:b] >= self.g + EDGE_HI * h)
        if above.size == 0:
            return None
        i80 = a + int(above[-1])
        below = np.flatnonzero(self.vf[i80:hi_bound] <= self.g + EDGE_LO * h)
        if below.size == 0:
            return None
        i20 = i80 + int(below[0])
        fit = self._fit(i80, i20, level)
        if fit is None or fit[1] >= 0:
            return None
        c, s, se = fit
        return (level - c) / s, (self.g - c) / s, se


def _bursts(vf: np.ndarray, stats: WaveformStats) -> list[tuple[int, int]]:
    noise = stats.noise_V / math.sqrt(SMOOTH_SAMPLES)   # of the smoothed signal
    thr = stats.ground_V + max(DETECT_NOISE_SIGMAS * noise, DETECT_FRACTION * stats.range_V)
    runs = _segments(vf > thr)
    # noise on a slow ramp can dip back under the threshold: runs between which the signal never came down to
    # half the threshold are one burst
    floor = stats.ground_V + 0.5 * (thr - stats.ground_V)
    merged: list[tuple[int, int]] = []
    for a, b in runs:
        if merged and float(np.min(vf[merged[-1][1]:a])) > floor:
            merged[-1] = (merged[-1][0], b)
        else:
            merged.append((a, b))
    runs = merged
    if len(runs) < 2:
        return runs
    heights = [float(np.max(vf[a:b])) - stats.ground_V for a, b in runs]
    keep = []
    for k, (a, b) in enumerate(runs):
        # ringing after an edge, or a glitch: small and short next to a neighbour, and closer to it than that
        # neighbour is long (a real cycle at a low level lasts as long as its neighbours)
        spurious = False
        for j in (k - 1, k + 1):
            if 0 <= j < len(runs) and heights[k] < RINGING_FRACTION * heights[j]:
                ja, jb = runs[j]
                gap = a - jb if j < k else ja - b
                if gap <= (jb - ja) and (b - a) < RINGING_FRACTION * (jb - ja):
                    spurious = True
        if not spurious:
            keep.append((a, b))
    return keep


def _snap(x: float, t: np.ndarray, tol: float) -> float:
    """A corner within `tol` of a sample time is that sample time (exact waveforms: corners on samples)."""
    i = int(np.searchsorted(t, x))
    for j in (i - 1, i):
        if 0 <= j < t.size and abs(t[j] - x) <= tol:
            return float(t[j])
    return float(x)


def _segment_cycles(t: np.ndarray, v: np.ndarray, stats: WaveformStats
                    ) -> list[tuple[float, float, float, float, float, bool, int, tuple[float, float]]]:
    """(rise start, high start, fall start, fall end, level above ground, complete, samples in the level) per
    burst of one gap-free stretch of samples."""
    edges = _Edges(t, v, stats)
    bursts = _bursts(edges.vf, stats)
    exact = stats.noise_V == 0.0
    dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    out = []
    for k, (a, b) in enumerate(bursts):
        lo_bound = bursts[k - 1][1] if k else 0
        hi_bound = bursts[k + 1][0] if k + 1 < len(bursts) else t.size
        top = np.percentile(edges.vf[a:b], 90)
        level = float(np.median(edges.vf[a:b][edges.vf[a:b] >= stats.ground_V + 0.9 * (top - stats.ground_V)]))
        rise = fall = None
        n_flat = 0
        for _ in range(2):   # corners from the level, then the level from the samples between the corners
            rise = edges.rise(a, b, lo_bound, level)
            fall = edges.fall(a, b, hi_bound, level)
            lo_t = rise[1] if rise else t[a]
            hi_t = fall[0] if fall else t[b - 1]
            # the raw samples of the flat top, less a margin at each corner (a monitor rings there), less spikes
            margin = max(2.0 * dt, FLAT_MARGIN * (hi_t - lo_t))
            flat = (t >= lo_t + margin) & (t <= hi_t - margin) & edges.ok
            if flat.sum() < 3:
                break
            level, n_flat = float(np.mean(v[flat])), int(flat.sum())
        rise_start, high_start = rise[:2] if rise else (float(t[0]), float(t[0]))
        fall_start, fall_end = fall[:2] if fall else (float(t[-1]), float(t[-1]))
        timing_se = (rise[2] if rise else math.nan, fall[2] if fall else math.nan)
        if rise and fall and high_start > fall_start:
            # no flat top (a triangle): the apex is where the two ramp lines meet
            s_up = (level - stats.ground_V) / (high_start - rise_start)
            s_down = (stats.ground_V - level) / (fall_end - fall_start)
            apex = (s_up * rise_start - s_down * fall_end) / (s_up - s_down)
            apex = min(max(apex, rise_start), fall_end)
            level = stats.ground_V + s_up * (apex - rise_start)
            high_start = fall_start = apex
        if exact:
            tol = 1e-9 * max(dt, 1e-9) + 1e-12
            rise_start, high_start, fall_start, fall_end = (_snap(x, t, tol)
                                                            for x in (rise_start, high_start, fall_start, fall_end))
        out.append((rise_start, high_start, fall_start, fall_end, level - stats.ground_V,
                    rise is not None and fall is not None, n_flat, timing_se))
    return out


def infer_cycles(time_s: np.ndarray, volts: np.ndarray, start_s: float | None = None,
                 stats: WaveformStats | None = None) -> list[Cycle]:
    """The trapezoid cycles of a drive waveform (see the module docstring), complete or not, in time order.

    `start_s`: where the waveform began (a commanded drive's first sample); the first cycle's low dwell starts
    there at the earliest. Default: the first sample. A gap in the sampling longer than GAP_FACTOR x the median
    sample spacing (e.g. between two specimens' data) cuts the waveform: a cycle across it is incomplete."""
    t = np.asarray(time_s, dtype=float)
    v = np.asarray(volts, dtype=float)
    ok = np.isfinite(t) & np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size < 3:
        return []
    stats = stats or waveform_stats(v)
    if not stats.range_V > max(10.0 * stats.noise_V, 1e-9):
        return []
    dts = np.diff(t)
    cuts = np.flatnonzero(dts > GAP_FACTOR * float(np.median(dts))) + 1
    bounds = [0, *cuts.tolist(), t.size]
    raw: list[tuple[float, float, float, float, float, bool, int, tuple[float, float]]] = []
    seg_of: list[int] = []
    for k in range(len(bounds) - 1):
        a, b = bounds[k], bounds[k + 1]
        if b - a >= 3:
            found = _segment_cycles(t[a:b], v[a:b], stats)
            raw += found
            seg_of += [k] * len(found)
    pauses = [raw[k][0] - raw[k - 1][3] for k in range(1, len(raw))
              if raw[k][5] and raw[k - 1][5] and seg_of[k] == seg_of[k - 1]]
    typical = float(np.median(pauses)) if pauses else None
    cycles = []
    for k, (rs, hs, fs, fe, level, complete, n_flat, (rise_se, fall_se)) in enumerate(raw):
        if k and seg_of[k] == seg_of[k - 1]:
            before = raw[k - 1][3]
        else:
            seg_start = float(t[bounds[seg_of[k]]])
            before = seg_start if start_s is None or seg_of[k] else min(float(start_s), seg_start)
        low = before
        if typical is not None and rs - before > PAUSE_FACTOR * typical:
            low = rs - typical
        low = min(max(low, before), rs)
        se = stats.noise_V / math.sqrt(n_flat) if n_flat else math.nan
        exact = stats.noise_V == 0
        cycles.append(Cycle(low, rs, hs, fs, fe, level, complete, 0.0 if exact else se, n_flat,
                            0.0 if exact else rise_se, 0.0 if exact else fall_se))
    return cycles
