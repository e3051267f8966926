"""The exact discretisations the bench integrates with, against closed forms and plain loops written here."""

import math

import numpy as np
import pytest

from sim_devices.linear_dynamics import FirstOrderLag, SecondOrderMode, first_order_recursion


@pytest.mark.parametrize("a", [0.9995, 0.5, 1e-9, 0.3 + 0.9j, 0.99 * np.exp(0.3j), np.exp(-17 + 2j), 1.0])
def test_recursion_matches_a_plain_loop(a):
    rng = np.random.default_rng(1)
    d = rng.normal(size=5000) + (1j * rng.normal(size=5000) if isinstance(a, complex) else 0.0)
    y, ref = 0.7, []
    for x in d:
        y = a * y + x
        ref.append(y)
    np.testing.assert_allclose(first_order_recursion(a, d, 0.7), ref, rtol=1e-9, atol=1e-9)


def test_first_order_lag_is_exact_for_a_ramp():
    tau, h = 0.03, 2.5e-4
    t = h * np.arange(1, 801)
    z = FirstOrderLag(tau, h).run(0.0, t, 0.0)      # input x(t) = t from rest
    np.testing.assert_allclose(z, t - tau * (1 - np.exp(-t / tau)), rtol=0, atol=1e-15)


def _step_response(t, w, z):
    wd = w * math.sqrt(1 - z * z)
    return 1 - np.exp(-z * w * t) * (np.cos(wd * t) + z / math.sqrt(1 - z * z) * np.sin(wd * t))


@pytest.mark.parametrize("f_Hz, zeta", [(300.0, 0.1), (2000.0, 0.06), (7200.0, 0.05)])
def test_mode_step_and_ramp_responses_are_the_closed_forms(f_Hz, zeta):
    w, h = 2 * math.pi * f_Hz, 2.5e-4
    mode = SecondOrderMode(w, zeta, h)
    n = 400
    t = h * np.arange(1, n + 1)
    x, _ = mode.from_modal(mode.run(0.0, 0.0, np.ones(n + 1)))
    np.testing.assert_allclose(x, _step_response(t, w, zeta), atol=1e-12)
    wd = w * math.sqrt(1 - zeta ** 2)
    x, _ = mode.from_modal(mode.run(0.0, 0.0, h * np.arange(n + 1)))
    ramp = t - 2 * zeta / w + np.exp(-zeta * w * t) * (2 * zeta / w * np.cos(wd * t)
                                                       + (2 * zeta ** 2 - 1) / wd * np.sin(wd * t))
    np.testing.assert_allclose(x, ramp, atol=1e-15)


def test_values_between_grid_points_and_step_integrals_are_exact():
    """A mode faster than the grid (7.2 kHz on a 4 kHz grid): the values between grid points and the integral over
    each step agree with the closed-form step response sampled finely, where linear interpolation would not."""
    w, zeta, h = 2 * math.pi * 7200.0, 0.05, 2.5e-4
    mode = SecondOrderMode(w, zeta, h)
    n = 40
    xi = np.concatenate([[mode.to_modal(0.0, 0.0)], mode.run(0.0, 0.0, np.ones(n + 1))])
    tq = np.linspace(0.0, n * h - 1e-9, 997)
    k = np.floor(tq / h).astype(int)
    got = mode.within_step(xi[k], np.ones_like(tq), np.ones_like(tq), tq - k * h)
    np.testing.assert_allclose(got, _step_response(tq, w, zeta), atol=1e-12)
    fine = np.linspace(0.0, n * h, 400001)
    integral = np.trapezoid(_step_response(fine, w, zeta), fine)
    assert mode.step_integral(xi[:-1], np.ones(n), np.ones(n)).sum() == pytest.approx(integral, rel=1e-9)


def test_a_mode_outside_its_range_is_refused():
    with pytest.raises(ValueError, match="zeta"):
        SecondOrderMode(100.0, 1.0, 1e-3)
