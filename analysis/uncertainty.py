"""The fitting engine shared by the actuator and transmission fits: bounded parameters in internal coordinates, the
two solvers (the paper's RMS cost with Nelder-Mead, and bounded least squares), profile-likelihood 95 % intervals,
and the identifiability verdict for each parameter.

Internal coordinates: a log-scaled parameter is z = ln(p / reference) (so a flat direction costs nothing to walk
along and every step is relative); a linear one is z = p / typical. Every residual vector is WEIGHTED (residual /
sigma of its group), so chi2 = sum(r^2).

Intervals: the noise scale is taken from the fit itself (s^2 = chi2_min / dof, dof = n - p - the sigmas estimated
from the same residuals; the weights fix only the relative scale between groups), and a value belongs to the 95 %
interval (or another `level`) when the profile chi2 (every other parameter re-fitted) stays within
F(level; 1, dof) s^2 of the minimum. An interval that runs into a bound is cut there and says so. A parameter
whose interval reaches both of its bounds is not identifiable from these data.

A weak pull toward the reference (`penalty`, 1e-2 per unit of z) makes the point estimate unique along directions
the data do not constrain at all; it moves identified parameters by a negligible amount (their curvature is >= 1e2
per unit z for any useful data) and is excluded from chi2 when intervals are computed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import optimize, stats

BAD_RESIDUAL = 1e3        # weighted residual for a model that cannot be evaluated (linkage cannot close, ...)
PENALTY = 1e-2


@dataclass(frozen=True)
class ParamSpec:
    name: str
    unit: str
    lower: float
    upper: float
    log: bool = True
    typical: float = 1.0     # scale of a linear parameter in internal units

    def to_z(self, value: float, reference: float) -> float:
        return math.log(value / reference) if self.log else value / self.typical

    def from_z(self, z: float, reference: float) -> float:
        return reference * math.exp(z) if self.log else z * self.typical

    def z_bounds(self, reference: float) -> tuple[float, float]:
        return self.to_z(self.lower, reference), self.to_z(self.upper, reference)


@dataclass
class Problem:
    """A weighted least-squares problem over bounded parameters."""

    specs: tuple[ParamSpec, ...]
    reference: np.ndarray                       # physical reference values (start point and pull target)
    residuals: Callable[[np.ndarray], np.ndarray]   # physical parameter vector -> weighted data residuals

    def __post_init__(self) -> None:
        self.reference = np.asarray(self.reference, float)
        self.z_ref = np.array([s.to_z(r, r) for s, r in zip(self.specs, self.reference)])
        lb, ub = zip(*(s.z_bounds(r) for s, r in zip(self.specs, self.reference)))
        self.lb, self.ub = np.array(lb), np.array(ub)
        self.z_ref = np.clip(self.z_ref, self.lb, self.ub)
        self.evaluations = 0

    def physical(self, z: np.ndarray) -> np.ndarray:
        return np.array([s.from_z(float(v), r) for s, v, r in zip(self.specs, z, self.reference)])

    def data_residuals(self, z: np.ndarray) -> np.ndarray:
        self.evaluations += 1
        r = self.residuals(self.physical(z))
        return np.where(np.isfinite(r), r, BAD_RESIDUAL)

    def full_residuals(self, z: np.ndarray, free: np.ndarray | None = None) -> np.ndarray:
        pen = PENALTY * (z - self.z_ref)
        if free is not None:
            pen = pen[free]
        return np.concatenate([self.data_residuals(z), pen])

    def chi2(self, z: np.ndarray) -> float:
        r = self.data_residuals(z)
        return float(r @ r)


def solve(problem: Problem, method: str = "least-squares", z0: np.ndarray | None = None,
          tol: float = 1e-8) -> np.ndarray:
    """Best internal parameter vector. 'nelder-mead' minimises the RMS of the weighted residuals (the paper's cost)
    within the bounds; 'least-squares' is scipy's bounded trust-region least squares."""
    # Start strictly inside the box (a trust-region method scales its steps by the distance to an active bound,
    # so a start exactly on one, e.g. kappa = 0, would never leave it).
    margin = 1e-3 * (problem.ub - problem.lb)
    z0 = np.clip(problem.z_ref.copy() if z0 is None else z0, problem.lb + margin, problem.ub - margin)
    if method == "least-squares":
        res = optimize.least_squares(problem.full_residuals, z0, bounds=(problem.lb, problem.ub), method="trf",
                                     x_scale=1.0, xtol=tol, ftol=tol, gtol=tol, max_nfev=400)
        return res.x
    if method == "nelder-mead":
        n = None

        def cost(z: np.ndarray) -> float:
            nonlocal n
            r = problem.full_residuals(np.clip(z, problem.lb, problem.ub))
            n = n or r.size
            return float(np.sqrt(np.mean(r * r)))

        dim = z0.size
        # initial simplex: 0.3 internal units per axis (30 % of a log parameter), inside the bounds
        simplex = [z0.copy()]
        for i in range(dim):
            z = z0.copy()
            step = 0.3 if z[i] + 0.3 <= problem.ub[i] else -0.3
            z[i] = np.clip(z[i] + step, problem.lb[i], problem.ub[i])
            simplex.append(z)
        res = optimize.minimize(cost, z0, method="Nelder-Mead", bounds=list(zip(problem.lb, problem.ub)),
                                options={"initial_simplex": np.array(simplex), "xatol": 1e3 * tol, "fatol": 0.1 * tol,
                                         "maxfev": 4000 * dim, "adaptive": dim > 3})
        return np.clip(res.x, problem.lb, problem.ub)
    raise ValueError(f"unknown method {method!r}")


def jacobian(problem: Problem, z: np.ndarray, step: float = 1e-5) -> np.ndarray:
    r0 = problem.data_residuals(z)
    J = np.empty((r0.size, z.size))
    for i in range(z.size):
        h = step if z[i] + step <= problem.ub[i] else -step
        zz = z.copy()
        zz[i] += h
        J[:, i] = (problem.data_residuals(zz) - r0) / h
    return J


@dataclass(frozen=True)
class Interval:
    lo: float                 # physical units
    hi: float
    lo_at_bound: bool
    hi_at_bound: bool
    status: str               # 'identified' | 'upper limit' | 'lower limit' | 'not identifiable'


def _refit_fixed(problem: Problem, z: np.ndarray, j: int, J: np.ndarray, tol: float,
                 accept_below: float) -> tuple[np.ndarray, float, np.ndarray]:
    """Minimise over every parameter but j (held at z[j]); returns (z, data chi2, Jacobian to use next).

    First chord steps: Gauss-Newton with the Jacobian J from an earlier point (one model evaluation each, projected
    onto the bounds); near that point the model is close to linear in the other parameters, so a few steps
    converge. If they do not, or if the chord result lies above `accept_below` (an unconverged minimum overstates
    the profile there, which would cut an interval short), bounded least squares finishes from where the chord got
    to, and its Jacobian replaces J for the next point along this profile."""
    free = np.ones(z.size, bool)
    free[j] = False
    z = np.clip(z, problem.lb, problem.ub)
    n_pen = z.size
    pinv = np.linalg.pinv(np.vstack([J[:, free], PENALTY * np.eye(z.size)[:, free]]))
    r = problem.full_residuals(z)
    c = float(r @ r)
    converged = False
    for iteration in range(8):
        trial = z.copy()
        trial[free] = np.clip(z[free] - pinv @ r, problem.lb[free], problem.ub[free])
        r_new = problem.full_residuals(trial)
        c_new = float(r_new @ r_new)
        if c_new >= c:
            converged = iteration > 0
            break
        z, r, gain, c = trial, r_new, c - c_new, c_new
        if gain < tol:
            converged = True
            break
    data = r[: r.size - n_pen]
    if converged and float(data @ data) < accept_below:
        return z, float(data @ data), J
    base = z.copy()

    def fun(x: np.ndarray) -> np.ndarray:
        zz = base.copy()
        zz[free] = x
        return problem.full_residuals(zz, free)

    res = optimize.least_squares(fun, z[free], bounds=(problem.lb[free], problem.ub[free]), method="trf",
                                 xtol=1e-8, ftol=1e-8, gtol=1e-8, max_nfev=100)
    out = base.copy()
    out[free] = res.x
    J_new = J.copy()
    J_new[:, free] = res.jac[: J.shape[0]]
    data = res.fun[: J.shape[0]]
    return out, float(data @ data), J_new


def profile_interval(problem: Problem, z_hat: np.ndarray, chi2_min: float, j: int, threshold: float,
                     sigma_z: float, J: np.ndarray) -> Interval:
    """95 % profile-likelihood interval of parameter j: where the profile chi2 crosses chi2_min + threshold.

    The search starts at the conditional (others fixed) Wald step, which never overshoots a quadratic profile,
    grows by the ratio a quadratic profile implies (at most x4) until it brackets the crossing, then refines by
    Illinois regula falsi on sqrt(delta chi2) - sqrt(threshold). The other parameters start from the linearised
    response to parameter j (from J) at each point."""
    JtJ = J.T @ J
    others = np.arange(z_hat.size) != j
    slope = np.zeros(z_hat.size)
    if others.any():
        H = JtJ[np.ix_(others, others)] + PENALTY**2 * np.eye(int(others.sum()))
        slope[others] = -np.linalg.lstsq(H, JtJ[others, j], rcond=None)[0]
    root_thr = math.sqrt(threshold)
    ends: list[float] = []
    at_bound: list[bool] = []
    for direction in (-1.0, 1.0):
        bound = problem.lb[j] if direction < 0 else problem.ub[j]
        room = abs(bound - z_hat[j])
        if room < 1e-4:     # at (or within 1e-4 internal units of) the bound already
            ends.append(float(bound))
            at_bound.append(True)
            continue
        t = min(max(sigma_z * root_thr, 1e-6), room) if np.isfinite(sigma_z) and sigma_z > 0 else min(0.1, room)
        lo_t, lo_g, lo_z, Jw = 0.0, -root_thr, z_hat.copy(), J
        hi_t = hi_g = None
        side = 0
        done = None
        for _ in range(14):
            zz = np.clip(lo_z + slope * (direction * (t - lo_t)), problem.lb, problem.ub)
            zz[j] = z_hat[j] + direction * t
            zz, c, Jn = _refit_fixed(problem, zz, j, Jw, tol=1e-3 * threshold, accept_below=chi2_min + threshold)
            d = max(c - chi2_min, 0.0)
            g = math.sqrt(d) - root_thr
            if abs(d - threshold) < 0.05 * threshold:
                done = t
                break
            if g < 0:
                lo_t, lo_g, lo_z, Jw = t, g, zz, Jn
                if side == -1 and hi_g is not None:
                    hi_g *= 0.5
                side = -1
                if hi_t is None and t >= room:
                    break
            else:
                hi_t, hi_g = t, g
                if side == 1:
                    lo_g *= 0.5
                side = 1
            if hi_t is None:
                ratio = root_thr / max(math.sqrt(d), 1e-3 * root_thr)
                t = min(room, t * min(4.0, max(1.2, 1.1 * ratio)))
            else:
                if hi_t - lo_t < 1e-5 * max(1.0, abs(hi_t)):
                    done = 0.5 * (lo_t + hi_t)
                    break
                t = lo_t - lo_g * (hi_t - lo_t) / (hi_g - lo_g)
                t = min(max(t, lo_t + 0.02 * (hi_t - lo_t)), hi_t - 0.02 * (hi_t - lo_t))
        if done is None and hi_t is None:
            ends.append(float(bound))
            at_bound.append(True)
            continue
        if done is None:
            done = 0.5 * (lo_t + hi_t)
        ends.append(float(z_hat[j] + direction * done))
        at_bound.append(False)
    spec, ref = problem.specs[j], problem.reference[j]
    lo, hi = spec.from_z(ends[0], ref), spec.from_z(ends[1], ref)
    if at_bound[0] and at_bound[1]:
        status = "not identifiable"
    elif at_bound[0] and spec.lower == 0.0:
        status = "upper limit"        # consistent with zero: only an upper bound is known
    elif at_bound[0] or at_bound[1]:
        status = "weakly identified"  # one side of the interval runs into the search range
    elif (spec.log and hi / lo > 100) or (not spec.log and hi - lo > 0.5 * (spec.upper - spec.lower)):
        status = "weakly identified"
    else:
        status = "identified"
    return Interval(lo, hi, at_bound[0], at_bound[1], status)


@dataclass(frozen=True)
class FitOutcome:
    values: np.ndarray                 # physical
    intervals: list[Interval | None] | None
    chi2: float
    dof: int
    correlation: np.ndarray            # from the Jacobian at the optimum (nan where undefined)
    evaluations: int


def fit_problem(problem: Problem, method: str = "least-squares", intervals: bool = True,
                z0: np.ndarray | None = None, profile=None, tol: float = 1e-8, level: float = 0.95,
                extra_dof_used: int = 0) -> FitOutcome:
    """Solve, then profile intervals at confidence `level` for the parameters in `profile` (all by default; the
    others, e.g. nuisance offsets, are re-fitted inside every profile but get no interval of their own).
    `extra_dof_used`: degrees of freedom spent elsewhere (e.g. one per noise sigma estimated from these data)."""
    z = solve(problem, method, z0, tol)
    # a parameter the optimiser left a hair above/below a bound (e.g. kappa = 1e-20 N m/rad) is at the bound
    z = np.where(z - problem.lb < 1e-6, problem.lb, np.where(problem.ub - z < 1e-6, problem.ub, z))
    chi2 = problem.chi2(z)
    n = problem.data_residuals(z).size
    p = z.size
    dof = n - p - extra_dof_used
    J = jacobian(problem, z)
    JtJ = J.T @ J
    cov = np.linalg.pinv(JtJ + 1e-12 * np.eye(p) * max(1.0, float(np.trace(JtJ)) / p))
    s2 = chi2 / dof if dof > 0 else 1.0
    # conditional (all others fixed) standard deviations: the profile search's first step never overshoots
    sd_cond = np.sqrt(s2 / np.maximum(np.diag(JtJ), 1e-300))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    ivs = None
    if intervals:
        threshold = (stats.f.ppf(level, 1, dof) if dof > 0 else stats.chi2.ppf(level, 1)) * s2
        threshold = max(threshold, 1e-12)
        which = set(range(p) if profile is None else profile)
        ivs = [profile_interval(problem, z, chi2, j, threshold, float(sd_cond[j]), J) if j in which else None
               for j in range(p)]
    return FitOutcome(problem.physical(z), ivs, chi2, dof, corr, problem.evaluations)
