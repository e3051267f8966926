"""The candidate families' operators checked against their definitions (no simulation): each property is computed
here the long way (sample by sample, or by measuring a loop), not with the code under test."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from analysis.gap import operators as op
from analysis.gap import tolerances as tol
from analysis.gap.families import FAMILIES
from hamr_bench.model import actuator as act
from hamr_bench.model import actuator_preset


def _play_reference(x, w, y0=None, floor=-math.inf):
    y, out = (x[0] if y0 is None else y0), []
    for xi in x:
        y = max(min(max(y, xi - w), xi + w), floor)
        out.append(y)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-100, 100), min_size=2, max_size=200), st.floats(0, 30))
def test_play_matches_its_definition(values, w):
    x = np.repeat(np.array(values), 3)
    assert np.allclose(op.play(x, w), _play_reference(x, w))


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(0, 1), min_size=2, max_size=200), st.floats(0.01, 0.5))
def test_floored_play_matches_its_definition(values, w):
    x = np.repeat(np.array(values), 2)
    assert np.allclose(op.play(x, w, y0=w, floor=w), _play_reference(x, w, y0=w, floor=w))


def _plate_reference(x, weights, tip_share):
    """One plate's response the long way: each floored play sample by sample, the first rise by its definition
    (a monotone rise from 0 V read off a fine grid) and inverted by interpolation."""
    r = op.plate_radii()
    memory = np.array([x - _play_reference(x, ri, y0=ri, floor=ri) + ri for ri in r])
    g1 = 1 - 2 * weights @ r
    p = (x - weights @ memory) / g1
    grid = np.linspace(0, 1, 20001)
    first_rise = np.array([(g - sum(a * min(g, 2 * ri) for a, ri in zip(weights, r, strict=True))) / g1
                           for g in grid])
    return (1 - tip_share) * np.interp(p, first_rise, grid) + tip_share * p


def _net(drive, bias, weights, tip_share):
    return _plate_reference(drive, weights, tip_share) - _plate_reference(bias - drive, weights, tip_share)


def _full_cycle(n=401):
    """The strength's cycle: the bias charged to full scale with the drive at 0, then the drive 0 -> 1 -> 0."""
    up = np.linspace(0, 1, n)
    drive = np.r_[np.zeros(n), up, up[::-1]]
    bias = np.r_[up, np.ones(2 * n)]
    return drive, bias


@pytest.mark.parametrize("strength,gamma,tip", [(0.12, 0.0, 0.0), (0.06, -0.5, 0.0), (0.16, 1.0, 0.5),
                                               (0.08, 0.5, 1.0)])
def test_hysteresis_strength_is_the_largest_net_loop_gap_of_a_full_cycle(strength, gamma, tip):
    drive, bias = _full_cycle()
    y = _net(drive, bias, op.plate_weights(strength, gamma, tip), tip)
    n = 401
    rise, fall = y[n:2 * n], y[2 * n:][::-1]
    assert rise[-1] == pytest.approx(1.0, abs=1e-3) and fall[0] == pytest.approx(-1.0, abs=1e-3)
    assert np.max(np.abs(fall - rise)) / 2 == pytest.approx(strength, rel=0.01)


def test_hysteresis_tips_on_the_first_rise_unless_mixed_and_memory_wiped_at_zero_volts():
    w = op.plate_weights(0.12, 0.0, 0.0)
    n = 201
    cycle = lambda a: np.r_[np.linspace(0, a, n), np.linspace(a, 0, n)[1:]]   # noqa: E731
    x = np.r_[cycle(1.0), cycle(0.4), cycle(0.4)]
    y = op.plate_hysteresis(x, op.plate_memory(x), w, 0.0)
    assert np.allclose(y, _plate_reference(x, w, 0.0), atol=2e-4)
    first, second = y[2 * n - 1:3 * n - 1], y[4 * n - 2:5 * n - 2]   # the two rises to 0.4
    assert first[-1] == pytest.approx(0.4, abs=1e-6)                     # the tip on the nominal line
    assert np.allclose(first, second, atol=1e-9)                          # 0 V wiped the full cycle's memory
    assert np.max(np.abs(first - np.linspace(0, 0.4, n))) < 1e-9          # a rise from 0 V is the first rise
    falling = y[3 * n - 2:4 * n - 2][::-1]
    assert np.max(falling - np.linspace(0, 0.4, n)) > 0.01                # the loop shows on the ramp down
    mixed = op.plate_hysteresis(x, op.plate_memory(x), op.plate_weights(0.12, 0.0, 1.0), 1.0)
    assert mixed[3 * n - 2] < 0.4 - 0.01                                  # unmapped: a partial tip below the line


