"""What the other lab's instruments add: the room's temperature, the force sensor's thermal drift and 1/f
wander (the drift effect), its filter, lag, noise and sample rate, a push-only or bonded contact, a
calibration error (a decoy), and a camera that tracks the tip at its own frame rate with exposure averaging
and pixel noise.

Drift form (in neither column of the project's table): the sensor's temperature follows the room (a drawn
profile: a slow trend plus an air-conditioning cycle) and its own electronics warming up, both through a
first-order thermal lag, times a temperature coefficient; plus pink (1/f) noise shaped in the frequency
domain. The sensor is tared once per mounting, so the baseline is its change since the tare.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter

SESSION_GRID_S = 0.05


@dataclass(frozen=True)
class RoomTemperature:
    trend_K_per_h: float
    hvac_K: float
    hvac_period_s: float
    hvac_phase: float

    def at(self, t_session_s: np.ndarray) -> np.ndarray:
        return (self.trend_K_per_h * t_session_s / 3600.0
                + self.hvac_K * np.sin(2 * np.pi * t_session_s / self.hvac_period_s + self.hvac_phase))


@dataclass(frozen=True)
class ThermalDrift:
    """Force baseline = coupling x (sensor temperature) + pink wander. The sensor temperature relaxes with
    `sensor_tau_s` toward the room plus an electronics warm-up of `warmup_K` (switched on at session time 0,
    time constant `warmup_tau_s`)."""

    coupling_N_per_K: float
    sensor_tau_s: float
    warmup_K: float
    warmup_tau_s: float
    pink_N: float

    def baseline(self, room: RoomTemperature, session_s: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
        """(session time grid, baseline force) over [0, session_s]."""
        t = np.arange(0.0, session_s + 10 * SESSION_GRID_S, SESSION_GRID_S)
        drive_K = room.at(t) + self.warmup_K * (1.0 - np.exp(-t / self.warmup_tau_s))
        a = np.exp(-SESSION_GRID_S / self.sensor_tau_s)
        sensor_K = lfilter([1.0 - a], [1.0, -a], drive_K, zi=[a * drive_K[0]])[0]
        return t, self.coupling_N_per_K * sensor_K + self.pink_N * pink_noise(t.size, seed)


def pink_noise(n: int, seed: int) -> np.ndarray:
    """Unit-RMS noise with a 1/f power spectrum (white noise shaped by 1/sqrt(f) in the frequency domain)."""
    rng = np.random.default_rng(seed)
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n)
    shape = np.zeros_like(f)
    shape[1:] = 1.0 / np.sqrt(f[1:])
    x = np.fft.irfft(spectrum * shape, n)
    return x / (x.std() or 1.0)


@dataclass(frozen=True)
class ForceSensor:
    """noise_N per sample (white, before the filter's smoothing is accounted: the RMS is set after it),
    filter_s (first-order anti-alias / load-cell response), lag_s (timestamps late by this), every
    `decimation`-th row carries a reading, `scale` (1 = calibrated; a decoy when off), push_only (the tip
    rests on the button) or bonded (reads pull too), resolution_N (quantisation)."""

    kind: str
    noise_N: float
    filter_s: float
    lag_s: float
    decimation: int
    scale: float
    push_only: bool
    resolution_N: float

    def read(self, t: np.ndarray, force_N: np.ndarray, baseline_N: np.ndarray, rng: np.random.Generator
             ) -> np.ndarray:
        dt = float(t[1] - t[0])
        a = np.exp(-dt / self.filter_s)
        seen = lfilter([1.0 - a], [1.0, -a], self.scale * force_N + baseline_N, zi=[a * baseline_N[0]])[0]
        seen = np.interp(t - self.lag_s, t, seen)
        noisy = seen + self.noise_N * rng.standard_normal(t.size)
        return np.round(noisy / self.resolution_N) * self.resolution_N


@dataclass(frozen=True)
class Camera:
    """Frames every `decimation` rows, each the mean tip position over `exposure_rows` rows before it, plus
    pixel noise; `offset_m` is where the tracker's reference happens to be."""

    decimation: int
    exposure_rows: int
    noise_m: float
    offset_m: float

    def read(self, displacement_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        c = np.cumsum(np.r_[0.0, displacement_m])
        k = self.exposure_rows
        mean = np.empty(displacement_m.size)
        mean[k - 1:] = (c[k:] - c[:-k]) / k
        mean[:k - 1] = displacement_m[:k - 1]
        out = np.full(displacement_m.size, np.nan)
        frames = np.arange(0, displacement_m.size, self.decimation)
        out[frames] = mean[frames] + self.offset_m + self.noise_m * rng.standard_normal(frames.size)
        return out
