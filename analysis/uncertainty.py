"""The fitting engine shared by the actuator and transmission fits: bounded parameters in internal coordinates, the
two solvers (the paper's RMS cost with Nelder-Mead, and bounded least squares), profile-likelihood 95 % intervals,
and the identifiability verdict for each parameter.

Internal coordinates: a log-scaled parameter is z = ln(p / reference) (so a flat direction costs nothing to walk
along and every step is relative); a linear one is z = p / typical. Every residual vector is WEIGHTED (residual /
sigma of its group), so chi2 = sum(r^2).

Least squares: bounded Gauss-Newton / Levenberg-Marquardt (`minimise`) with forward-difference Jacobians, each
step the Gauss-Newton model's minimiser over the box; scipy's trust-region least squares is its fallback.

Intervals: the noise scale is taken from the fit itself (s^2 = chi2_min / dof, dof = n - p - the sigmas estimated
from the same residuals; the weights fix only the relative scale between groups), and a value belongs to the 95 %
interval (or another `level`) when the profile chi2 (every other parameter re-fitted) stays within
F(level; 1, dof) s^2 of the minimum. An interval that runs into a bound is cut there and says so. A parameter
whose interval reaches both of its bounds is not identifiable from these data. Each end is found by root-finding
on the profile (`profile_interval`), each profile point a warm-started constrained re-fit; the reported interval
is always this profile interval (no Wald or other approximation stands in for it).

A weak pull toward the reference (`penalty`, 1e-2 per unit of z) makes the point estimate unique along directions
the data do not constrain at all; it moves identified parameters by a negligible amount (their curvature is >= 1e2
per unit z for any useful data) and is excluded from chi2 when intervals are computed.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

BAD_RESIDUAL = 1e3        # weighted residual for a model that cannot be evaluated (linkage cannot close, ...)
PENALTY = 1e-2
FD_STEP = 1e-5           # forward-difference step of the Jacobian, internal units


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
        self.z_ref = np.array([s.to_z(r, r) for s, r in zip(self.specs, self.reference, strict=True)])
        lb, ub = zip(*(s.z_bounds(r) for s, r in zip(self.specs, self.reference, strict=True)), strict=True)
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


def jacobian(problem: Problem, z: np.ndarray, step: float = FD_STEP, free: np.ndarray | None = None,
             r0: np.ndarray | None = None, J: np.ndarray | None = None) -> np.ndarray:
    """Forward-difference Jacobian of the weighted data residuals in internal units (one model evaluation per
    column). With `free`, only those columns are computed; the others are copied from `J` (zero without it)."""
    r0 = problem.data_residuals(z) if r0 is None else r0
    out = np.zeros((r0.size, z.size)) if J is None else np.array(J, float, copy=True)
    for i in range(z.size) if free is None else np.flatnonzero(free):
        h = step if z[i] + step <= problem.ub[i] else -step
        zz = z.copy()
        zz[i] += h
        out[:, i] = (problem.data_residuals(zz) - r0) / h
    return out


@dataclass(frozen=True)
class Minimum:
    """Result of a (possibly constrained) minimisation: the point, its DATA chi2 (the pull excluded), the data
    Jacobian (fresh at z in the free columns when `verified`), and whether convergence was checked with it."""

    z: np.ndarray
    chi2: float
    J: np.ndarray
    verified: bool


def minimise(problem: Problem, z0: np.ndarray, free: np.ndarray | None = None, J: np.ndarray | None = None,
             tol: float = 1e-6, accept_below: float = -math.inf, max_iter: int = 60,
             tol_per_residual: float | None = None) -> Minimum:
    """Minimise data chi2 + the pull of the free parameters over the free ones (the others held at z0) in the box.

    Gauss-Newton with Levenberg-Marquardt damping, each step the minimiser of the Gauss-Newton model over the box
    (`_box_step`), so parameters on a bound (kappa = 0) are handled exactly and a start on a bound is fine.
    Converged when the Gauss-Newton model, with a Jacobian evaluated AT the point, predicts less than `tol` further
    decrease of chi2. Between fresh Jacobians (forward differences, one evaluation per free column) the
    steps reuse the last one with Broyden rank-one updates (one evaluation a step); `J` seeds it (e.g. from a
    nearby point). `accept_below`: a point where those cheaper steps have converged and whose chi2 is below this is
    returned without the fresh-Jacobian check (an unconverged minimum can only overstate chi2, so a point found
    below a threshold is below it). If the iteration does not converge, scipy's bounded trust-region least
    squares finishes from where it got to. `tol_per_residual`, if given, replaces tol by it x the number of
    residuals (chi2 is about that number at a good fit)."""
    lb, ub = problem.lb, problem.ub
    free = np.ones(problem.lb.size, bool) if free is None else np.asarray(free, bool)
    idx = np.flatnonzero(free)
    z = np.clip(np.asarray(z0, float), lb, ub)
    r = problem.data_residuals(z)
    if tol_per_residual is not None:
        tol = tol_per_residual * max(r.size, 1)
    zr, lbf, ubf = problem.z_ref[idx], lb[idx], ub[idx]
    eye = PENALTY**2 * np.eye(idx.size)

    def cost(zz: np.ndarray, rr: np.ndarray) -> float:
        pen = PENALTY * (zz[idx] - zr)
        return float(rr @ rr + pen @ pen)

    c = cost(z, r)
    fresh = J is None
    J = jacobian(problem, z, free=free, r0=r, J=J) if fresh else np.array(J, float, copy=True)
    lam = 0.0
    for _ in range(max_iter):
        Jf = J[:, idx]
        zf = z[idx]
        g = Jf.T @ r + PENALTY**2 * (zf - zr)
        H = Jf.T @ Jf + eye
        lo, hi = lbf - zf, ubf - zf
        d_gn = _box_step(H, g, lo, hi, 0.0)
        if -float(g @ d_gn + 0.5 * d_gn @ H @ d_gn) <= tol:       # predicted decrease of the undamped step
            if fresh or float(r @ r) < accept_below:
                return Minimum(z, float(r @ r), J, fresh)
            J, fresh, lam = jacobian(problem, z, free=free, r0=r, J=J), True, 0.0
            continue
        d = d_gn if lam == 0.0 else _box_step(H, g, lo, hi, lam)
        pred = -float(g @ d + 0.5 * d @ H @ d)
        trial = z.copy()
        trial[idx] = np.clip(zf + d, lbf, ubf)
        r_t = problem.data_residuals(trial)
        c_t = cost(trial, r_t)
        if c_t < c:
            s = trial[idx] - zf
            J[:, idx] += np.outer(r_t - r - Jf @ s, s) / float(s @ s)     # Broyden: J now fits this step
            poor = c - c_t < 0.25 * pred
            z, r, c = trial, r_t, c_t
            if poor and not fresh:
                J, fresh = jacobian(problem, z, free=free, r0=r, J=J), True
                continue
            fresh = False
            lam = 0.0 if lam < 1e-6 else lam / 10.0
            if poor:
                lam = max(lam * 10.0, 1e-3)
        elif not fresh:        # the stale Jacobian misled the step: evaluate it here
            J, fresh = jacobian(problem, z, free=free, r0=r, J=J), True
        else:
            lam = 1e-3 if lam == 0.0 else lam * 10.0
            if lam > 1e10:
                break
    return _finish_with_scipy(problem, z, free, J)


def _box_step(H: np.ndarray, g: np.ndarray, lo: np.ndarray, hi: np.ndarray, lam: float) -> np.ndarray:
    """Minimiser of the (damped) quadratic model 1/2 d'Hd + g'd over the box lo <= d <= hi (lo <= 0 <= hi), by a
    primal active-set method from d = 0: each iteration moves toward the Newton point of the free variables, stops
    at the first bound it meets (and holds that variable there), and releases a held variable whose multiplier has
    the wrong sign. Every move lowers the model, so the predicted decrease is never negative. H must be positive
    definite (the pull toward the reference makes it so)."""
    n = g.size
    Hd = H + lam * np.diag(np.diag(H)) if lam > 0.0 else H
    d = np.zeros(n)
    at_lo = (lo >= 0.0) & (g > 0.0)
    at_hi = (hi <= 0.0) & (g < 0.0)
    for _ in range(4 * n + 4):
        held = at_lo | at_hi
        f = ~held
        grad = Hd @ d + g
        p = np.zeros(n)
        if f.any():
            Hf = Hd[np.ix_(f, f)]
            try:
                p[f] = np.linalg.solve(Hf, -grad[f])
            except np.linalg.LinAlgError:
                p[f] = np.linalg.lstsq(Hf, -grad[f], rcond=None)[0]
        if np.all(np.abs(p) <= 1e-14 * (1.0 + np.abs(d))):
            wrong = np.where(at_lo & (grad < 0.0), -grad, 0.0) + np.where(at_hi & (grad > 0.0), grad, 0.0)
            if not np.any(wrong > 0.0):
                return d
            i = int(np.argmax(wrong))
            at_lo[i] = at_hi[i] = False
            continue
        alpha, block = 1.0, -1
        for k in np.flatnonzero(f & (p != 0.0)):
            a = ((lo[k] if p[k] < 0 else hi[k]) - d[k]) / p[k]
            if a < alpha:
                alpha, block = max(a, 0.0), int(k)
        d = d + alpha * p
        if block >= 0:
            if p[block] < 0:
                d[block], at_lo[block] = lo[block], True
            else:
                d[block], at_hi[block] = hi[block], True
    return np.clip(d, lo, hi)


def _finish_with_scipy(problem: Problem, z: np.ndarray, free: np.ndarray, J: np.ndarray) -> Minimum:
    """The fallback when `minimise` does not converge: scipy's bounded trust-region least squares from z."""
    idx = np.flatnonzero(free)
    base = z.copy()
    margin = 1e-9 * (problem.ub[idx] - problem.lb[idx])

    def fun(x: np.ndarray) -> np.ndarray:
        zz = base.copy()
        zz[idx] = x
        return problem.full_residuals(zz, free)

    x0 = np.clip(z[idx], problem.lb[idx] + margin, problem.ub[idx] - margin)
    res = optimize.least_squares(fun, x0, bounds=(problem.lb[idx], problem.ub[idx]), method="trf",
                                 xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=200)
    out = base.copy()
    out[idx] = res.x
    n = J.shape[0]
    J = J.copy()
    J[:, idx] = res.jac[:n]
    data = res.fun[:n]
    return Minimum(out, float(data @ data), J, True)


