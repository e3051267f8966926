"""Effects: strength 0 is the nominal model exactly, effects compose, and each implemented effect does its job."""

from dataclasses import dataclass

import numpy as np
import pytest

from hamr_bench.errors import ModelError
from hamr_bench.model import BaseCompliance, Effect, FieldDependentD31, PlayHysteresis, powertrain

V = np.array([0.0, 60.0, 125.0, 250.0])[:, None]
S = np.array([0.0, 0.4e-3, 1e-3])[None, :]


@dataclass(frozen=True)
class Vandal(Effect):
    """An effect defined outside hamr_bench.model that wrecks every hook: harmless at strength 0."""

    name: str = "vandal"

    def actuator_params(self, params):
        raise AssertionError("called at strength 0")

    def plate_voltage(self, v, actuator):
        return v * 1e6

    def serial_stiffness(self, k, actuator):
        return 1e-9

    def foot_force(self, f):
        return f * 0

    def voltage_series(self, t, vb, vd):
        return vb * 0, vd * 0


def _outputs(p):
    return (p.blocked_force_N(V, S), p.free_displacement_m(V), p.static_displacement_m(np.array([1e-3, 2e-3])),
            p.foot_force_N(200.0, 37.0, S))


@pytest.mark.parametrize("effects", [
    (BaseCompliance(0.0),), (FieldDependentD31(0.0),), (PlayHysteresis(0.0),), (Vandal(0.0),),
    (BaseCompliance(0.0), FieldDependentD31(0.0), Vandal(0.0)),
])
@pytest.mark.parametrize("design", [2, 4])
def test_strength_zero_is_nominal_exactly(effects, design):
    nominal = _outputs(powertrain(design))
    with_effects = _outputs(powertrain(design, effects=effects))
    for a, b in zip(nominal, with_effects):
        assert np.array_equal(a, b, equal_nan=True)
    t = np.linspace(0, 1, 50)
    vd = 125 + 125 * np.sin(2 * np.pi * t)
    vb2, vd2 = powertrain(design, effects=effects).apply_voltage_series(t, 250.0, vd)
    assert np.array_equal(vd2, vd) and vb2 == 250.0


def test_base_compliance_lowers_force_keeps_free_stroke():
    nom = powertrain(4)
    eff = powertrain(4, effects=(BaseCompliance(0.5),))
    assert eff.blocked_force_N(200.0, 0.0) < nom.blocked_force_N(200.0, 0.0)
    # the series spring carries no load when nothing touches the foot, except through the flexure preload
    assert eff.k_ser_N_per_m == pytest.approx(1 / (1 / nom.k_ser_N_per_m + 0.5 / nom.k_act_N_per_m))
    assert eff.A < nom.A


def test_effects_compose_in_series():
    """Two base compliances in series equal one with the summed strength (compliances add)."""
    a = powertrain(1, effects=(BaseCompliance(0.2), BaseCompliance(0.3)))
    b = powertrain(1, effects=(BaseCompliance(0.5),))
    assert a.k_ser_N_per_m == pytest.approx(b.k_ser_N_per_m, rel=1e-14)
    assert np.allclose(a.blocked_force_N(V, 0.0), b.blocked_force_N(V, 0.0), rtol=1e-12)


def test_field_dependent_d31_convex_and_keeps_neutral():
    p = powertrain(4, effects=(FieldDependentD31(0.5),))
    nom = powertrain(4)
    assert abs(p.foot_force_N(200.0, 100.0, 0.0)) < 1e-12
    f = p.blocked_force_N(np.array([125.0, 250.0]), 0.0)
    assert f[1] > 2.0 * f[0]                    # convex in voltage
    assert f[1] > nom.blocked_force_N(250.0, 0.0)
    r = nom.blocked_force_N(np.array([125.0, 250.0]), 0.0)
    assert r[1] == pytest.approx(2.0 * r[0])   # nominal is linear


def test_play_hysteresis_up_down_differ():
    eff = PlayHysteresis(0.2)
    t = np.linspace(0, 2, 401)
    vd = 125 + 125 * np.sin(2 * np.pi * t)
    _, out = eff.voltage_series(t, 250.0, vd)
    assert np.max(np.abs(out - vd)) <= 0.5 * 0.2 * 250.0 + 1e-12
    up = out[(t > 1) & (np.gradient(vd) > 0) & (np.abs(vd - 125) < 2)]
    down = out[(t > 1) & (np.gradient(vd) < 0) & (np.abs(vd - 125) < 2)]
    assert up.mean() < down.mean() - 10.0


def test_effect_strength_must_be_finite():
    with pytest.raises(ModelError, match="strength"):
        BaseCompliance(float("nan"))
    with pytest.raises(ModelError, match="base_compliance"):
        BaseCompliance(-0.1)
