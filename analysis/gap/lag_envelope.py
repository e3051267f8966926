"""Freeing a sensor chain's lag that was fitted without a drive effect, when the effect is added to the nominal
fit (`Problem.solve(free_lags=True)`, from `screening.fit_added`).

A sample taken in step with a staircase drive (a commanded one, or a logged command) reads the same step until
its lag carries it across the next update, so the rows are a staircase in the lag: flat within an interval, steep
across its edge. The solver's fine differences read 0 there (or a slope many times the envelope's), so a fit
seldom moves a lag out of the interval it started in. A lag fitted with no drive effect takes up part of an
effect's delayed response on the ramps (a creep's or a loop's late part reads as a late sensor); with the effect
added, the lag has to move back before the effect can take its full strength. On the bench's creep trials the fit
stopped at 0.040 of a 0.053 creep, objective 1805 against 262 with the lag freed (docs/gap.md, Method).

So such a fit is solved first for a few evaluations with each lag's column of the solver's Jacobian the secant
over one drive update interval (`SecantJacobian`, the envelope's slope, as `Problem._lag_secants` gives the
covariance), moving the lags along the envelope together with every other parameter; then every parameter is
polished with ordinary differences from there (the rows' fine structure within an interval is the model's too).
"""

from __future__ import annotations

from collections.abc import Callable
from functools import cached_property

import numpy as np
from scipy.sparse import csc_matrix, csr_matrix

FD_STEP = 1e-4      # relative forward-difference step of every other column (least_squares' diff_step)
ENVELOPE_NFEV = 8   # solver evaluations along the envelope: enough to carry a lag across a few intervals


class SecantJacobian:
    """J(x) for `least_squares(jac=...)`: forward differences grouped by the layout's sparsity (as least_squares
    groups its own), each lag's column the secant over its interval centred on x (clipped to the bounds).
    `lags`: each lag parameter's index -> its drive update interval (s)."""

    def __init__(self, sparsity: object, lags: dict[int, float], lo: np.ndarray, hi: np.ndarray) -> None:
        pattern = csc_matrix(sparsity)
        self.shape = pattern.shape
        self.rows_of = [pattern.indices[pattern.indptr[j]:pattern.indptr[j + 1]] for j in range(self.shape[1])]
        self.lags = dict(lags)
        self.lo, self.hi = np.asarray(lo, float), np.asarray(hi, float)
        self.lag_groups = _groups(sorted(self.lags), self.rows_of, self.shape[0])   # chains' rows are disjoint

    @cached_property
    def groups(self) -> list[np.ndarray]:
        """The other columns in groups that touch no row in common (only the solver's J needs them)."""
        return _groups([j for j in range(self.shape[1]) if j not in self.lags], self.rows_of, self.shape[0])

    def __call__(self, fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> csr_matrix:
        x = np.asarray(x, float)
        f0 = fun(x)
        h = FD_STEP * np.where(x >= 0.0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        h = np.where((x + h > self.hi) & (x - h >= self.lo), -h, h)   # backward where forward leaves the bounds
        rows, cols, vals = [], [], []
        for group in self.groups:
            xp = x.copy()
            xp[group] += h[group]
            df = fun(xp) - f0
            for j in group:
                r = self.rows_of[j]
                rows.append(r)
                cols.append(np.full(r.size, j))
                vals.append(df[r] / (xp[j] - x[j]))
        for j, r, v in self.lag_columns(fun, x):
            rows.append(r)
            cols.append(np.full(r.size, j))
            vals.append(v)
        if not rows:
            return csr_matrix(self.shape)
        return csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=self.shape)


    def lag_columns(self, fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray
                    ) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """Each lag's (index, rows, values): the secant over its interval centred on x, clipped to the bounds (a lag
        pinned at both is left out); the chains touch disjoint rows, so two evaluations serve every lag."""
        out = []
        for group in self.lag_groups:
            xa, xb = x.copy(), x.copy()
            for j in group:
                xa[j] = max(self.lo[j], x[j] - self.lags[j] / 2)
                xb[j] = min(self.hi[j], x[j] + self.lags[j] / 2)
            fa, fb = fun(xa), fun(xb)
            for j in group:
                if xb[j] > xa[j]:
                    r = self.rows_of[j]
                    out.append((int(j), r, (fb[r] - fa[r]) / (xb[j] - xa[j])))
        return out


def _groups(columns: list[int], rows_of: list[np.ndarray], n_rows: int) -> list[np.ndarray]:
    """Columns that touch no row in common, gathered greedily: one perturbed evaluation differences them all."""
    groups: list[list[int]] = []
    used: list[np.ndarray] = []
    for j in columns:
        for g, mask in zip(groups, used, strict=True):
            if not mask[rows_of[j]].any():
                g.append(j)
                mask[rows_of[j]] = True
                break
        else:
            mask = np.zeros(n_rows, bool)
            mask[rows_of[j]] = True
            groups.append([j])
            used.append(mask)
    return [np.array(g, int) for g in groups]


__all__ = ["ENVELOPE_NFEV", "FD_STEP", "SecantJacobian"]
