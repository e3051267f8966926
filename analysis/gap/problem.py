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
from hamr_bench.errors import HamrBenchError
from analysis.gap.library import RunEngine

OFFSET_STEP = {"leg": 2e-6, "actuator": 1e-3}   # m (h0) and N (f0): finite-difference steps for the columns
LAG_BOUNDS_S = (0.0, 0.06)
LAG_STEP_S = 2e-3
# contact shift search range: actuator, 2 coarse steps of the trial's search plus the largest play; leg, the
# default search's threshold over the softest leg at zero sag (0.4 mN at ~2 N/m) with margin
SHIFT_BOUND_M = {"actuator": 60e-6, "leg": 1e-3}


def offset_rows(e: RunEngine, undriven_only: bool = False) -> np.ndarray:
    """The rows a run's zero offset (contact shift and its linear column) is identified from: its force rows; with
    `undriven_only`, when the run has an undriven stiffness sweep (two or more pushes), those holds alone.

    Attribution uses all force rows: the offset and the effects that act on the sweep (a sensor spring scales its
    forces, a play shifts its loading branch) are then not identified from the same eight holds (from the holds
    alone, sensor-compliance strengths came out 4-10 % low and small plays were missed; docs/gap.md, fifth run).
    The residual map (`where`) uses the holds alone: no drive effect acts on them, and fitted over the driven rows
    too, a drive effect's misfit of the blocked force moves the contact (~7-11 um with hysteresis 0.12) and paints
    its gap on the sweep, where data and model agree."""
    force = e.is_force_row
    if not undriven_only:
        return force
    holds = force & np.array([r.mode == "stiffness" for r in e.rows], dtype=bool)
    if np.unique([r.sag_m for r, h in zip(e.rows, holds) if h]).size >= 2:
        return holds
    return force