def test_hysteresis_loop_grows_faster_with_amplitude_for_a_larger_density_exponent():
    def share(a, gamma):
        drive, bias = _full_cycle()
        drive, bias = a * drive, a * bias
        y = _net(drive, bias, op.plate_weights(0.1, gamma, 0.0), 0.0)
        rise, fall = y[401:802], y[802:][::-1]
        return np.max(np.abs(fall - rise)) / (2 * a)
    ratios = [share(1.0, g) / share(0.4, g) for g in (-0.5, 1.5)]
    assert 1.0 < ratios[0] < ratios[1]
    assert op.slope_after_reversal(op.plate_weights(0.3, -0.8, 0.0)) > 0.0


def test_creep_kernel_log_law_limit_and_unit_mean_slope_per_decade():
    # growth from 50 ms to 400 ms is log10(8) decades x 1 per decade for any exponent
    tau = np.array([0.05, 0.4])
    for n in (-0.4, 0.0, 1e-9, 0.2, 0.5):
        k = op.creep_kernel(tau - op.CREEP_TAU0_S, n)
        assert (k[1] - k[0]) / np.log10(8.0) == pytest.approx(1.0, rel=1e-6)
        assert op.creep_kernel(np.array([1.0 - op.CREEP_TAU0_S]), n)[0] == pytest.approx(0.0, abs=1e-9)
    t = np.array([0.01, 0.1, 10.0])
    assert np.allclose(op.creep_kernel(t, 1e-9), np.log10(t + op.CREEP_TAU0_S), atol=1e-6)


def test_creep_kernel_growth_per_decade_falls_with_time_for_a_negative_exponent():
    decades = op.creep_kernel(10.0 ** np.arange(-2.0, 3.0), -0.4)
    per_decade = np.diff(decades)
    assert np.all(per_decade > 0) and np.all(np.diff(per_decade) < 0)    # saturating: front-loaded growth
    rising = np.diff(op.creep_kernel(10.0 ** np.arange(-2.0, 3.0), 0.3))
    assert np.all(np.diff(rising) > 0)


def test_curved_creep_kernel_keeps_the_units_and_meets_the_power_law_at_zero_curvature():
    tau = np.array([0.05, 0.4]) - op.CREEP_TAU0_S
    for n, q in ((0.0, -1.5), (0.3, -0.5), (-0.4, 0.3)):
        k = op.creep_kernel(tau, n, q)
        assert (k[1] - k[0]) / np.log10(8.0) == pytest.approx(1.0, rel=1e-4)     # 1 per decade over the span
        assert op.creep_kernel(np.array([1.0 - op.CREEP_TAU0_S]), n, q)[0] == pytest.approx(0.0, abs=1e-6)
    t = np.geomspace(1e-3, 30.0, 40)
    assert np.allclose(op.creep_kernel(t, 0.2, 1e-7), op.creep_kernel(t, 0.2), atol=1e-5)    # the q -> 0 limit


def test_negative_curvature_makes_the_growth_per_decade_a_bump_in_log_time():
    per_decade = np.diff(op.creep_kernel(10.0 ** np.arange(-3.0, 3.5, 0.5), 0.0, -1.5))
    peak = int(np.argmax(per_decade))
    assert 0 < peak < per_decade.size - 1
    assert np.all(np.diff(per_decade[:peak + 1]) > 0) and np.all(np.diff(per_decade[peak:]) < 0)


# The ages a dwell shows a step's creep at (20 ms - 2 s).
DWELL_AGES_S = np.geomspace(0.02, 2.0, 60)


def _bench_creep_growth(strength, taus_s, weights, ages_s=DWELL_AGES_S):
    """The bench's creep (a Kelvin-Voigt chain, another formula than the family's) after a unit step, at
    `ages_s`, relative to its response at 1 s, minus 1: what the family's kernel x strength stands for."""
    from sim_devices.drive_chain import PronyCreep

    r = PronyCreep(strength, taus_s=taus_s, weights=weights).step_response(np.r_[ages_s, 1.0])
    return r[:-1] / r[-1] - 1.0


