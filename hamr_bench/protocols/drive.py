"""The trapezoid drive the paper uses: the drive channel goes ground -> bias -> ground with finite ramps, because a
square wave would excite the actuator resonance. Pure function of its parameters."""

from __future__ import annotations

import numpy as np

from hamr_bench.errors import ConfigError


def trapezoid_V(
    bias_V: float,
    ramp_s: float,
    dwell_high_s: float,
    dwell_low_s: float,
    cycles: int,
    sample_rate_Hz: float,
) -> np.ndarray:
    """Samples of `cycles` trapezoids: low dwell at 0 V, ramp up, high dwell at `bias_V`, ramp down; ends at 0 V.

    The low dwell comes first so every cycle starts from rest at ground."""
    for name, value in (("ramp_s", ramp_s), ("dwell_high_s", dwell_high_s), ("dwell_low_s", dwell_low_s)):
        if not np.isfinite(value) or value < 0:
            raise ConfigError(f"drive {name}: expected a non-negative time, got {value!r}")
    if ramp_s <= 0:
        raise ConfigError(f"drive ramp_s: must be positive (a step excites the actuator resonance), got {ramp_s!r}")
    if cycles < 1:
        raise ConfigError(f"drive cycles: expected at least 1, got {cycles!r}")
    if not sample_rate_Hz > 0:
        raise ConfigError(f"drive sample_rate_Hz: expected a positive rate, got {sample_rate_Hz!r}")
    period_s = 2 * ramp_s + dwell_high_s + dwell_low_s
    t = np.arange(int(round(cycles * period_s * sample_rate_Hz)) + 1) / sample_rate_Hz
    phase = np.mod(t, period_s)
    rise_start, high_start = dwell_low_s, dwell_low_s + ramp_s
    fall_start, fall_end = high_start + dwell_high_s, high_start + dwell_high_s + ramp_s
    level = np.interp(phase, [0.0, rise_start, high_start, fall_start, fall_end, period_s], [0, 0, 1, 1, 0, 0])
    level[-1] = 0.0
    return bias_V * level


def phase_labels(
    time_s: np.ndarray, ramp_s: float, dwell_high_s: float, dwell_low_s: float
) -> np.ndarray:
    """Label each time since the waveform start as 'low', 'rise', 'high' or 'fall' (the gap diagnosis maps
    residuals by phase)."""
    period_s = 2 * ramp_s + dwell_high_s + dwell_low_s
    phase = np.mod(np.asarray(time_s, dtype=float), period_s)
    edges = np.cumsum([dwell_low_s, ramp_s, dwell_high_s, ramp_s])
    names = np.array(["low", "rise", "high", "fall", "low"])
    return names[np.searchsorted(edges, phase, side="right")]