class Problem:
    def __init__(self, data: GapData, fit_params: dict | None = None, offsets_from_undriven: bool = False) -> None:
        self.data = data
        self.offsets_from_undriven = offsets_from_undriven  # see `offset_rows`: the residual map's view
        self.engines = [RunEngine(run, fit_params) for run in data.runs]
        self.rows = data.rows
        self.y = np.array([r.value for r in self.rows])
        # pure error, and where the drive was inferred from a measured monitor, the model's own error from it
        se = np.array([math.hypot(r.se, getattr(r, "drive_se", 0.0)) if np.isfinite(r.se) else r.se
                       for r in self.rows], float)
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
        self.contact_shift: dict[int, float] = {}
        self._pinv_cache: dict = {}
        self.pure_dof = int(sum(max(r.n - 1, 0) for r in self.rows))
        # The contact shifts and the sensor lags each move the other's best value: fitted in turn, shift last.
        self._fit_contact_shifts()
        self._fit_lags()
        self._fit_contact_shifts()
        self._offset_cols = self._offset_columns()
        self._drift_cols = self._drift_columns()

    # --- model -------------------------------------------------------------------------------------------
    def _run_lag(self, e: RunEngine) -> dict[str, float]:
        fx = e.run.fixture
        return {q: self.lag.get((fx, q), 0.0) for q in ("force_N", "displacement_m")}

    def model(self, strengths: dict[str, float]) -> np.ndarray:
        out = np.empty(self.y.size)
        for k, (e, sl) in enumerate(zip(self.engines, self.slices)):
            out[sl] = e.predict(strengths, self._run_lag(e), shift_m=self.contact_shift.get(k, 0.0))
        return out

    def _fit_contact_shifts(self, strengths: dict[str, float] | None = None) -> None:
        """Per run with a contact search, where the sensor surface really sits relative to the search's zero: the
        nonlinear form of the run's offset nuisance (h0 for a leg, f0 = -k_act x0 for the actuator), which the
        linear offset column is then taken about, both from `offset_rows`. The search's zero can be far off: on a
        leg a drifting force baseline moves the threshold crossing; and recordings made before the runner's search
        approached from one side only (third session) have it misplaced by up to a stage's play on the stiff bare
        actuator. Rows this leaves out of contact read 0 (a leg at low voltage may not reach the sensor at all),
        which an offset linearised at the search's zero cannot reach. With `sensor_drift` in `strengths`, each
        run's drift baseline is fitted along (projected out)."""
        strengths = strengths or {}
        drift = "sensor_drift" in strengths
        for k, (e, sl) in enumerate(zip(self.engines, self.slices)):
            if not e.has_offset():
                continue
            force = offset_rows(e, self.offsets_from_undriven)
            y, sig = self.y[sl][force], self.sigma[sl][force]
            lag = self._run_lag(e)
            basis = e.drift_columns()[force] / sig[:, None] if drift else np.zeros((int(force.sum()), 0))
            proj = np.linalg.pinv(basis) if basis.shape[1] else None

            def cost(x0: float) -> float:
                try:
                    m = e.predict(strengths, lag, shift_m=x0)[force]
                except HamrBenchError:   # a shift beyond the linkage's reach
                    return math.inf
                z = np.nan_to_num((y - m) / sig)
                if proj is not None:
                    z = z - basis @ (proj @ z)
                return float(z @ z)

            bound = SHIFT_BOUND_M[e.run.fixture]
            grid = np.linspace(-bound, bound, 49)
            costs = [cost(x) for x in grid]
            j = int(np.argmin(costs))
            lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
            r = minimize_scalar(cost, bounds=(lo, hi), method="bounded", options={"xatol": bound * 1e-4})
            self.contact_shift[k] = float(r.x) if r.fun <= costs[j] else float(grid[j])

    def _offset_columns(self) -> np.ndarray:
        cols = []
        for k, (e, sl) in enumerate(zip(self.engines, self.slices)):
            if not e.has_offset():
                continue
            step = OFFSET_STEP[e.run.fixture]
            lag = self._run_lag(e)
            x0 = self.contact_shift.get(k, 0.0)
            col = np.zeros(self.y.size)
            col[sl] = (e.predict({}, lag, step, x0) - e.predict({}, lag, -step, x0)) / (2 * step)
            col[sl] = np.where(offset_rows(e, self.offsets_from_undriven), col[sl], 0.0)
            if np.any(col):
                cols.append(col / self.sigma)
        # Timing lag of each sensor chain, linearised about the nominal estimate: the nominal fit alone would let
        # the lag soak up a rise/fall asymmetry that hysteresis also makes (hysteresis also moves the plateaus,
        # which a lag cannot), so every candidate is fitted with the lag free.
        for g in sorted(self.lag):
            col = np.zeros(self.y.size)
            for k, (e, sl) in enumerate(zip(self.engines, self.slices)):
                if e.run.fixture != g[0]:
                    continue
                lag_p, lag_m = self._run_lag(e), self._run_lag(e)
                lag_p[g[1]] += LAG_STEP_S
                lag_m[g[1]] = max(lag_m[g[1]] - LAG_STEP_S, 0.0)
                width = lag_p[g[1]] - lag_m[g[1]]
                x0 = self.contact_shift.get(k, 0.0)
                col[sl] = (e.predict({}, lag_p, shift_m=x0) - e.predict({}, lag_m, shift_m=x0)) / width
            if np.any(col):
                cols.append(col / self.sigma)
        return np.array(cols).T if cols else np.zeros((self.y.size, 0))

    def _drift_columns(self) -> np.ndarray:
        """Columns of the piecewise-linear drift baselines (one per knot after each run's tare); the knot times
        of each column's run go to `self._drift_knots` (run index, knot times, column numbers)."""
        cols = []
        self._drift_knots: list[tuple[int, np.ndarray, list[int]]] = []
        for k, (e, sl) in enumerate(zip(self.engines, self.slices)):
            block = e.drift_columns()
            mine = []
            for j in range(block.shape[1]):
                col = np.zeros(self.y.size)
                col[sl] = block[:, j]
                mine.append(len(cols))
                cols.append(col / self.sigma)
            if mine:
                self._drift_knots.append((k, e.drift_knots_s(), mine))
        return np.array(cols).T if cols else np.zeros((self.y.size, 0))

    def relinearised(self, strengths: dict[str, float]) -> "Problem":
        """A copy whose sensor lags and contact shifts are re-estimated with `strengths` in the model and whose
        nuisance columns are rebuilt there. A ramp cannot tell a time lag from a play-type memory (both delay every
        crossing); only the plateaus can, so each candidate is judged with the lag estimated under that candidate."""
        import copy

        q = copy.copy(self)
        q.lag = dict(self.lag)
        q.contact_shift = dict(self.contact_shift)
        q._pinv_cache = {}
        q._fit_contact_shifts(strengths)
        q._fit_lags(strengths)
        q._fit_contact_shifts(strengths)
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
                    m = e.predict(strengths, self._run_lag(e), shift_m=self.contact_shift.get(i, 0.0))
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
        """Sum of squared z on `mask` rows; inf where the strengths (with a run's contact shift) put the foot
        beyond the linkage's reach."""
        try:
            z, _ = self.residual(strengths, mask)
        except HamrBenchError:
            return math.inf
        m = np.ones(self.y.size, bool) if mask is None else mask
        return float(np.sum(z[m] ** 2))

    def n_nuisance(self, names: Sequence[str]) -> int:
        return self.design(names).shape[1]

    def drift_rms_slope(self, strengths: dict[str, float], draws: int = 400, seed: int = 0
                        ) -> tuple[float, np.ndarray, np.ndarray, list[float]]:
        """The drift baselines fitted (with the nuisances) and their wander rate over every run's knots (the
        baseline is 0 at the tare): q^2 = (sum dB^2 - its expectation from the knot values' noise) / sum dt, in
        N/sqrt(s), the scale of a random walk's strength. Returns (q, knot values in N, their covariance in N^2 at
        unit noise scale, a 95 % interval of q from draws of the knot values, each bias-corrected the same way)."""
        z0 = np.nan_to_num((self.y - self.model(strengths)) / self.sigma)
        a = self.design(list(strengths) + ["sensor_drift"])
        coef, *_ = np.linalg.lstsq(a, z0, rcond=None)
        n_off = self._offset_cols.shape[1]
        values = coef[n_off:]
        cov = np.linalg.pinv(a.T @ a)[n_off:, n_off:]
        if values.size == 0:
            return 0.0, values, cov, [0.0, 0.0]
        # differences of consecutive knot values per run (the first from the tare's 0), as one linear map
        rows, span = [], 0.0
        for _run, knots, cols in self._drift_knots:
            prev = None
            for c in cols:
                d = np.zeros(values.size)
                d[c] = 1.0
                if prev is not None:
                    d[prev] = -1.0
                rows.append(d)
                prev = c
            span += float(knots[-1] - knots[0])
        diff = np.array(rows)
        noise = float(np.trace(diff @ cov @ diff.T))

        def rate(v: np.ndarray) -> np.ndarray:
            ss = np.sum((np.atleast_2d(v) @ diff.T) ** 2, axis=1)
            return np.sqrt(np.maximum(ss - noise, 0.0) / span)

        q = float(rate(values)[0])
        sample = np.random.default_rng(seed).multivariate_normal(values, cov, size=draws, method="eigh")
        qs = rate(sample)
        # basic (pivot) interval: the draws scatter about q as q about the truth
        return q, values, cov, [max(0.0, 2 * q - float(np.percentile(qs, 97.5))),
                                max(0.0, 2 * q - float(np.percentile(qs, 2.5)))]