def _best_creep_fit(target, shapes, start, ages_s=DWELL_AGES_S):
    """Least squares of strength x the family's kernel to `target` at `ages_s`, the named `shapes` free within the
    family's bounds (the others at 0); `start` is (strength, then each free shape)."""
    from scipy.optimize import least_squares

    bounds = [FAMILIES["creep"].shapes[name] for name in shapes]

    def res(p: np.ndarray) -> np.ndarray:
        return p[0] * op.creep_kernel(ages_s - op.CREEP_TAU0_S, **dict(zip(shapes, p[1:], strict=True))) - target

    return least_squares(res, start, bounds=([-1.0] + [b.lo for b in bounds], [1.0] + [b.hi for b in bounds]))


@pytest.mark.parametrize("taus_s,weights", [((0.1,), (1.0,)), ((0.2, 5.0), (1.0, 0.3))])
def test_a_creep_dominated_by_one_time_constant_is_followed_closer_with_curvature(taus_s, weights):
    """The bench's creep is a sum of exponentials (a different formula). Where one time constant dominates, its
    growth per decade is a bump no power law follows; the curved shape, within the family's bounds, follows the
    ages the dwell shows (20 ms - 2 s) at least 4x closer than the best power law."""
    target = _bench_creep_growth(0.02, taus_s, weights)

    def best_rms(curved: bool) -> float:
        fit = _best_creep_fit(target, ("exponent", "curvature") if curved else ("exponent",),
                              [0.01, 0.0, 0.0] if curved else [0.01, 0.0])
        return float(np.sqrt(np.mean(fit.fun ** 2)))

    assert best_rms(True) * 4.0 < best_rms(False)


@pytest.mark.parametrize("tau_s", [0.04, 0.1, 0.5, 2.0, 20.0])
def test_the_creep_family_reads_one_kelvin_voigt_element_of_any_time_constant(tau_s):
    """One exponential (the bench's form, not the family's) from far below the dwell to far above it: the best
    shape within the family's bounds follows the ages the dwell shows (20 ms - 2 s) and reads its growth per decade
    over 50 - 400 ms within 5 %."""
    from sim_devices.scenarios import library_strength

    target = _bench_creep_growth(0.005, (tau_s,), (1.0,))
    truth = library_strength("creep", 0.005, {"tau1_s": tau_s, "weight1": 1.0})
    n_b = FAMILIES["creep"].shapes["exponent"]
    best = min((_best_creep_fit(target, ("exponent", "curvature"), [0.01, n0, -0.5])
                for n0 in (n_b.lo / 2, 0.0, n_b.hi / 2)),
               key=lambda f: f.cost)
    assert np.sqrt(np.mean(best.fun ** 2)) < 0.025 * np.ptp(target)
    assert best.x[0] == pytest.approx(truth, rel=0.05)


@pytest.mark.parametrize("taus_s,weights", [((0.05, 30.0), (0.7, 0.3)), ((0.012, 0.36), (0.3, 0.7)),
                                            ((0.2, 5.0), (1.0, 0.3))])
def test_two_bands_of_time_constants_are_followed_closer_with_the_skew(taus_s, weights):
    """Two Kelvin-Voigt elements a decade or more apart (the bench's form, not the family's), seen from the dwell's
    20 ms to the 60 s a run's later steps show an earlier step's creep at: the growth per decade is a bump with a
    shoulder, which a parabola in log time cannot follow. With the skew free the best fit follows it at least 2x
    closer and reads the growth per decade over 50 - 400 ms within 10 %."""
    from sim_devices.scenarios import library_strength

    ages_s = np.geomspace(0.02, 60.0, 80)
    target = _bench_creep_growth(0.01, taus_s, weights, ages_s)
    truth = library_strength("creep", 0.01, {**{f"tau{i + 1}_s": t for i, t in enumerate(taus_s)},
                                             **{f"weight{i + 1}": w for i, w in enumerate(weights)}})

    def best(shapes):
        fits = [_best_creep_fit(target, shapes, [0.01, n0, -0.5, 0.0][:len(shapes) + 1], ages_s)
                for n0 in (-1.0, 0.0, 0.5)]
        return min(fits, key=lambda f: f.cost)

    parabola, skewed = best(("exponent", "curvature")), best(("exponent", "curvature", "skew"))
    assert np.sqrt(np.mean(skewed.fun ** 2)) * 2.0 < np.sqrt(np.mean(parabola.fun ** 2))
    assert skewed.x[0] == pytest.approx(truth, rel=0.10)