def solve(problem: Problem, method: str = "least-squares", z0: np.ndarray | None = None,
          tol: float = 1e-8) -> np.ndarray:
    """Best internal parameter vector. 'nelder-mead' minimises the RMS of the weighted residuals (the paper's cost)
    within the bounds; 'least-squares' is the bounded Gauss-Newton / Levenberg-Marquardt of `minimise` (stopping
    when less than tol x (number of residuals) of chi2 is left to gain)."""
    if method == "least-squares":
        return _least_squares(problem, z0, None, tol).z
    if method == "nelder-mead":
        # Start strictly inside the box (the simplex must be able to move both ways)
        margin = 1e-3 * (problem.ub - problem.lb)
        z0 = np.clip(problem.z_ref.copy() if z0 is None else z0, problem.lb + margin, problem.ub - margin)

        def cost(z: np.ndarray) -> float:
            r = problem.full_residuals(np.clip(z, problem.lb, problem.ub))
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


def _least_squares(problem: Problem, z0: np.ndarray | None, J0: np.ndarray | None, tol: float) -> Minimum:
    z0 = problem.z_ref.copy() if z0 is None else np.asarray(z0, float)
    return minimise(problem, z0, None, J0, tol_per_residual=tol)


@dataclass(frozen=True)
class Interval:
    lo: float                 # physical units
    hi: float
    lo_at_bound: bool
    hi_at_bound: bool
    status: str               # 'identified' | 'weakly identified' | 'upper limit' | 'not identifiable'


