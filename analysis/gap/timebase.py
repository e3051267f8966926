"""Where a run's commands and samples sit in time: a command held between its samples (a DAQ's zero-order hold)
and read through its running integral, the mean of a combination of such staircases over a window as a function
of the window's start, and the places of sample times on a uniform grid. What `engine.RunEngine` reads the drive
and the stage through; no model here."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


def zoh(t_cmd: np.ndarray, v_cmd: np.ndarray, t: np.ndarray, before: float = 0.0) -> np.ndarray:
    """The held command at times t (`before` until its first sample)."""
    if t_cmd.size == 0:
        return np.full(t.shape, before)
    i = np.searchsorted(t_cmd, t, "right") - 1
    return np.where(i >= 0, v_cmd[np.clip(i, 0, None)], before)


class Staircase:
    """A command held between its samples (a DAQ's zero-order hold), through its running integral: the mean over
    any interval is exact wherever the interval falls relative to the steps."""

    def __init__(self, t_cmd: np.ndarray, v_cmd: np.ndarray, before: float = 0.0) -> None:
        self.t, self.v, self.before = t_cmd, v_cmd, before
        self._at = np.r_[0.0, np.cumsum(v_cmd[:-1] * np.diff(t_cmd))] if t_cmd.size else np.zeros(0)

    def integral(self, t: np.ndarray) -> np.ndarray:
        """The integral from the first sample to `t` (the value before it: `before`)."""
        if self.t.size == 0:
            return self.before * t
        i = np.searchsorted(self.t, t, "right") - 1
        k = np.maximum(i, 0)
        out = self._at[k] + self.v[k] * (t - self.t[k])
        before = i < 0
        if before.any():   # rare (a lag reaching before the first command): not computed for every sample
            out[before] = self.before * (t[before] - self.t[0])
        return out

    def mean(self, start: np.ndarray, width: float) -> np.ndarray:
        return (self.integral(start + width) - self.integral(start)) / width

    def mean_knots(self, width: float) -> np.ndarray:
        """Where the mean over [s, s + width] bends as a function of s: at the steps and `width` before them
        (between these it is linear in s, and constant beyond them)."""
        return np.union1d(self.t, self.t - width)


class WindowMean:
    """A linear combination of staircases' window means, sum c_i mean_i(s, width), as a function of the window's
    start s: piecewise linear with knots where a window edge meets a step, so one interpolation on a table of its
    values at the knots gives it exactly (in place of two binary searches per staircase at every evaluation: the
    played drive is read again whenever a fit moves a sensor lag)."""

    def __init__(self, parts: list[tuple[float, Staircase]], width: float) -> None:
        knots = np.unique(np.concatenate([st.mean_knots(width) for _, st in parts]))
        if knots.size == 0:
            knots = np.zeros(1)
        self.knots = knots
        self.values = sum(c * st.mean(knots, width) for c, st in parts)

    def __call__(self, start: np.ndarray) -> np.ndarray:
        return np.interp(start, self.knots, self.values)


@dataclass(frozen=True)
class GridPlaces:
    """Where times fall on a uniform grid x0 + dx k (k < n): each time's cell and its fraction across it, clamped
    at the ends as np.interp clamps; found by index arithmetic (no search) and kept for every drive effect a fit
    tries at the same sample times."""

    lo: np.ndarray
    hi: np.ndarray
    frac: np.ndarray

    @classmethod
    def of(cls, x: np.ndarray, x0: float, dx: float, n: int) -> GridPlaces:
        u = (x - x0) / dx
        lo = np.clip(np.floor(u), 0, n - 2).astype(np.intp)
        return cls(lo, lo + 1, np.clip(u - lo, 0.0, 1.0))

    def through(self, index: np.ndarray) -> GridPlaces:
        """The same places on a coarser grid whose node `index[k]` holds grid node k's value: interpolating the
        coarse values there is interpolating the grid's, to the bit."""
        return GridPlaces(index[self.lo], index[self.hi], self.frac)

    def interp(self, y: np.ndarray) -> np.ndarray:
        """np.interp of the grid's values y at the times."""
        a = y[self.lo]
        return a + self.frac * (y[self.hi] - a)