def test_the_skew_at_zero_is_the_two_shape_kernel_and_keeps_the_units():
    t = np.geomspace(1e-3, 300.0, 50)
    assert np.array_equal(op.creep_kernel(t, 0.2, -0.7, 0.0), op.creep_kernel(t, 0.2, -0.7))
    assert np.allclose(op.creep_kernel(t, 0.2, -0.7, 1e-7), op.creep_kernel(t, 0.2, -0.7), atol=1e-5)
    tau = np.array([0.05, 0.4]) - op.CREEP_TAU0_S
    for n, q, r in ((0.0, -1.0, 0.5), (0.5, -0.3, -0.8)):
        k = op.creep_kernel(tau, n, q, r)
        assert (k[1] - k[0]) / np.log10(8.0) == pytest.approx(1.0, rel=1e-4)
        assert op.creep_kernel(np.array([1.0 - op.CREEP_TAU0_S]), n, q, r)[0] == pytest.approx(0.0, abs=1e-6)
    # the cap: uncapped, r = 0.8 alone would make the growth per decade at 1000 - 3000 s ~10^60 the window's
    late = op.creep_kernel(np.array([1e3, 3e3]), 0.0, 0.0, 0.8)
    assert (late[1] - late[0]) / np.log10(3.0) < 10.0 ** (op.CREEP_SKEW_CAP + 0.5)