PROFILE_RTOL = 0.005     # an end is where delta chi2 is within 0.5 % of the threshold


def profile_interval(problem: Problem, z_hat: np.ndarray, chi2_min: float, j: int, threshold: float,
                     J: np.ndarray, rtol: float = PROFILE_RTOL) -> Interval:
    """Profile-likelihood interval of parameter j: where the profile chi2 (every other parameter re-fitted, data
    chi2 of `minimise`) crosses chi2_min + threshold, on each side of z_hat.

    Root-finding on g(t) = sqrt(delta chi2(t)) - sqrt(threshold), t the distance from z_hat[j] (g is linear in t
    for a quadratic profile, so secant steps are exact there). The first point is the quadratic model's crossing
    (from J at the optimum, the parameters on a bound held: the Wald estimate of the end, capped at 4 conditional
    steps); while inside, secant steps through the last two points (at least x1.02, at most x4, never past the
    bound); once bracketed, Illinois regula falsi. An end is accepted where |delta chi2 - threshold| <= rtol x
    threshold at a re-fit whose convergence was checked with a fresh Jacobian (so the end is within rtol/2 of its
    distance from the estimate for a quadratic profile, within rtol for one linear in t); a point still inside at
    the parameter's bound puts that end at the bound. Every re-fit is warm-started: from the previous inside
    point plus the quadratic model's response of the others to parameter j (between two bracketing points, from
    the interpolation of their solutions), with the previous point's Jacobian, and only points at or beyond
    (1 - rtol) x threshold pay for the fresh-Jacobian check (`minimise`'s accept_below)."""
    p = z_hat.size
    free = np.arange(p) != j
    H = J.T @ J + PENALTY**2 * np.eye(p)
    # Quadratic model of the profile with the parameters that sit on a bound at the optimum held there (a kappa at 0
    # cannot go negative to compensate): delta chi2(t) = t^2 / C_jj, the others moving by slope * t.
    model = ~((z_hat <= problem.lb) | (z_hat >= problem.ub))
    model[j] = True
    C = np.zeros((p, p))
    C[np.ix_(model, model)] = np.linalg.pinv(H[np.ix_(model, model)])
    c_jj = float(C[j, j])
    slope = C[:, j] / c_jj if c_jj > 0 else np.zeros(p)
    slope[j] = 0.0
    # First point: the model's crossing, but at most 4 conditional (others fixed) steps: an overshoot into a region
    # where the model breaks down costs far more re-fitting than one more step from inside.
    t_cond = math.sqrt(threshold / H[j, j])
    t_quad = min(math.sqrt(threshold * c_jj), 4.0 * t_cond) if c_jj > 0 and np.isfinite(c_jj) else t_cond
    root_thr = math.sqrt(threshold)
    accept_below = chi2_min + (1.0 - rtol) * threshold
    fit_tol = 1e-3 * threshold
    ends: list[float] = []
    at_bound: list[bool] = []
    for direction in (-1.0, 1.0):
        bound = problem.lb[j] if direction < 0 else problem.ub[j]
        room = abs(bound - z_hat[j])
        if room < 1e-4:     # at (or within 1e-4 internal units of) the bound already
            ends.append(float(bound))
            at_bound.append(True)
            continue
        t = min(max(t_quad, 1e-6), room)
        lo_t, lo_g, lo_z = 0.0, -root_thr, z_hat.copy()
        prev_t, prev_g = lo_t, lo_g
        hi_t: float | None = None       # the bracket's far end, once found (hi_g, hi_z: its g and point)
        hi_g, hi_z = 0.0, lo_z
        Jw = J
        side = 0
        done = None
        for _ in range(30):
            if hi_t is None:
                start = np.clip(lo_z + slope * (direction * (t - lo_t)), problem.lb, problem.ub)
            else:
                w = (t - lo_t) / (hi_t - lo_t)
                start = (1.0 - w) * lo_z + w * hi_z
            start[j] = z_hat[j] + direction * t
            m = minimise(problem, start, free, Jw, tol=fit_tol, accept_below=accept_below)
            Jw = m.J
            d = max(m.chi2 - chi2_min, 0.0)
            g = math.sqrt(d) - root_thr
            if abs(d - threshold) <= rtol * threshold:
                done = t
                break
            if g < 0:
                prev_t, prev_g = lo_t, lo_g
                lo_t, lo_g, lo_z = t, g, m.z
                if side == -1 and hi_t is not None:
                    hi_g *= 0.5
                side = -1
                if hi_t is None and t >= room:
                    break
            else:
                hi_t, hi_g, hi_z = t, g, m.z
                if side == 1:
                    lo_g *= 0.5
                side = 1
            if hi_t is None:
                secant = lo_t - lo_g * (lo_t - prev_t) / (lo_g - prev_g) if lo_g > prev_g else 4.0 * lo_t
                t = min(room, min(max(secant, 1.02 * lo_t), 4.0 * lo_t))
            else:
                if hi_t - lo_t < 1e-5 * max(1.0, abs(hi_t)):
                    done = 0.5 * (lo_t + hi_t)
                    break
                t = lo_t - lo_g * (hi_t - lo_t) / (hi_g - lo_g)
                t = min(max(t, lo_t + 0.02 * (hi_t - lo_t)), hi_t - 0.02 * (hi_t - lo_t))
        if done is None:
            if hi_t is None:
                ends.append(float(bound))
                at_bound.append(True)
                continue
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
    jacobian: np.ndarray | None = None  # of the weighted data residuals at the optimum, internal units


