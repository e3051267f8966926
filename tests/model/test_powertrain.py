"""Powertrain: the quasi-static solution against the paper's eq. 4, the energy, the power balance, and conventions."""

import numpy as np
import pytest
from dataclasses import replace

from hamr_bench.errors import ModelError
from hamr_bench.model import Powertrain, actuator_preset, design_preset, powertrain
from hamr_bench.model import transmission as tr

DESIGNS = [1, 2, 3, 4, 5]


@pytest.fixture(scope="module")
def pts():
    return {d: powertrain(d) for d in DESIGNS}


@pytest.mark.parametrize("d", DESIGNS)
def test_blocked_force_is_foot_force_at_full_drive(pts, d):
    p = pts[d]
    V = np.array([100.0, 150.0, 200.0, 250.0])[:, None]
    s = np.array([0.0, 1e-3, 2e-3])[None, :]
    assert np.array_equal(p.blocked_force_N(V, s), p.foot_force_N(V, V, s), equal_nan=True)


@pytest.mark.parametrize("d", DESIGNS)
def test_neutral_is_undriven_equilibrium(pts, d):
    p = pts[d]
    assert abs(p.foot_force_N(0.0, 0.0, 0.0)) < 1e-9
    assert abs(p.foot_force_N(180.0, 90.0, 0.0)) < 1e-9
    assert abs(p.free_foot_height_m(0.0, 0.0)) < 1e-9
    assert abs(p.free_foot_height_m(200.0, 100.0)) < 1e-9


@pytest.mark.parametrize("d", DESIGNS)
def test_drive_pushes_foot_down_and_into_the_support(pts, d):
    p = pts[d]
    assert p.blocked_force_N(200.0, 0.0) > 0
    assert p.free_foot_height_m(200.0, 200.0) < 0
    assert p.free_foot_height_m(200.0, 0.0) > 0
    assert p.foot_force_N(200.0, 0.0, 0.0) < 0   # reverse drive would pull away