def test_creep_response_of_a_step_is_the_kernel():
    dt = 1e-3
    y = np.r_[np.zeros(100), np.ones(5000)]
    r = op.creep_response(y, dt, 0.2)
    tau = (np.arange(5000)) * dt
    assert np.allclose(r[100:], op.creep_kernel(tau, 0.2), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("s,knee,p", [(0.8, 3.0, 1.0), (0.8, 3.0, 2.0), (-0.4, 0.5, 4.0), (1.0, 1.2, 8.0)])
def test_d31_strength_is_the_gain_ratio_250_to_100_volts_either_sign(s, knee, p):
    t_p = 155e-6
    v = np.array([100.0, 250.0])
    g = op.plate_gain(v, t_p, s, knee, p)
    assert g[1] / g[0] - 1.0 == pytest.approx(s, rel=1e-9)
    assert np.all(g > 0)


def test_base_spring_strength_is_the_blocked_force_loss_it_causes():
    from analysis.gap.engine import REFERENCE_ACTUATOR, base_compliance_m_per_N

    a = REFERENCE_ACTUATOR
    k, f0 = act.stiffness_N_per_m(a), float(act.blocked_force_N(a, 250.0))
    for beta in (1.0, 0.6):
        c = base_compliance_m_per_N(0.2, beta)
        f = op.spring_solve_many(np.array([f0]), k, [(c, beta, 1.0)])[0]
        assert 1 - f / f0 == pytest.approx(0.2, rel=1e-3)


@pytest.mark.parametrize("beta,rho", [(1.0, 1.0), (0.5, 1.0), (1.3, 2.0)])
def test_series_spring_solve_balances_the_forces(beta, rho):
    k, c = 2000.0, 1e-4
    f0 = np.linspace(-0.1, 0.2, 31)
    f = op.spring_solve_many(f0, k, [(c, beta, rho)])
    assert np.allclose(f + k * op.spring_deflection(f, c, beta, rho), f0, atol=1e-7)
    assert np.all(np.abs(f) <= np.abs(f0) + 1e-12)


def test_stiffening_spring_loses_a_smaller_share_at_high_force():
    k = 2000.0
    f0 = np.array([0.01, 0.2])
    f = op.spring_solve_many(f0, k, [(1e-4, 0.5, 1.0)])
    assert (f / f0)[1] > (f / f0)[0]


def test_specimen_gain_directions_and_prior():
    a = actuator_preset(2, "effective")
    # d31 moves the stroke alone at fixed stiffness; the kerf the stiffness alone
    assert np.allclose(tol.direction(a, "d31"), [1.0, 0.0], atol=1e-6)
    d_w = tol.direction(a, "width")
    assert abs(d_w[0]) < 1e-6 and d_w[1] < -0.8   # a loss (positive strength) softens; the taper change too
    cov = tol.gain_prior_cov(a)
    assert math.sqrt(cov[0, 0]) >= tol.TOLERANCE["d31"]
    b = tol.with_gains(a, 0.05, -0.02)
    assert math.log(act.displacement_per_volt(b) / act.displacement_per_volt(a)) == pytest.approx(0.05)
    assert math.log(act.stiffness_N_per_m(b) / act.stiffness_N_per_m(a)) == pytest.approx(-0.02)


def test_kerf_keeps_the_taper_and_fabrication_shifts_scale_their_parameter():
    a = actuator_preset(2, "effective")
    b = tol.scaled(a, "width_loss", 0.15)
    assert b.width_nom_m == pytest.approx(0.85 * a.width_nom_m)
    assert 2 * b.width_nom_m * (b.width_ratio - 1) == pytest.approx(2 * a.width_nom_m * (a.width_ratio - 1))
    c = tol.scaled(a, "grounding_lengthening", 0.1)
    assert c.length_m == pytest.approx(1.1 * a.length_m)
    assert c.length_m * c.length_ratio == pytest.approx(a.length_m * a.length_ratio)


def test_every_family_has_a_unit_bounds_and_shapes_inside_them():
    for f in FAMILIES.values():
        assert f.unit and f.bounds[0] <= 0.0 <= f.bounds[1]
        for s in f.shapes.values():
            assert s.lo <= s.default <= s.hi and s.prior_sd > 0


def test_a_one_sigma_fabrication_change_is_within_one_sigma_of_the_gain_prior():
    """The gain prior is the tolerances pushed through the closed form (Sigma = sum_k tol_k^2 j_k j_k^T), so a
    change of one parameter by its own tolerance has a Mahalanobis length of at most 1, and twice that change
    twice the length: the yardstick `selfcheck.gain_sigmas` measures hidden shifts with."""
    from analysis.gap import tolerances as tol
    from hamr_bench.model import actuator_preset

    for layers in (1, 2, 3):
        a = actuator_preset(layers, "effective")
        w = tol.whitening(a)
        for name, t in tol.TOLERANCE.items():
            one = float(np.linalg.norm(w @ (tol.log_outputs(tol.scaled(a, name, t)) - tol.log_outputs(a))))
            two = float(np.linalg.norm(w @ (tol.log_outputs(tol.scaled(a, name, 2 * t)) - tol.log_outputs(a))))
            assert 0.0 < one <= 1.0 + 1e-3, (layers, name, one)
            assert two == pytest.approx(2 * one, rel=0.1), (layers, name)


def test_gain_sigmas_measures_the_hidden_fabrication_shifts_and_springs_only():
    from analysis.gap.families import FABRICATION
    from analysis.gap.selfcheck import EXCLUDED_FROM_DRAW, gain_sigmas
    from sim_devices.scenarios import LIBRARY_EFFECTS, draw_scenario

    pool = tuple(n for n in LIBRARY_EFFECTS if n not in EXCLUDED_FROM_DRAW)
    found = 0
    for seed in range(40):
        sig = gain_sigmas(seed)
        sc = draw_scenario(seed, fixtures=("actuator",), pool=pool)
        on_gains = {e.library_name for e in sc.effects if not e.decoy and
                    (e.library_name in FABRICATION or e.library_name in ("sensor_compliance", "base_compliance"))}
        assert set(sig) == on_gains, seed
        found += bool(sig)
        assert all(v > 0 for v in sig.values())
    assert found >= 3


def test_the_self_checks_creep_truth_is_read_in_the_candidates_unit():
    from sim_devices.drive_chain import PronyCreep, creep_shape
    from sim_devices.scenarios import LIBRARY_CREEP_SPAN_S, library_strength

    assert np.log10(LIBRARY_CREEP_SPAN_S) == pytest.approx(op.CREEP_SPAN_DECADES)
    # a time constant inside the span: much of its growth falls there; a slow one: almost none
    fast = {"tau1_s": 0.3, "weight1": 1.0}
    slow = {"tau1_s": 50.0, "weight1": 1.0}
    g_fast, g_slow = (library_strength("creep", 0.01, s) for s in (fast, slow))
    assert g_fast > 0.015 > 0.001 > g_slow > 0.0
    # the candidate's kernel at that strength and a log law reproduce the same growth over the span
    r = PronyCreep(0.01, **creep_shape(fast)).step_response(np.array([*LIBRARY_CREEP_SPAN_S, 1.0]))
    k = op.creep_kernel(np.array(LIBRARY_CREEP_SPAN_S) - op.CREEP_TAU0_S, 0.0)
    assert g_fast * (k[1] - k[0]) == pytest.approx((r[1] - r[0]) / r[2], rel=1e-9)


@pytest.mark.parametrize("switch,width,strength", [(0.5, 0.15, -0.3), (0.9, 0.2, 0.5), (1.3, 0.5, 0.5)])
def test_d31_knee_family_reaches_the_benchs_logistic_switch_in_field(switch, width, strength):
    """The bench's d31 can be a logistic in field (a different formula): some knee and steepness follow it within
    5 % of the gain over 5-250 V (the largest misfit is at low field, where the logistic has a floor), where the
    quadratic family it replaced missed by 13 % and 11 % on the first two."""
    from scipy.optimize import minimize

    from sim_devices.drive_chain import FieldGain

    t_p = 127e-6
    law = FieldGain(strength, "logistic", switch_field_V_per_um=switch, width_V_per_um=width)
    v = np.linspace(5.0, 250.0, 50)
    truth = law(v / t_p) / law(op.D31_ANCHOR_V_PER_UM * 1e6)
    strength = float(truth[-1] / truth[np.argmin(abs(v - 100.0))] - 1.0)

    shapes = FAMILIES["field_dependent_d31"].shapes
    knee, p = shapes["log10_knee_V_per_um"], shapes["steepness"]

    def misfit(z):   # within the family's shape bounds
        g = op.plate_gain(v, t_p, strength, 10.0 ** np.clip(z[0], knee.lo, knee.hi), np.clip(z[1], p.lo, p.hi))
        return float(np.max(np.abs(g / truth - 1.0)))

    best = min((minimize(misfit, [k, p], method="Nelder-Mead") for k in (-0.3, 0.0, 0.3) for p in (2.0, 6.0)),
               key=lambda r: r.fun)
    assert best.fun < 0.05


def _bouc_wen(u, alpha, beta_plus_gamma):
    """Bouc-Wen (n = 1, beta = gamma) on the net drive, sample by sample: y = u - h, dh = alpha du - beta |du| h -
    gamma du |h|. Rate-independent; its loop widens with amplitude and saturates at alpha / (beta + gamma)."""
    h, out, b = 0.0, [], beta_plus_gamma / 2
    for i, ui in enumerate(u):
        du = ui - u[i - 1] if i else 0.0
        h += alpha * du - b * abs(du) * h - b * du * abs(h)
        out.append(ui - h)
    return np.array(out)


def test_hysteresis_family_follows_a_bouc_wen_loop_across_bias_voltages():
    """A form the family does not share (Bouc-Wen on the net drive, its loop saturating from ~80 V on) on
    bias-drive-ground cycles at 100, 175 and 250 V, one gain for all (a specimen's), the first cycle left out: the
    family within its shape bounds leaves less than a fifth of the loop's rms. With the density exponent bounded
    at -0.8, as before it reached the scale-free -1 and below, it left 33 % (14 % now)."""
    from scipy.optimize import minimize

    ramp = np.linspace(0.0, 1.0, 120)
    cycle = np.r_[np.zeros(60), ramp, np.ones(100), ramp[::-1]]
    cases = []
    for v in (100.0, 175.0, 250.0):
        drive = np.tile(cycle, 3) * v
        truth = _bouc_wen(2 * drive - v, 0.3, 0.03) / 250.0
        x_b, x_t = drive / 250.0, (v - drive) / 250.0
        cases.append((x_b, op.plate_memory(x_b), x_t, op.plate_memory(x_t), truth, np.arange(drive.size) >= cycle.size))
    shapes = FAMILIES["hysteresis"].shapes
    gamma, tip = shapes["density_exponent"], shapes["tip_share"]
    truths = [t[k] for *_, t, k in cases]

    def left(pred):     # rms of what the best common gain leaves
        gain = sum(p @ q for p, q in zip(pred, truths, strict=True)) / sum(p @ p for p in pred)
        return math.sqrt(sum(float(np.sum((gain * p - q) ** 2)) for p, q in zip(pred, truths, strict=True)))

    def family(z):
        c = float(np.clip(z[2], tip.lo, tip.hi))
        w = op.plate_weights(max(float(z[0]), 0.0), float(np.clip(z[1], gamma.lo, gamma.hi)), c)
        return left([(op.plate_hysteresis(xb, mb, w, c) - op.plate_hysteresis(xt, mt, w, c))[k]
                     for xb, mb, xt, mt, _, k in cases])

    loop = left([(xb - xt)[k] for xb, _, xt, _, _, k in cases])     # about the best straight line
    best = min((minimize(family, [0.05, g0, 1.0], method="Nelder-Mead", options={"maxiter": 200})
                for g0 in (-1.5, 0.0)), key=lambda r: r.fun)
    assert best.fun / loop < 0.2
