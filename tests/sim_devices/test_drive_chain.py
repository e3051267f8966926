"""The bench's drive effects (per PZT plate: Preisach hysteresis, Kelvin-Voigt creep, field-dependent d31) against
independent estimates: a brute-force relay simulation, double quadratures, closed-form step responses, and the
properties that define each form (loops closing at reversals, growth with amplitude, rate independence, a finite
slope after reversal)."""

import math

import numpy as np
import pytest

from sim_devices.drive_chain import (FIELD_HIGH_V_PER_M, FIELD_LOW_V_PER_M, FIELD_REF_V_PER_M, DriveChain,
                                     FieldGain, PronyCreep, full_cycle_gap, hysteresis_setup)
from sim_devices.preisach import (EverettTable, PreisachDensity, PreisachOperator, loop_area_quadrature,
                                  normalised_run)

H = 2.5e-4
PER_VOLT = 1.0 / 250.0   # u in units of the full-scale deflection


def _relays(density, x, n=500):
    """Independent model: a grid of n^2/2 relays, each switching up at alpha and down at beta, weighted by the
    density, stepped sample by sample."""
    g = (np.arange(n) + 0.5) / n
    a, b = np.meshgrid(g, g, indexing="ij")
    mask = a > b
    w, a, b = density(a, b)[mask], a[mask], b[mask]
    up = np.zeros(a.size, bool)
    out = np.empty(x.size)
    for i, xi in enumerate(x):
        up |= xi >= a
        up &= ~(xi <= b)
        out[i] = w[up].sum() / w.sum()
    return out


@pytest.mark.parametrize("r0, kappa", [(0.3, 0.5), (1.0, -0.4)])
def test_preisach_operator_matches_a_relay_simulation(r0, kappa):
    density = PreisachDensity(r0, kappa)
    rng = np.random.default_rng(2)
    knots = np.concatenate([[0.0], rng.uniform(0, 1, 12), [1.0, 0.3, 0.6, 0.45, 0.0, 0.7]])
    x = np.concatenate([np.linspace(knots[i], knots[i + 1], 40, endpoint=False) for i in range(len(knots) - 1)])
    got = normalised_run(PreisachOperator(EverettTable(density)), x)
    np.testing.assert_allclose(got, _relays(density, x), atol=4e-3)   # the relay grid's own resolution (1/500)


def test_major_loop_area_matches_a_double_quadrature():
    density = PreisachDensity(0.5, 0.3)
    op = PreisachOperator(EverettTable(density))
    x = np.linspace(0.0, 1.0, 8001)
    rise = normalised_run(op, x)
    fall = normalised_run(op, x[::-1])[::-1]
    assert np.trapezoid(fall - rise, x) == pytest.approx(loop_area_quadrature(density, n=1201), rel=5e-3)


def _cycle(chain_effects, shapes, bias_V, points=800):
    """u over: bias charged, a drive rise 0 -> bias and fall back; returns (drive, u rising, u falling)."""
    chain = DriveChain(H, PER_VOLT, 155e-6, chain_effects, shapes)
    ramp = np.linspace(0.0, bias_V, points)
    vb = np.concatenate([np.linspace(0.0, bias_V, points), np.full(2 * points, bias_V)])
    vd = np.concatenate([np.zeros(points), ramp, ramp[::-1]])
    u = chain.run(vb, vd)
    return ramp, u[points:2 * points], u[2 * points:][::-1]


def test_hysteresis_loop_grows_with_amplitude_and_closes_on_the_nominal_line():
    """PI's figures for PZT: ~2 % of the span at small signal, 10-15 % at large. The strength is the gap at
    250 V; the loop's tips (the dwells) sit where the nominal model puts them."""
    gaps = []
    for bias in (25.0, 50.0, 100.0, 175.0, 250.0):
        v, rise, fall = _cycle({"hysteresis": 0.12}, {}, bias)
        span = 2 * bias * PER_VOLT
        gaps.append(float(np.max(fall - rise)) / span)
        nominal = PER_VOLT * (2 * v - bias)
        assert rise[-1] == pytest.approx(nominal[-1], abs=1e-9) and fall[0] == pytest.approx(nominal[0], abs=1e-9)
        assert np.all(rise <= nominal + 1e-12) and np.all(fall >= nominal - 1e-12)   # rise below, fall above
    assert gaps[-1] == pytest.approx(0.12, rel=1e-3)
    assert 0.01 < gaps[0] < 0.03                    # small signal: ~2 %
    assert np.all(np.diff(gaps) > 0)                # grows with amplitude


