"""The fitting engine (analysis/uncertainty.py) against independent computations.

- The fast profile-interval search (root-finding on the profile with warm-started Gauss-Newton re-fits) against a
  brute-force grid profile: every grid value re-fitted by scipy's bounded least squares from two starts, the
  crossing located on a grid and refined on a finer one. Same definition of the interval (profile chi2 within
  F(0.95; 1, n - p) s^2 of the minimum), nothing shared but the residual function. Tolerance: each end within 1 %
  of the interval's width (the search stops within 0.5 % of the threshold, about 0.25 % of the half-width).
- The bounded Gauss-Newton minimiser against scipy's trust-region least squares.
- On a real transmission fit: at each reported end an independent scipy re-fit gives delta chi2 = threshold.
- The cache of Powertrains in the transmission fit returns what the uncached observation model returns.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import optimize, stats

from analysis.uncertainty import ParamSpec, Problem, fit_problem, minimise

# y = A w (1 - exp(-x / tau)) + k x^2 + b: A and w enter only as a product (w is not identifiable; A only within
# the range w can compensate), k is truly 0 (an upper limit), tau and b are identified.
SPECS = (
    ParamSpec("A", "1", 0.1, 50.0),
    ParamSpec("tau", "s", 0.3, 10.0),
    ParamSpec("k", "1/s2", 0.0, 0.05, log=False, typical=0.01),
    ParamSpec("b", "1", -1.0, 1.0, log=False, typical=0.1),
    ParamSpec("w", "1", 0.5, 2.0),
)
TRUTH = np.array([2.0, 1.5, 0.0, 0.1, 1.0])
REFERENCE = np.array([1.0, 1.0, 0.0, 0.0, 1.0])
SIGMA = 0.05


def small_problem(seed: int = 4) -> Problem:
    x = np.linspace(0.1, 5.0, 40)

    def model(p: np.ndarray) -> np.ndarray:
        a, tau, k, b, w = p
        return a * w * (1.0 - np.exp(-x / tau)) + k * x**2 + b

    y = model(TRUTH) + np.random.default_rng(seed).normal(0.0, SIGMA, x.size)
    return Problem(SPECS, REFERENCE, lambda p: (model(p) - y) / SIGMA)


def _scipy_min(problem: Problem, z0: np.ndarray, free: np.ndarray) -> tuple[np.ndarray, float]:
    """Minimise data chi2 + the pull of the free parameters with scipy (the same objective as the engine)."""
    base = np.asarray(z0, float).copy()
    span = problem.ub[free] - problem.lb[free]
    x0 = np.clip(base[free], problem.lb[free] + 1e-6 * span, problem.ub[free] - 1e-6 * span)

    def fun(x: np.ndarray) -> np.ndarray:
        z = base.copy()
        z[free] = x
        return problem.full_residuals(z, free)

    res = optimize.least_squares(fun, x0, bounds=(problem.lb[free], problem.ub[free]), method="trf",
                                 xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=2000)
    z = base.copy()
    z[free] = res.x
    return z, problem.chi2(z)


def brute_force_interval(problem: Problem, j: int, level: float = 0.95, n_coarse: int = 61,
                         n_fine: int = 21) -> tuple[float, float, bool, bool]:
    """Profile interval of parameter j on a grid over its whole range: (lo, hi, lo_at_bound, hi_at_bound) in
    physical units."""
    p = len(problem.specs)
    everything = np.ones(p, bool)
    z_hat, chi2_min = _scipy_min(problem, problem.z_ref.copy(), everything)
    dof = problem.data_residuals(z_hat).size - p
    threshold = stats.f.ppf(level, 1, dof) * chi2_min / dof
    free = np.arange(p) != j
    cache: dict[float, tuple[np.ndarray, float]] = {}

    def profile(v: float, near: np.ndarray) -> tuple[np.ndarray, float]:
        if v not in cache:
            best = None
            for start in (z_hat, near):
                s = start.copy()
                s[j] = v
                z, c = _scipy_min(problem, s, free)
                if best is None or c < best[1]:
                    best = (z, c)
            cache[v] = best
        return cache[v]

    def g(c: float) -> float:
        return math.sqrt(max(c - chi2_min, 0.0)) - math.sqrt(threshold)

    ends, at_bound = [], []
    for direction in (-1, 1):
        bound = problem.lb[j] if direction < 0 else problem.ub[j]
        grid = np.linspace(z_hat[j], bound, n_coarse)
        near, prev = z_hat, (z_hat[j], g(chi2_min))
        crossing = None
        for v in grid[1:]:
            near, c = profile(float(v), near)
            if g(c) > 0:
                crossing = (prev[0], float(v))
                break
            prev = (float(v), g(c))
        if crossing is None:
            ends.append(float(bound))
            at_bound.append(True)
            continue
        fine = np.linspace(crossing[0], crossing[1], n_fine)
        prev = (fine[0], g(profile(float(fine[0]), near)[1]))
        for v in fine[1:]:
            near, c = profile(float(v), near)
            if g(c) > 0:
                t = prev[0] + (v - prev[0]) * (-prev[1]) / (g(c) - prev[1])     # linear in sqrt(delta chi2)
                ends.append(float(t))
                break
            prev = (float(v), g(c))
        at_bound.append(False)
    spec, ref = problem.specs[j], problem.reference[j]
    return spec.from_z(ends[0], ref), spec.from_z(ends[1], ref), at_bound[0], at_bound[1]


def test_fast_profile_intervals_match_a_brute_force_grid_profile():
    problem = small_problem()
    out = fit_problem(problem, "least-squares")
    statuses = {s.name: iv.status for s, iv in zip(SPECS, out.intervals)}
    # what the construction of the problem implies
    assert statuses["tau"] == statuses["b"] == "identified"
    assert statuses["k"] == "upper limit"
    assert statuses["w"] == "not identifiable"
    for j, spec in enumerate(SPECS):
        fast = out.intervals[j]
        lo, hi, lo_b, hi_b = brute_force_interval(problem, j)
        assert (fast.lo_at_bound, fast.hi_at_bound) == (lo_b, hi_b), spec.name
        # compare in the internal coordinate the profile is searched in (log for A, tau, w)
        zl, zh = (spec.to_z(v, problem.reference[j]) for v in (lo, hi))
        fl, fh = (spec.to_z(v, problem.reference[j]) for v in (fast.lo, fast.hi))
        width = zh - zl
        assert abs(fl - zl) <= 0.01 * width and abs(fh - zh) <= 0.01 * width, (spec.name, (fast.lo, fast.hi),
                                                                                (lo, hi))


def test_minimiser_agrees_with_scipy_least_squares():
    problem = small_problem(seed=9)
    every = np.ones(len(SPECS), bool)
    z_ref, chi2_ref = _scipy_min(problem, problem.z_ref.copy(), every)
    m = minimise(problem, problem.z_ref.copy(), tol_per_residual=1e-10)
    assert m.verified
    assert m.chi2 == pytest.approx(chi2_ref, rel=1e-6)
    # identified parameters agree to a small fraction of their standard error (~0.02-0.05 in internal units)
    for j in (1, 2, 3):
        assert abs(m.z[j] - z_ref[j]) < 1e-3, SPECS[j].name


def test_transmission_interval_ends_sit_on_the_threshold_by_an_independent_refit():
    """Design 4 (synthetic, one seed): at each reported end that is not a bound, re-fitting every other parameter
    with scipy's least squares from the optimum gives delta chi2 within 1.5 % of the threshold."""
    import analysis.fit as fit

    captured = {}
    original = fit.fit_problem

    def capture(problem, *args, **kwargs):
        out = original(problem, *args, **kwargs)
        if kwargs.get("profile") is not None:
            captured.update(problem=problem, out=out)
        return out

    from tests.analysis.synth import table_dataset

    try:
        fit.fit_problem = capture
        fit.fit_transmission(table_dataset(4, seed=11), 4, "least-squares")
    finally:
        fit.fit_problem = original
    problem, out = captured["problem"], captured["out"]
    z_hat = np.array([s.to_z(v, r) for s, v, r in zip(problem.specs, out.values, problem.reference)])
    threshold = stats.f.ppf(0.95, 1, out.dof) * out.chi2 / out.dof
    checked = 0
    for j in (0, 1, 2, 4):          # k_ser, kappa_1, kappa_2 (an upper limit), bias
        iv = out.intervals[j]
        for value, at_bound in ((iv.lo, iv.lo_at_bound), (iv.hi, iv.hi_at_bound)):
            if at_bound:
                continue
            start = z_hat.copy()
            start[j] = problem.specs[j].to_z(value, problem.reference[j])
            _, c = _scipy_min(problem, start, np.arange(z_hat.size) != j)
            assert (c - out.chi2) / threshold == pytest.approx(1.0, abs=0.015), (problem.specs[j].name, value)
            checked += 1
    assert checked >= 6