@pytest.mark.parametrize("d", [1, 2, 3, 4])
def test_force_is_paper_eq4(pts, d):
    """F R_tra = A F_act - A k_act delta_tra - sum kappa_i Phi_i dPhi_i/d delta_tra, from the kinematics alone
    (the paper's linear serial compliance: coupler strips that never buckle)."""
    p = Powertrain(pts[d].actuator, replace(pts[d].design, coupler_buckling=False))
    g, c = p.geometry, p.coupler_m
    vb, vd = 220.0, 190.0
    h = np.linspace(-0.5e-3, 2e-3, 6)
    th = p.theta_at_height(h)
    a = p.actuator
    F_act = a.tip_force_N(vb, vd, 0.0)
    A, k = p.A, a.stiffness_N_per_m
    flex = np.sum(p.kappa[:, None] * tr.joint_angles_rad(g, c, th) * tr.joint_dangles_ddelta_tra(g, c, th), axis=0)
    rhs = A * F_act - A * k * tr.delta_tra_m(g, c, th) - flex
    assert np.allclose(p.foot_force_N(vb, vd, h) * tr.transmission_ratio(g, c, th), rhs, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("d", [1, 4, 5])
def test_force_is_energy_gradient(pts, d):
    p = pts[d]
    u = float(p.free_actuator_deflection_m(250.0, 250.0))
    h = np.linspace(-0.5e-3, 2.5e-3, 7)
    e = 1e-8
    fd = (p.energy_J(p.theta_at_height(h + e), u) - p.energy_J(p.theta_at_height(h - e), u)) / (2 * e)
    assert np.allclose(p.foot_force_N(250.0, 250.0, h), fd, rtol=1e-5, atol=1e-9)


@pytest.mark.parametrize("d", [1, 3])
def test_buckled_chain_generalises_eq4(d):
    """With buckling the serial term A k_act (u - delta_tra) becomes the chain force; nothing else changes. The
    strips are 300 um long: their Euler load is then low enough that both designs' paths buckle them."""
    p = powertrain(d, flexure_length_m=300e-6, flexure_width_m=1.5e-3)
    g, c = p.geometry, p.coupler_m
    h = np.linspace(0.0, 3e-3, 7)
    th = p.theta_at_height(h)
    gap = float(p.free_actuator_deflection_m(250.0, 250.0)) - tr.delta_tra_m(g, c, th)
    assert np.any(gap > p.serial_chain.buckling_gap_m)      # the path does buckle the strips
    flex = np.sum(p.kappa[:, None] * tr.joint_angles_rad(g, c, th) * tr.joint_dangles_ddelta_tra(g, c, th), axis=0)
    rhs = p.serial_chain.force_N(gap) - flex
    assert np.allclose(p.blocked_force_N(250.0, h) * tr.transmission_ratio(g, c, th), rhs, rtol=1e-9, atol=1e-12)
    assert np.allclose(p.coupler_force_N(250.0, 250.0, h), p.serial_chain.force_N(gap), rtol=1e-12)


def test_power_balance_with_buckled_strips():
    """Piezo work = actuator spring + serial spring + the two strips' elastica energy + flexures + work on the leg,
    with every internal deflection resolved explicitly and the strips' energy integrated from their own
    load-shortening law (not from the chain's energy)."""
    p = powertrain(3, flexure_length_m=200e-6, flexure_width_m=1.5e-3)
    a, strip = p.actuator, p.design.flexure_strip
    ka, ks = a.stiffness_N_per_m, p.k_ser_N_per_m
    s = np.linspace(0.0, 1.0, 20001)
    h = 3e-3 - 3e-3 * s
    vd, vb = 125.0 + 125.0 * s, 250.0
    th = p.theta_at_height(h)
    u = p.free_actuator_deflection_m(vb, vd)
    F = p.serial_chain.force_N(u - tr.delta_tra_m(p.geometry, p.coupler_m, th))
    assert F.max() > 1.05 * strip.euler_load_N
    Fp = a.tip_force_N(vb, vd, 0.0)
    dact = u - F / ka                                    # actuator tip deflection toward the hip
    short = strip.shortening_m(F)                        # each strip
    def trap(y, x):
        return np.concatenate([[0.0], np.cumsum(0.5 * (y[1:] + y[:-1]) * np.diff(x))])
    strips = 2 * trap(np.where(short > 0, F, 0.0), short)
    phi = tr.joint_angles_rad(p.geometry, p.coupler_m, th)
    stored = 0.5 * ka * dact**2 + 0.5 * F**2 / ks + strips + 0.5 * np.sum(p.kappa[:, None] * phi**2, axis=0)
    W_act = trap(Fp, dact)[-1]
    W_leg = trap(p.foot_force_N(vb, vd, h), -h)[-1]
    assert W_act == pytest.approx(stored[-1] - stored[0] + W_leg, rel=2e-4)


@pytest.mark.parametrize("d", [2, 4])
def test_power_balance_conserves_energy_along_quasi_static_path(pts, d):
    """Actuator work = change of stored energy (actuator spring, serial spring, flexures) + work done on the leg.

    The internal actuator deflection is resolved explicitly (eq. 2) rather than through A, so this checks the
    series elimination as well as the sign of every term. Path: foot moved from 2 mm up to 0.5 mm down while the
    drive ramps from neutral to full (so the piezo force changes along the path).
    """
    p = pts[d]
    a = p.actuator
    ka, ks = a.stiffness_N_per_m, p.k_ser_N_per_m
    n = 20001
    s = np.linspace(0.0, 1.0, n)
    h = 2e-3 - 2.5e-3 * s
    vd = 110.0 + 110.0 * s
    vb = 220.0
    th = p.theta_at_height(h)
    dtra = tr.delta_tra_m(p.geometry, p.coupler_m, th)
    Fp = a.tip_force_N(vb, vd, 0.0)
    dact = (Fp + ks * dtra) / (ka + ks)
    phi = tr.joint_angles_rad(p.geometry, p.coupler_m, th)
    stored = 0.5 * ka * dact**2 + 0.5 * ks * (dtra - dact) ** 2 + 0.5 * np.sum(p.kappa[:, None] * phi**2, axis=0)
    F = p.foot_force_N(vb, vd, h)
    def trap(y, x):
        return float(np.sum(0.5 * (y[1:] + y[:-1]) * np.diff(x)))
    W_act = trap(Fp, dact)                 # piezo force through the actuator tip's own travel
    W_leg = trap(F, -h)                    # foot pushes down with F while moving down by -dh
    # the piezo force is a function of the drive, not a potential: its work is exact only as the line integral
    assert W_act == pytest.approx(stored[-1] - stored[0] + W_leg, rel=1e-6, abs=1e-13)


def test_stiffer_flexure_resists_motion():
    a = actuator_preset(2)
    d = design_preset(1)
    soft = Powertrain(a, d)
    stiff = Powertrain(a, replace(d, kappa_N_m_per_rad=(d.kappa_N_m_per_rad[0], d.kappa_N_m_per_rad[1], 5e-5)))
    assert stiff.free_displacement_m(200.0) < soft.free_displacement_m(200.0)
    assert stiff.static_displacement_m(2.65e-3) < soft.static_displacement_m(2.65e-3)
    assert stiff.leg_stiffness_N_per_m(0.0) > soft.leg_stiffness_N_per_m(0.0)
    # torque of a lone flexure opposes its rotation
    only = Powertrain(a, replace(d, kappa_N_m_per_rad=(0.0, 0.0, 1e-4)))
    th = d.geometry.theta_fab_rad + np.array([-0.05, 0.05])
    assert np.all(np.sign(only._flex_torque(th)) == np.sign(th - d.geometry.theta_fab_rad))


@pytest.mark.parametrize("d", DESIGNS)
def test_free_and_static_solutions_are_equilibria(pts, d):
    p = pts[d]
    V = np.array([100.0, 175.0, 250.0])
    hf = p.free_foot_height_m(V, V)
    assert np.allclose(p.foot_force_N(V, V, hf), 0.0, atol=1e-10)
    F = np.array([0.5e-3, 1.5e-3, 2.65e-3])
    sag = p.static_displacement_m(F)
    ok = np.isfinite(sag)
    assert np.all(sag[ok] > 0)
    assert np.allclose(p.foot_force_N(0.0, 0.0, sag[ok]), F[ok], rtol=1e-8)


def test_broadcasting_shapes(pts):
    p = pts[4]
    V = np.linspace(0, 250, 5)[:, None]
    s = np.linspace(0, 3e-3, 4)[None, :]
    assert p.blocked_force_N(V, s).shape == (5, 4)
    assert p.free_displacement_m(V).shape == (5, 1)
    assert p.static_displacement_m(np.ones((2, 3)) * 1e-3).shape == (2, 3)


def test_voltage_limit_is_enforced_and_named(pts):
    with pytest.raises(ModelError, match="v_bias_V=300 V exceeds the configured limit 250 V"):
        pts[4].blocked_force_N(300.0, 0.0)
    p = powertrain(4, voltage_limit_V=300.0)
    assert np.isfinite(p.blocked_force_N(300.0, 0.0))


def test_biased_neutral_is_rotated_away_from_fabrication(pts):
    # the bias rotates the crank in the drive direction: foot neutral below the unbiased one
    g = pts[4].geometry
    assert pts[4].theta_neutral_rad > pts[1].theta_neutral_rad
    assert tr.foot_height_fab_m(g, pts[4].theta_neutral_rad) < tr.foot_height_fab_m(g, pts[1].theta_neutral_rad)


def test_bad_design():
    with pytest.raises(ModelError, match="design"):
        design_preset(6)
    with pytest.raises(ModelError, match="k_ser"):
        replace(design_preset(1), k_ser_N_per_m=-1.0)


@pytest.mark.parametrize("d", [2, 4, 5])
def test_fused_solver_residual_matches_readable_energy_derivative(pts, d):
    p = pts[d]
    th = p.theta_neutral_rad + np.linspace(-0.2, 0.2, 9)
    u = 40e-6
    assert np.allclose(p._G(th, u, 0.0), p.denergy_dtheta(th, u), rtol=1e-10, atol=1e-15)


def test_free_height_depends_on_drive_only_through_u(pts):
    p = pts[4]
    vb, vd = 240.0, np.array([0.0, 60.0, 200.0, 240.0])
    u = p.free_actuator_deflection_m(vb, vd)
    assert np.array_equal(p.free_foot_height_at_deflection_m(u), p.free_foot_height_m(vb, vd))
    assert np.array_equal(p.plate_voltage_map(vd), vd)