def fit_problem(problem: Problem, method: str = "least-squares", intervals: bool = True,
                z0: np.ndarray | None = None, profile=None, tol: float = 1e-8, level: float = 0.95,
                extra_dof_used: int = 0, J0: np.ndarray | None = None) -> FitOutcome:
    """Solve, then profile intervals at confidence `level` for the parameters in `profile` (all by default; the
    others, e.g. nuisance offsets, are re-fitted inside every profile but get no interval of their own).
    `extra_dof_used`: degrees of freedom spent elsewhere (e.g. one per noise sigma estimated from these data).
    `J0`: the data Jacobian at z0 if known (least squares starts from it instead of evaluating one)."""
    if method == "least-squares":
        m = _least_squares(problem, z0, J0, tol)
        z, J = m.z, m.J
        chi2 = m.chi2
    else:
        z = solve(problem, method, z0, tol)
        # a parameter the optimiser left a hair above/below a bound (e.g. kappa = 1e-20 N m/rad) is at the bound
        z = np.where(z - problem.lb < 1e-6, problem.lb, np.where(problem.ub - z < 1e-6, problem.ub, z))
        r = problem.data_residuals(z)
        chi2 = float(r @ r)
        J = jacobian(problem, z, r0=r)
    n = J.shape[0]
    p = z.size
    dof = n - p - extra_dof_used
    JtJ = J.T @ J
    cov = np.linalg.pinv(JtJ + 1e-12 * np.eye(p) * max(1.0, float(np.trace(JtJ)) / p))
    s2 = chi2 / dof if dof > 0 else 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov / np.sqrt(np.outer(np.diag(cov), np.diag(cov)))
    ivs = None
    if intervals:
        threshold = (stats.f.ppf(level, 1, dof) if dof > 0 else stats.chi2.ppf(level, 1)) * s2
        threshold = max(threshold, 1e-12)
        which = set(range(p) if profile is None else profile)
        ivs = [profile_interval(problem, z, chi2, j, threshold, J) if j in which else None for j in range(p)]
    return FitOutcome(problem.physical(z), ivs, chi2, dof, corr, problem.evaluations, J)
