"""Exact, vectorised solutions of the linear systems the simulated bench integrates on its time grid: a first-order
linear recursion (y[n] = a y[n-1] + d[n], real or complex a) evaluated block-wise with numpy instead of a Python
loop, a first-order lag and a damped second-order mode driven by an input that is linear between grid points
(first-order hold), both discretised exactly (no step-size error), with the response between grid points and its
integral over a grid step in closed form.

Why exact discretisation: the bench's modes span 100 Hz (a loaded leg) to several kHz (a sensor carrying the
foot), and its grid is 0.25 ms; an explicit integrator would need steps far below the fastest period, the exact
one is right at any step (for a piecewise-linear input). Why closed-form values between grid points: a DAQ samples
instantaneous force, and a mode faster than the grid would alias if read off the grid points by interpolation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# |a|^k must stay representable while a block is summed: chunks keep |a|^-k below 1e150.
_CHUNK_LOG_RANGE = math.log(1e150)
# Below this |a|^k for k taps the remaining terms are beneath double precision: a short FIR is exact enough.
_FIR_LOG_FLOOR = math.log(1e-17)
_FIR_MAX_TAPS = 24


def first_order_recursion(a: complex | float, drive: np.ndarray, y0: complex | float) -> np.ndarray:
    """y[n] = a y[n-1] + drive[n] for n = 0..N-1 with y[-1] = y0 (a, drive and y0 real or complex).

    Vectorised: within a chunk, y[k] = a^(k+1) (y_before + sum_{j<=k} drive[j] a^-(j+1)); the chunk length keeps
    the scaled terms finite. A fast-decaying |a| (a memory shorter than 24 samples) is a truncated FIR instead."""
    d = np.asarray(drive)
    n = d.shape[0]
    dtype = np.result_type(d, a, y0, float)
    out = np.empty(n, dtype=dtype)
    if n == 0:
        return out
    mag = abs(a)
    if mag == 0.0:
        out[:] = d
        return out
    log_mag = math.log(mag)
    if log_mag < 0 and _FIR_LOG_FLOOR / log_mag <= _FIR_MAX_TAPS:
        taps = int(math.ceil(_FIR_LOG_FLOOR / log_mag))
        out[:] = d
        power = 1.0 + 0.0 * a
        for m in range(1, taps + 1):
            power = power * a
            if m < n:
                out[m:] += power * d[:-m]
            # the initial state's share: a^(k+1) y0 for the first samples
        k = np.arange(min(n, taps + 1))
        out[: k.size] += (a ** (k + 1)) * y0
        return out
    chunk = n if log_mag >= 0 else max(1, int(_CHUNK_LOG_RANGE / -log_mag))
    if log_mag > 0:   # a growing recursion (never used by the bench, kept correct): short chunks
        chunk = max(1, int(_CHUNK_LOG_RANGE / log_mag))
    y_before = y0
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        k = np.arange(1, stop - start + 1)
        powers = a ** k
        out[start:stop] = powers * (y_before + np.cumsum(d[start:stop] / powers))
        y_before = out[stop - 1]
    return out


@dataclass(frozen=True)
class FirstOrderLag:
    """dz/dt = (x - z) / tau, x linear between grid points of spacing h: the exact update
    z[n+1] = a z[n] + b0 x[n] + b1 x[n+1]."""

    tau_s: float
    h_s: float

    def __post_init__(self) -> None:
        if not (self.tau_s > 0 and self.h_s > 0):
            raise ValueError(f"FirstOrderLag needs tau_s > 0 and h_s > 0, got {self.tau_s!r}, {self.h_s!r}")

    @property
    def coefficients(self) -> tuple[float, float, float]:
        r = self.h_s / self.tau_s
        a = math.exp(-r)
        one_minus_a = -math.expm1(-r)
        b1 = 1.0 - one_minus_a / r
        b0 = one_minus_a / r - a
        return a, b0, b1

    def run(self, x_prev: float, x: np.ndarray, z0: float) -> np.ndarray:
        """z at the grid points of `x` (x_prev is the input at the step before x[0], z0 the state there)."""
        a, b0, b1 = self.coefficients
        xs = np.concatenate([[x_prev], np.asarray(x, dtype=float)])
        return first_order_recursion(a, b0 * xs[:-1] + b1 * xs[1:], z0)


@dataclass(frozen=True)
class SecondOrderMode:
    """One damped mode: x'' + 2 zeta omega x' + omega^2 (x - target) = 0, 0 <= zeta < 1, the target linear between
    grid points h apart. State (x, v) = (position, velocity); in modal form x = 2 Re(xi), v = 2 Re(lambda xi),
    lambda = -zeta omega + i omega sqrt(1 - zeta^2), and xi[n+1] = E xi[n] + beta (g0 u[n] + g1 u[n+1]) exactly."""

    omega_rad_s: float
    zeta: float
    h_s: float

    def __post_init__(self) -> None:
        if not (self.omega_rad_s > 0 and 0 <= self.zeta < 1 and self.h_s > 0):
            raise ValueError(f"SecondOrderMode needs omega > 0, 0 <= zeta < 1, h > 0; got {self.omega_rad_s!r}, "
                             f"{self.zeta!r}, {self.h_s!r}")
        lam = complex(-self.zeta * self.omega_rad_s, self.omega_rad_s * math.sqrt(1.0 - self.zeta ** 2))
        object.__setattr__(self, "_lam", lam)
        object.__setattr__(self, "_beta", self.omega_rad_s ** 2 / (lam - lam.conjugate()))
        e, g0, g1 = self._step_gains(self.h_s)
        object.__setattr__(self, "_E", e)
        object.__setattr__(self, "_g0", g0)
        object.__setattr__(self, "_g1", g1)

    @property
    def lam(self) -> complex:
        return self._lam  # type: ignore[attr-defined]

    def _step_gains(self, tau):
        """e^(lambda tau) and the input gains after a time tau into a step of length h: the target's value at the
        step start weighs g0, its value at the step end g1 (first-order hold over the full step h)."""
        lam, h = self._lam, self.h_s
        e = np.exp(lam * tau)
        i0 = (e - 1.0) / lam                            # int_0^tau e^(lam (tau - s)) ds
        i1 = (e - 1.0 - lam * tau) / lam ** 2           # int_0^tau e^(lam (tau - s)) s ds
        return e, i0 - i1 / h, i1 / h

    def to_modal(self, x: float, v: float) -> complex:
        lam = self._lam  # type: ignore[attr-defined]
        return (v - lam.conjugate() * x) / (lam - lam.conjugate())

    def from_modal(self, xi: np.ndarray | complex) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(2.0 * np.real(xi)), np.asarray(2.0 * np.real(self._lam * np.asarray(xi)))  # type: ignore[attr-defined]

    def run(self, x0: float, v0: float, target: np.ndarray, offset: np.ndarray | None = None) -> np.ndarray:
        """Modal states xi at target[1:] grid points, starting from (x0, v0) at the time of target[0]. `offset`
        (one per step, held over it) adds to the target: a damper tied to a moving base contributes
        2 zeta v_base / omega, constant over a step where the base moves linearly."""
        u = np.asarray(target, dtype=float)
        drive = self._beta * (self._g0 * u[:-1] + self._g1 * u[1:])  # type: ignore[attr-defined]
        if offset is not None:
            drive = drive + self._beta * (self._g0 + self._g1) * np.asarray(offset)  # type: ignore[attr-defined]
        return first_order_recursion(self._E, drive, self.to_modal(x0, v0))  # type: ignore[attr-defined]

    def within_step(self, xi0: np.ndarray, u0: np.ndarray, u1: np.ndarray, tau_s: np.ndarray,
                    offset: np.ndarray | float = 0.0) -> np.ndarray:
        """x at time tau_s (0 <= tau_s <= h) into steps that start in modal state xi0 with target u0 -> u1."""
        e, g0, g1 = self._step_gains(np.asarray(tau_s, dtype=float))
        slope_part = self._beta * (g1 * self.h_s)  # type: ignore[attr-defined]
        # the target in the step is u0 + (u1 - u0) tau / h: weights for u0 (and the held offset) and for the slope
        xi = (e * xi0 + self._beta * (g0 + g1) * (u0 + offset)  # type: ignore[attr-defined]
              + slope_part * (u1 - u0) / self.h_s)
        return 2.0 * np.real(xi)

    def partial_integral(self, xi0: np.ndarray, u0: np.ndarray, u1: np.ndarray, tau_s: np.ndarray | float,
                         offset: np.ndarray | float = 0.0) -> np.ndarray:
        """The integral of x from a step's start to tau_s into it (closed form), for exact averages."""
        lam, h, beta = self._lam, self.h_s, self._beta  # type: ignore[attr-defined]
        tau = np.asarray(tau_s, dtype=float)
        j0 = np.expm1(lam * tau) / lam                               # int_0^tau e^(lam t) dt
        k0 = (j0 - tau) / lam                                        # int_0^tau (e^(lam t) - 1) / lam dt
        k1 = (j0 - tau - lam * tau * tau / 2.0) / lam ** 2           # int_0^tau (e^(lam t) - 1 - lam t) / lam^2 dt
        slope = (np.asarray(u1) - np.asarray(u0)) / h
        return 2.0 * np.real(xi0 * j0 + beta * ((np.asarray(u0) + offset) * k0 + slope * k1))

    def step_integral(self, xi0: np.ndarray, u0: np.ndarray, u1: np.ndarray,
                      offset: np.ndarray | float = 0.0) -> np.ndarray:
        """The integral of x over whole steps (start state xi0, target u0 -> u1)."""
        return self.partial_integral(xi0, u0, u1, self.h_s, offset)
