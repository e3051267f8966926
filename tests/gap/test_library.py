"""Candidate forms of the gap diagnosis, checked against their definitions (no simulation)."""

import math

import numpy as np
from hypothesis import given, settings, strategies as st

from analysis.gap.library import CREEP_T_MAX_S, CREEP_T_MIN_S, EdgeLoss, LinearFieldD31, log_creep, play
from hamr_bench.model import actuator_preset


def _play_reference(x, w):
    """The play operator's definition, one sample at a time."""
    y, out = x[0], []
    for xi in x:
        y = min(max(y, xi - w), xi + w)
        out.append(y)
    return np.array(out)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-100, 100), min_size=2, max_size=200), st.floats(0, 30))
def test_play_matches_its_definition(values, w):
    x = np.repeat(np.array(values), 3)   # flat pieces too
    assert np.allclose(play(x, w), _play_reference(x, w))


def test_play_width_zero_is_identity():
    x = np.sin(np.linspace(0, 20, 500))
    assert np.array_equal(play(x, 0.0), x)


def test_log_creep_step_response_follows_the_log_law():
    t = np.arange(0, 200, 0.002)
    s = np.where(t >= 1.0, 100.0, 0.0)
    g = 0.02
    t_eval = np.array([1.1, 2.0, 11.0, 50.0, 150.0])
    got = log_creep(t, s, g, t_eval)
    tau = t_eval - t[np.argmax(s > 0)]
    want = 100.0 * (1 - g * np.where(tau < CREEP_T_MAX_S, np.log10(CREEP_T_MAX_S / (tau + CREEP_T_MIN_S)), 0.0))
    assert np.allclose(got, want, rtol=1e-3)
    # one decade later the response has grown by g x step
    a, b = log_creep(t, s, g, np.array([2.0, 11.0]))
    assert math.isclose(b - a, 100 * g * math.log10((10 + CREEP_T_MIN_S) / (1 + CREEP_T_MIN_S)), rel_tol=1e-3)


def test_edge_loss_removes_the_same_kerf_along_the_taper():
    a = actuator_preset(2, "effective")
    s = 0.15
    b = EdgeLoss(strength=s).actuator_params(a)
    assert math.isclose(b.width_nom_m, (1 - s) * a.width_nom_m)
    # base width minus tip width (the taper) is unchanged by a constant kerf: w (w_r - (2 - w_r)) = 2 w (w_r - 1)
    assert math.isclose(2 * b.width_nom_m * (b.width_ratio - 1), 2 * a.width_nom_m * (a.width_ratio - 1))


def test_linear_d31_gain_at_two_volts_per_micron():
    a = actuator_preset(2, "effective")
    v = 2e6 * a.pzt_thickness_m   # plate voltage giving 2 V/um
    assert math.isclose(float(LinearFieldD31(strength=0.3).plate_voltage(np.array([v]), a)[0]), 1.3 * v)
    assert math.isclose(float(LinearFieldD31(strength=0.3).plate_voltage(np.array([-v]), a)[0]), -1.3 * v)
