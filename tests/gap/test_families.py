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


def _play_reference(x, w):
    y, out = x[0], []
    for xi in x:
        y = min(max(y, xi - w), xi + w)
        out.append(y)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-100, 100), min_size=2, max_size=200), st.floats(0, 30))
def test_play_matches_its_definition(values, w):
    x = np.repeat(np.array(values), 3)
    assert np.allclose(op.play(x, w), _play_reference(x, w))


def _pi(u, strength, gamma):
    w = op.pi_weights(strength, gamma)
    return (u - w @ op.pi_deviations(u)) / op.pi_full_drive_gain(w)


def _triangle(amplitude, cycles=4, n=400):
    t = np.linspace(0, cycles, cycles * n + 1)
    return amplitude * (2 * np.abs(2 * (t - np.floor(t + 0.5))) - 1)   # starts at -A


def _loop_half_width(u, y, amplitude):
    """Half the vertical distance between the falling and the rising branch at u = 0, last cycle."""
    last = slice(len(u) - 401, len(u))
    uu, yy = u[last], y[last]
    rising = np.r_[np.diff(uu) > 0, False]
    up = np.interp(0.0, uu[rising], yy[rising])
    falling = ~rising
    order = np.argsort(uu[falling])
    down = np.interp(0.0, uu[falling][order], yy[falling][order])
    return 0.5 * (down - up)


@pytest.mark.parametrize("gamma", [-1.0, 0.0, 1.0])
def test_pi_loop_half_width_at_full_drive_is_the_strength(gamma):
    u = _triangle(1.0)
    y = _pi(u, 0.08, gamma)
    span = y[-401:].max() - y[-401:].min()
    assert span == pytest.approx(2.0, rel=1e-3)           # the full-drive span is kept
    assert 2 * _loop_half_width(u, y, 1.0) / span == pytest.approx(0.08, rel=0.03)


def test_pi_loop_grows_with_amplitude_as_the_density_says():
    # density ~ r^gamma: half-width ~ A^(gamma + 2), i.e. the loop's share of the span ~ A^(gamma + 1)
    for gamma in (0.0, 1.0):
        h = [_loop_half_width(_triangle(a), _pi(_triangle(a), 0.08, gamma), a) for a in (0.4, 0.8)]
        assert h[1] / h[0] == pytest.approx(2.0 ** (gamma + 2), rel=0.15)


def test_pi_loop_closes_at_the_reversals_with_a_finite_slope():
    u = _triangle(1.0, cycles=3)
    y = _pi(u, 0.1, 0.0)
    period = 400
    # after the first cycle every cycle repeats: the loop closes
    assert np.allclose(y[period:2 * period], y[2 * period:3 * period], atol=1e-9)
    # right after a reversal the slope is 1 - sum alpha (> 0), then rises toward 1
    w = op.pi_weights(0.1, 0.0)
    assert 0 < op.pi_slope_after_reversal(0.1, 0.0) == pytest.approx(1 - w.sum())


def test_creep_kernel_log_law_limit_and_unit_mean_slope_per_decade():
    # growth from 10 ms to 100 s is 4 decades x 1 per decade for any exponent
    tau = np.array([0.01, 100.0])
    for n in (0.0, 0.2, 0.5):
        k = op.creep_kernel(tau - op.CREEP_TAU0_S, n)
        assert (k[1] - k[0]) / 4.0 == pytest.approx(1.0, rel=1e-6)
        assert op.creep_kernel(np.array([1.0 - op.CREEP_TAU0_S]), n)[0] == pytest.approx(0.0, abs=1e-9)
    t = np.array([0.01, 0.1, 10.0])
    assert np.allclose(op.creep_kernel(t, 1e-9), np.log10(t + op.CREEP_TAU0_S), atol=1e-6)


def test_creep_response_of_a_step_is_the_kernel():
    dt = 1e-3
    y = np.r_[np.zeros(100), np.ones(5000)]
    r = op.creep_response(y, dt, 0.2)
    tau = (np.arange(5000)) * dt
    assert np.allclose(r[100:], op.creep_kernel(tau, 0.2), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("s,q", [(0.8, 0.0), (0.8, 1.0), (-0.4, 0.5), (1.0, -0.5)])
def test_d31_strength_is_the_gain_ratio_250_to_100_volts_either_sign(s, q):
    t_p = 155e-6
    v = np.array([100.0, 250.0])
    g = op.plate_map(v, t_p, s, q) / v
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
    twice the length: the yardstick `selfcheck.shift_sigmas` measures hidden shifts with."""
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


def test_shift_sigmas_measures_the_hidden_fabrication_shifts_only():
    from analysis.gap.families import FABRICATION
    from analysis.gap.selfcheck import EXCLUDED_FROM_DRAW, shift_sigmas
    from sim_devices.scenarios import LIBRARY_EFFECTS, draw_scenario

    pool = tuple(n for n in LIBRARY_EFFECTS if n not in EXCLUDED_FROM_DRAW)
    found = 0
    for seed in range(40):
        sig = shift_sigmas(seed)
        sc = draw_scenario(seed, fixtures=("actuator",), pool=pool)
        fabrication = {e.library_name for e in sc.effects if not e.decoy and e.library_name in FABRICATION}
        assert set(sig) == fabrication, seed
        found += bool(sig)
        assert all(v > 0 for v in sig.values())
    assert found >= 3