def test_hysteresis_has_a_finite_slope_right_after_each_reversal():
    """No dead band: the first samples after the top reversal already move (a Bouc-Wen form with the old
    parameters held the output still there)."""
    v, rise, fall = _cycle({"hysteresis": 0.16}, {"hysteresis": {"r0": 0.5}}, 250.0)
    nominal_slope = 2 * PER_VOLT
    slope_after_reversal = (fall[-1] - fall[-2]) / (v[-1] - v[-2])
    assert slope_after_reversal > 0.3 * nominal_slope


def test_hysteresis_is_rate_independent_and_forgets_at_zero():
    _, rise_fast, fall_fast = _cycle({"hysteresis": 0.12}, {}, 200.0, points=201)
    _, rise_slow, fall_slow = _cycle({"hysteresis": 0.12}, {}, 200.0, points=1601)
    np.testing.assert_allclose(rise_fast, rise_slow[::8], atol=1e-12)
    np.testing.assert_allclose(fall_fast, fall_slow[::8], atol=1e-12)
    chain = DriveChain(H, PER_VOLT, 155e-6, {"hysteresis": 0.12}, {})
    wave = np.concatenate([np.linspace(0, 1, 300), np.linspace(1, 0, 300)]) * 150.0
    vb = np.full(wave.size, 150.0)
    chain.run(np.linspace(0, 150.0, 300), np.zeros(300))
    first = chain.run(vb, wave)
    second = chain.run(vb, wave)
    np.testing.assert_allclose(first, second, atol=1e-12)   # a cycle from 0 V wipes the memory


def test_hysteresis_strength_is_the_gap_at_full_drive_for_every_shape():
    for shape in ({"r0": 0.5, "kappa": -0.6}, {"r0": 2.0, "kappa": 0.6}):
        hmap = hysteresis_setup(0.1, shape)
        assert full_cycle_gap(hmap, points=4001) == pytest.approx(0.1, rel=2e-3)


def test_creep_step_response_is_the_prony_series():
    creep = PronyCreep(0.02, taus_s=(0.03, 0.7, 12.0), weights=(0.2, 0.5, 0.3))
    chain = DriveChain(H, PER_VOLT, 155e-6, {"creep": 0.02},
                       {"creep": {"tau1_s": 0.03, "tau2_s": 0.7, "tau3_s": 12.0, "weight1": 0.2, "weight2": 0.5,
                                  "weight3": 0.3}})
    n = 200_000   # 50 s
    vd = np.full(n, 100.0)
    u = chain.run(np.zeros(n), vd) / (PER_VOLT * 100.0 * 2)   # bias 0: both plates see +-100 V
    t = H * np.arange(n)
    # the step arrives at the first sample (held from 0 before it): the response a first-order hold gives
    expected = creep.step_response(t)
    np.testing.assert_allclose(u[1:], expected[1:], atol=2e-3 * creep.amplitudes.sum())
    a = creep.amplitudes
    growth = (creep.step_response(100.0) - creep.step_response(0.01)) / 4.0
    assert growth == pytest.approx(0.02, rel=1e-9)
    assert a.sum() > 0


def test_d31_curve_definition_and_monotonicity_for_both_forms():
    for form in ("logistic", "knots"):
        for s in (0.6, -0.4):
            g = FieldGain(s, form=form)
            assert float(g(FIELD_REF_V_PER_M)) == pytest.approx(1.0, abs=1e-12)
            assert float(g(FIELD_HIGH_V_PER_M) / g(FIELD_LOW_V_PER_M)) == pytest.approx(1.0 + s, rel=1e-9)
            e = np.linspace(0, 2e6, 2001)
            step = np.diff(g(e))
            assert np.all(step * math.copysign(1.0, s) >= -1e-12)


def test_d31_gain_reaches_the_free_deflection_at_each_voltage():
    """The bench's u at V_drive = V_bias: the plate at the bias has gain G(V / t_p), the grounded one none."""
    for form in (0.0, 1.0):
        for bias in (100.0, 250.0):
            chain = DriveChain(H, PER_VOLT, 155e-6, {"field_dependent_d31": 0.5},
                               {"field_dependent_d31": {"form": form}})
            u = chain.run(np.full(3, bias), np.full(3, bias))
            g = FieldGain(0.5, form="knots" if form else "logistic")
            assert u[-1] == pytest.approx(PER_VOLT * bias * float(g(bias / 155e-6)), rel=1e-12)


def test_strength_zero_drive_chain_is_the_nominal_line_exactly():
    chain = DriveChain(H, PER_VOLT, 155e-6, {}, {})
    rng = np.random.default_rng(0)
    vb, vd = rng.uniform(0, 250, 100), rng.uniform(0, 250, 100)
    assert np.array_equal(chain.run(vb, vd), PER_VOLT * (2.0 * vd - vb))