def test_cached_leg_prediction_equals_the_observation_model():
    from analysis.fit import TRANSMISSION_SPECS, _CachedLegPrediction, design_with
    from analysis.observations import LegObservations
    from hamr_bench.model import Powertrain, actuator_preset, design_preset
    from tests.analysis.synth import table_dataset

    obs = table_dataset(2, seed=3).observations
    legs = LegObservations([o.protocol for o in obs], [o.voltage_V for o in obs], [o.sag_m for o in obs])
    a, base = actuator_preset(2, "effective"), design_preset(2)
    names = [s.name for s in TRANSMISSION_SPECS]

    def build(p):
        return Powertrain(a, design_with(base, dict(zip(names, p))))

    cached = _CachedLegPrediction(legs, build, size=2)
    rng = np.random.default_rng(0)
    params = [np.array([800.0, 2e-5, 1e-6, 0.0, -1e-5]), np.array([900.0, 1e-5, 0.0, 2e-6, 5e-6])]
    # revisit parameter sets in and out of the cache, with new offsets each time
    for p in (params[0], params[1], params[0], params[0], params[1], params[0]):
        offsets = rng.normal(0.0, 5e-6, len(obs))
        np.testing.assert_array_equal(cached(p, offsets), legs.predict(build(p), offsets))
