"""Foot friction: the closed form against (1) a vector force-and-torque balance of the leg written out by hand and
(2) an incremental stick-slip contact simulation in which the slide direction is not assumed but emerges from how
the contact is loaded (drive ramp against a fixed support, or the support raised into the foot)."""

import numpy as np
import pytest

from hamr_bench.errors import ModelError
from hamr_bench.model import powertrain
from hamr_bench.model.contact import FOOT_FRICTION_MU_BAND, LIFTED, PRESSING, friction_reading_ratio


def _statics_ratio(beta, mu, pressing, side):
    """Leg from the hip (origin) to the foot at side*L cos(beta), -L sin(beta); the drive torque pushes the foot
    down. Friction opposes the foot's slide: the foot's velocity when the leg rotates foot-down is
    d/dbeta (side L cos, -L sin) = (-side L sin, -L cos): it slides toward -side when pressing."""
    L, Q = 7e-3, 1e-4
    foot = np.array([side * L * np.cos(beta), -L * np.sin(beta)])
    slide_x = -side if pressing else side
    # contact force on the foot: (T, N) with T = -mu N sign(slide_x); its torque about the hip must cancel the
    # drive torque. Torque of (Fx, Fy) at (x, y) = x Fy - y Fx; the drive's torque pushing the foot down is -side Q.
    unit = np.array([-mu * slide_x, 1.0])                  # contact force per unit N
    torque_per_N = foot[0] * unit[1] - foot[1] * unit[0]
    N = side * Q / torque_per_N
    N0 = side * Q / foot[0]
    return N / N0


@pytest.mark.parametrize("side", [1, -1])
def test_closed_form_matches_the_vector_statics(side):
    rng = np.random.default_rng(3)
    for _ in range(50):
        beta, mu = rng.uniform(0.05, 1.2), rng.uniform(0.0, 0.4)
        for pressing, s in ((True, PRESSING), (False, LIFTED)):
            expected = _statics_ratio(beta, mu, pressing, side)
            if expected <= 0:      # wedged
                assert np.isnan(friction_reading_ratio(beta, mu, s))
            else:
                assert float(friction_reading_ratio(beta, mu, s)) == pytest.approx(expected, rel=1e-12)


def _stick_slip_reading(beta0, mu, scenario):
    """Quasi-static stick-slip: a rigid leg (length L, angle th below horizontal) on a torsional spring k_th about
    the hip, the foot on a horizontal support with a normal penalty spring k_n and an elastic-perfectly-plastic
    tangential spring k_t
    (|T| <= mu N, the anchor slides when exceeded). Returns (N, N0) at the end, where N0 is what a frictionless
    support reads for the same leg torque."""
    L, k_th, k_n, k_t = 7e-3, 2e-3, 2e4, 2e4
    def x_of(th):
        return L * np.cos(th)
    def y_of(th):
        return -L * np.sin(th)
    th_cmd0 = beta0
    z0 = y_of(beta0)                     # support touching the foot at beta0, unloaded
    anchor = x_of(beta0)
    th = beta0
    steps = 400
    for i in range(1, steps + 1):
        f = i / steps
        if scenario == "drive":          # drive torque ramps against a fixed support
            th_cmd, z = th_cmd0 + 0.02 * f, z0
        else:                            # the support is raised into the driven foot
            th_cmd, z = th_cmd0 + 0.02, z0 + 20e-6 * f
        # solve torque balance for th with the anchor fixed (stick), then slip if |T| > mu N
        for _ in range(60):
            N = k_n * max(0.0, z - y_of(th))
            T = -k_t * (x_of(th) - anchor)
            if abs(T) > mu * N:          # slip: friction saturates, anchor follows the foot
                T = np.sign(T) * mu * N
            torque = k_th * (th_cmd - th) - x_of(th) * N + y_of(th) * T   # generalised forces on th
            # derivative by finite difference (robust across the stick/slip switch)
            h = 1e-9
            thp = th + h
            Np = k_n * max(0.0, z - y_of(thp))
            Tp = -k_t * (x_of(thp) - anchor)
            if abs(Tp) > mu * Np:
                Tp = np.sign(Tp) * mu * Np
            dtorque = (k_th * (th_cmd - thp) - x_of(thp) * Np + y_of(thp) * Tp - torque) / h
            th -= torque / dtorque
            if abs(torque) < 1e-15:
                break
        N = k_n * max(0.0, z - y_of(th))
        T = -k_t * (x_of(th) - anchor)
        if abs(T) > mu * N:
            anchor = x_of(th) + np.sign(T) * mu * N / k_t
            T = np.sign(T) * mu * N
    N0 = k_th * (th_cmd - th) / x_of(th)          # the same leg torque on a frictionless support
    return N, N0, th


@pytest.mark.parametrize("beta_deg,mu", [(60.0, 0.3), (45.0, 0.2), (30.0, 0.25)])
def test_slide_direction_emerges_from_the_loading(beta_deg, mu):
    beta = np.radians(beta_deg)
    N, N0, th = _stick_slip_reading(beta, mu, "drive")
    assert pytest.approx(float(friction_reading_ratio(th, mu, PRESSING)), rel=0.02) == N / N0
    assert N < N0
    N, N0, th = _stick_slip_reading(beta, mu, "raise")
    assert pytest.approx(float(friction_reading_ratio(th, mu, LIFTED)), rel=0.02) == N / N0
    assert N > N0


def test_limits_and_band():
    assert float(friction_reading_ratio(1.0, 0.0, PRESSING)) == 1.0
    assert float(friction_reading_ratio(0.0, 0.3, LIFTED)) == 1.0          # horizontal leg: no slide
    assert float(friction_reading_ratio(1.0, 0.3, 0)) == 1.0
    assert np.isnan(friction_reading_ratio(np.radians(75), 0.3, LIFTED))   # mu tan(beta) > 1: wedged
    lo, hi = FOOT_FRICTION_MU_BAND
    # the range: legs 57-63 deg below horizontal, mu 0.2-0.3 -> 0.6-2.4x
    b = np.radians([57.0, 63.0])
    r = np.concatenate([friction_reading_ratio(b, m, s) for m in (lo, hi) for s in (PRESSING, LIFTED)])
    assert 0.6 < r.min() < 0.65 and 2.3 < r.max() < 2.5
    with pytest.raises(ModelError, match="mu"):
        friction_reading_ratio(1.0, -0.1, PRESSING)


def test_powertrain_applies_friction_at_the_contact_leg_angle():
    p = powertrain(4)
    h = np.array([0.0, 1e-3, 2e-3])
    f0 = p.blocked_force_N(250.0, h)
    beta = p.leg_angle_rad(p.theta_at_height(h))
    # the leg angle is the hip-to-foot line: its sine is the foot's depth below the hip over the leg length
    g = p.geometry
    depth = g.leg_length_m * np.sin(g.leg_angle0_rad) - (h + p._h_neutral_fab)
    assert np.allclose(np.sin(beta), depth / g.leg_length_m, rtol=1e-12)
    for mu, s in ((0.25, PRESSING), (0.25, LIFTED)):
        assert np.allclose(p.blocked_force_N(250.0, h, mu, s), f0 * friction_reading_ratio(beta, mu, s))
    assert np.array_equal(p.blocked_force_N(250.0, h, 0.0), f0)
