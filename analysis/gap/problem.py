"""The weighted least-squares problem every part of the diagnosis shares: observed rows, their noise (pure error),
the nominal model plus candidate strengths, and the nuisances (per-run zero offset, per-sensor timing lag, and the
drift slopes when the drift candidate is in) solved linearly for any strengths (variable projection).

Residuals are in noise units (z = (y - model) / sigma), so rows of force and displacement sit in one sum."""

from __future__ import annotations

import math
from typing import Sequence

import numpy as np
from scipy.optimize import minimize_scalar

from analysis.gap.features import GapData
from analysis.gap.library import RunEngine

OFFSET_STEP = {"leg": 2e-6, "actuator": 1e-3}   # m (h0) and N (f0): finite-difference steps for the columns
LAG_BOUNDS_S = (0.0, 0.06)
LAG_STEP_S = 2e-3


class Problem:
    def __init__(self, data: GapData, fit_params: dict | None = None) -> None:
        self.data = data
        self.engines = [RunEngine(run, fit_params) for run in data.runs]
        self.rows = data.rows
        self.y = np.array([r.value for r in self.rows])
        se = np.array([r.se for r in self.rows], float)
        self.run_of = np.array([r.run for r in self.rows])
        # rows with no pure-error estimate get their run's median (never zero: a floor of 1e-9 of the scale)
        for k in np.unique(self.run_of):
            m = self.run_of == k
            good = se[m][np.isfinite(se[m]) & (se[m] > 0)]
            fill = float(np.median(good)) if good.size else float(np.nanmax(np.abs(self.y[m])) * 1e-3 + 1e-12)
            se[m] = np.where(np.isfinite(se[m]) & (se[m] > 0), se[m], fill)
        self.sigma = se
        self.slices = []
        start = 0
        for e in self.engines:
            self.slices.append(slice(start, start + e.n_rows))
            start += e.n_rows
        self.lag: dict[tuple[str, str], float] = {}
        self._pinv_cache: dict = {}
        self.pure_dof = int(sum(max(r.n - 1, 0) for r in self.rows))
        self._fit_lags()
        self._offset_cols = self._offset_columns()
        self._drift_cols = self._drift_columns()

    # --- model -------------------------------------------------------------------------------------------
    def _run_lag(self, e: RunEngine) -> dict[str, float]:
        fx = e.run.fixture
        return {q: self.lag.get((fx, q), 0.0) for q in ("force_N", "displacement_m")}

    def model(self, strengths: dict[str, float]) -> np.ndarray:
        out = np.empty(self.y.size)
        for e, sl in zip(self.engines, self.slices):
            out[sl] = e.predict(strengths, self._run_lag(e))
        return out

    def _offset_columns(self) -> np.ndarray:
        cols = []
        for k, (e, sl) in enumerate(zip(self.engines, self.slices)):
            if not e.has_offset():
                continue
            step = OFFSET_STEP[e.run.fixture]
            lag = self._run_lag(e)
            col = np.zeros(self.y.size)
            col[sl] = (e.predict({}, lag, step) - e.predict({}, lag, -step)) / (2 * step)
            col[sl] = np.where(e.is_force_row, col[sl], 0.0)
            if np.any(col):
                cols.append(col / self.sigma)
        # Timing lag of each sensor chain, linearised about the nominal estimate: the nominal fit alone would let
        # the lag soak up a rise/fall asymmetry that hysteresis also makes (hysteresis also moves the plateaus,
        # which a lag cannot), so every candidate is fitted with the lag free.
        for g in sorted(self.lag):
            col = np.zeros(self.y.size)
            for e, sl in zip(self.engines, self.slices):
                if e.run.fixture != g[0]:
                    continue
                lag_p, lag_m = self._run_lag(e), self._run_lag(e)
                lag_p[g[1]] += LAG_STEP_S
                lag_m[g[1]] = max(lag_m[g[1]] - LAG_STEP_S, 0.0)
                width = lag_p[g[1]] - lag_m[g[1]]
                col[sl] = (e.predict({}, lag_p) - e.predict({}, lag_m)) / width
            if np.any(col):
                cols.append(col / self.sigma)
        return np.array(cols).T if cols else np.zeros((self.y.size, 0))

    def _drift_columns(self) -> np.ndarray:
        cols = []
        for e, sl in zip(self.engines, self.slices):
            col = np.zeros(self.y.size)
            col[sl] = e.drift_column()
            if np.any(col):
                cols.append(col / self.sigma)
        return np.array(cols).T if cols else np.zeros((self.y.size, 0))

    def relinearised(self, strengths: dict[str, float]) -> "Problem":
        """A copy whose sensor lags are re-estimated with `strengths` in the model and whose nuisance columns are
        rebuilt there. A ramp cannot tell a time lag from a play-type memory (both delay every crossing); only the
        plateaus can, so each candidate is judged with the lag estimated under that candidate."""
        import copy

        q = copy.copy(self)
        q.lag = dict(self.lag)
        q._pinv_cache = {}
        q._fit_lags(strengths)
        q._offset_cols = q._offset_columns()
        return q

    def _fit_lags(self, strengths: dict[str, float] | None = None) -> None:
        """Per (fixture, quantity) the timing lag that best fits the model (nominal unless `strengths`): a property
        of the sensor chain (a serial load cell stamps lines after sampling), held fixed afterwards."""
        strengths = strengths or {}
        groups = sorted({(e.run.fixture, r.quantity) for e in self.engines for r in e.rows})
        for g in groups:
            idx = [i for i, e in enumerate(self.engines) if e.run.fixture == g[0]]

            def cost(lag: float) -> float:
                self.lag[g] = lag
                tot = 0.0
                for i in idx:
                    e, sl = self.engines[i], self.slices[i]
                    m = e.predict(strengths, self._run_lag(e))
                    z = ((self.y[sl] - m) / self.sigma[sl])[np.array([r.quantity == g[1] for r in e.rows])]
                    tot += float(np.sum(z * z))
                return tot

            grid = np.linspace(*LAG_BOUNDS_S, 13)
            costs = [cost(x) for x in grid]
            j = int(np.argmin(costs))
            lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
            self.lag[g] = float(minimize_scalar(cost, bounds=(lo, hi), method="bounded",
                                                options={"xatol": 2e-4}).x) if hi > lo else float(grid[j])

    # --- the projected residual --------------------------------------------------------------------------
    def design(self, names: Sequence[str], mask: np.ndarray | None = None) -> np.ndarray:
        cols = [self._offset_cols]
        if "sensor_drift" in names:
            cols.append(self._drift_cols)
        a = np.hstack(cols) if cols else np.zeros((self.y.size, 0))
        return a if mask is None else a[mask]

    def residual(self, strengths: dict[str, float], mask: np.ndarray | None = None,
                 predict_mask: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """z-residual after the linear nuisances fitted on `mask` rows; returns (z on all rows, nuisance coefs)."""
        z0 = (self.y - self.model(strengths)) / self.sigma
        z0 = np.nan_to_num(z0, nan=0.0)
        drift = "sensor_drift" in strengths
        a = self.design(list(strengths))
        m = np.ones(self.y.size, bool) if mask is None else mask
        if a.shape[1]:
            # the nuisance design is fixed for a view, a mask and the drift switch: factor it once
            key = (drift, id(self._offset_cols), m.tobytes() if mask is not None else None)
            pinv = self._pinv_cache.get(key)
            if pinv is None:
                pinv = np.linalg.pinv(a[m])
                if len(self._pinv_cache) > 32:
                    self._pinv_cache.clear()
                self._pinv_cache[key] = pinv
            coef = pinv @ z0[m]
            return z0 - a @ coef, coef
        return z0, np.zeros(0)

    def chi2(self, strengths: dict[str, float], mask: np.ndarray | None = None) -> float:
        z, _ = self.residual(strengths, mask)
        m = np.ones(self.y.size, bool) if mask is None else mask
        return float(np.sum(z[m] ** 2))

    def n_nuisance(self, names: Sequence[str]) -> int:
        return self.design(names).shape[1]

    def drift_rms_slope(self, strengths: dict[str, float]) -> tuple[float, np.ndarray]:
        """RMS of the fitted drift slopes (N/s) and their covariance-based standard errors."""
        z0 = np.nan_to_num((self.y - self.model(strengths)) / self.sigma)
        a = self.design(list(strengths) + ["sensor_drift"])
        coef, *_ = np.linalg.lstsq(a, z0, rcond=None)
        n_off = self._offset_cols.shape[1]
        slopes = coef[n_off:]
        cov = np.linalg.pinv(a.T @ a)[n_off:, n_off:]
        return float(math.sqrt(np.mean(slopes ** 2))) if slopes.size else 0.0, slopes, cov
