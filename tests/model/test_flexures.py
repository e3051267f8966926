"""Kapton strips: PRB stiffness and Euler load against hand numbers, the elastica law against a numerically shot
elastica (an independent solution of the beam equation), and the serial chain as a potential."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from hamr_bench.errors import ModelError
from hamr_bench.model.flexures import FlexureStrip, SerialChain, prb_band_N_m_per_rad


def test_prb_and_euler_numbers_by_hand():
    s = FlexureStrip(12.5e-6, 1.5e-3, 200e-6)
    second_moment = 1.5e-3 * (12.5e-6) ** 3 / 12                       # 2.44e-19 m^4
    assert s.prb_stiffness_N_m_per_rad == pytest.approx(2.5e9 * second_moment / 200e-6)
    assert s.prb_stiffness_N_m_per_rad == pytest.approx(3.05e-6, rel=1e-2)
    assert s.euler_load_N == pytest.approx(np.pi**2 * 2.5e9 * second_moment / 200e-6**2)
    assert s.euler_load_N == pytest.approx(0.150, rel=1e-2)
    # 8x at double thickness; clamped-clamped (K = 0.5) four times the guided mode
    assert FlexureStrip(25e-6, 1.5e-3, 200e-6).euler_load_N == pytest.approx(8 * s.euler_load_N)
    assert FlexureStrip(12.5e-6, 1.5e-3, 200e-6, end_factor=0.5).euler_load_N == pytest.approx(4 * s.euler_load_N)
    lo, hi = prb_band_N_m_per_rad(25e-6)
    assert lo == pytest.approx(2.44e-5, rel=1e-2) and hi == pytest.approx(6.51e-5, rel=1e-2)


def _shot_elastica(P_over_Pcr: float, L: float = 1.0) -> float:
    """Shortening / L of a guided strip (slope 0 at both ends) under P, by shooting on the beam equation
    EI theta'' = -P sin(theta): find the end curvature whose slope returns to 0 exactly at s = L."""
    lam2 = P_over_Pcr * np.pi**2 / L**2            # P / EI

    def rhs(s, y):
        return [y[1], -lam2 * np.sin(y[0]), 1.0 - np.cos(y[0])]

    def back_to_zero(s, y):
        return y[0]
    back_to_zero.direction = -1

    def return_length(c):
        back_to_zero.terminal = True
        sol = solve_ivp(rhs, (0, 10 * L), [0.0, c, 0.0], events=back_to_zero, rtol=1e-11, atol=1e-13)
        return sol.t_events[0][0] - L, sol

    c = brentq(lambda c: return_length(c)[0], 1e-3 * np.sqrt(lam2), 1.999 * np.sqrt(lam2), xtol=1e-13)
    _, sol = return_length(c)
    return float(sol.y_events[0][0][2] / L)


@pytest.mark.parametrize("ratio", [1.02, 1.2, 1.6, 2.5])
def test_elastica_matches_a_shot_solution(ratio):
    s = FlexureStrip(12.5e-6, 1.5e-3, 150e-6)
    P = ratio * s.euler_load_N
    expected = _shot_elastica(ratio) * s.length_m
    assert float(s.shortening_m(P)) == pytest.approx(expected, rel=2e-3)
    assert float(s.post_buckling_load_N(expected)) == pytest.approx(P, rel=2e-3)


def test_post_buckling_starts_with_the_small_deflection_slope():
    s = FlexureStrip(12.5e-6, 1.75e-3, 150e-6)
    d = np.array([1e-4, 1e-3]) * s.length_m
    # P = P_cr (1 + shortening / 2L) to first order
    assert np.allclose(s.post_buckling_load_N(d), s.euler_load_N * (1 + d / (2 * s.length_m)), rtol=1e-3)
    assert float(s.shortening_m(0.99 * s.euler_load_N)) == 0.0


@pytest.fixture
def chain():
    return SerialChain(1144.0, FlexureStrip(12.5e-6, 1.75e-3, 150e-6))


def test_chain_is_linear_below_the_euler_load_and_in_tension(chain):
    g = np.array([-3e-4, -1e-5, 0.0, 0.5 * chain.buckling_gap_m, chain.buckling_gap_m])
    assert np.allclose(chain.force_N(g), 1144.0 * g, rtol=1e-12)
    assert np.allclose(chain.energy_J(g), 0.5 * 1144.0 * g**2, rtol=1e-12)


def test_chain_force_is_the_energy_gradient(chain):
    g = np.linspace(-1e-4, 8e-4, 301)
    h = 1e-9
    fd = (chain.energy_J(g + h) - chain.energy_J(g - h)) / (2 * h)
    assert np.allclose(chain.force_N(g), fd, rtol=1e-5, atol=1e-8)


def test_chain_gap_splits_into_springs_and_strips(chain):
    # past the onset the gap is the linear chain's stretch plus both strips' elastica shortening
    F = chain.buckling_load_N * np.array([1.05, 1.3, 1.8])
    gap = F / 1144.0 + 2 * chain.strip.shortening_m(F)
    assert np.allclose(chain.force_N(gap), F, rtol=2e-3)
    # the buckled chain is much softer than the linear one, but not flat
    assert 0 < chain.post_buckling_slope_N_per_m < 0.5 * 1144.0


def test_bad_strip_is_named():
    with pytest.raises(ModelError, match="flexure strip length_m"):
        FlexureStrip(12.5e-6, 1.5e-3, 0.0)
