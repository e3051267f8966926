"""Slider-crank kinematics: analytic derivatives against finite differences, closing, and the leg mapping."""

import numpy as np
import pytest

from hamr_bench.errors import ModelError
from hamr_bench.model import GEOMETRY, design_preset
from hamr_bench.model import transmission as tr
from hamr_bench.model.transmission import SliderCrankGeometry

H = 1e-7


def _thetas(g, coupler):
    th = g.theta_fab_rad + np.linspace(-0.3, 0.3, 13)
    s = g.crank_m * np.sin(th) - g.offset_m
    return th[np.abs(s) < 0.95 * coupler]


@pytest.mark.parametrize("design", [1, 4])
def test_ddelta_and_dphi_dtheta_by_finite_difference(design):
    g = GEOMETRY
    c = design_preset(design).coupler_m
    th = _thetas(g, c)
    fd = (tr.delta_tra_m(g, c, th + H) - tr.delta_tra_m(g, c, th - H)) / (2 * H)
    assert np.allclose(tr.ddelta_tra_dtheta(g, c, th), fd, rtol=1e-6, atol=1e-12)
    fd_phi = (tr.joint_angles_rad(g, c, th + H) - tr.joint_angles_rad(g, c, th - H)) / (2 * H)
    assert np.allclose(tr.joint_dangles_dtheta(g, c, th), fd_phi, rtol=1e-6, atol=1e-9)


@pytest.mark.parametrize("design", [1, 3, 4])
def test_R_tra_and_dphi_ddelta_by_finite_difference_in_delta(design):
    """Parametrise by delta_tra directly: step the input, re-solve theta, difference the leg and joint angles."""
    g = GEOMETRY
    c = design_preset(design).coupler_m
    th = _thetas(g, c)
    d0 = tr.delta_tra_m(g, c, th)
    eps = 1e-9
    # invert delta_tra(theta) locally by Newton on the analytic function (independent of the ratio formula)
    def theta_at(delta, guess):
        t = guess.copy()
        for _ in range(30):
            slope = (tr.delta_tra_m(g, c, t + 1e-7) - tr.delta_tra_m(g, c, t - 1e-7)) / 2e-7
            t = t - (tr.delta_tra_m(g, c, t) - delta) / slope
        return t
    tp, tm = theta_at(d0 + eps, th), theta_at(d0 - eps, th)
    def leg(t):
        return -tr.foot_height_fab_m(g, t)
    R_fd = (leg(tp) - leg(tm)) / (2 * eps)
    assert np.allclose(tr.transmission_ratio(g, c, th), R_fd, rtol=1e-4)
    dphi_fd = (tr.joint_angles_rad(g, c, tp) - tr.joint_angles_rad(g, c, tm)) / (2 * eps)
    assert np.allclose(tr.joint_dangles_ddelta_tra(g, c, th), dphi_fd, rtol=1e-4, atol=1e-3)


def test_flexures_straight_in_fabricated_configuration():
    g = GEOMETRY
    assert np.allclose(tr.joint_angles_rad(g, g.coupler_m, g.theta_fab_rad), 0.0)
    assert tr.delta_tra_m(g, g.coupler_m, g.theta_fab_rad) == 0.0


def test_lengthened_coupler_pushes_input_back():
    """A longer input link at the fabricated angle sits b * l / sqrt(l^2 - s^2) further from the hip (delta < 0)."""
    g = GEOMETRY
    b = 100e-6
    d = float(tr.delta_tra_m(g, g.coupler_m + b, g.theta_fab_rad))
    assert d < 0 and abs(d) >= b * 0.999


def test_joint_relation_phi2_is_crank_minus_coupler():
    g = GEOMETRY
    th = g.theta_fab_rad + 0.1
    p1, p2, p3 = tr.joint_angles_rad(g, g.coupler_m, th)
    assert p2 == pytest.approx(p3 - p1)
    assert p3 == pytest.approx(0.1)


def test_foot_height_inverse():
    g = GEOMETRY
    th = g.theta_fab_rad + np.linspace(-0.2, 0.2, 7)
    assert np.allclose(tr.theta_from_foot_height(g, tr.foot_height_fab_m(g, th)), th)


def test_geometry_that_cannot_close_is_named():
    with pytest.raises(ModelError, match="cannot close"):
        SliderCrankGeometry(crank_m=1e-3, coupler_m=0.2e-3, offset_m=0.0, theta_fab_rad=1.2, leg_length_m=6e-3)
    with pytest.raises(ModelError, match="crank_m"):
        SliderCrankGeometry(crank_m=-1e-3, coupler_m=2e-3, offset_m=0.0, theta_fab_rad=0.3, leg_length_m=6e-3)
