"""Actuator: closed form vs independent integration, the bias-drive-ground law, presets and bad input."""

import numpy as np
import pytest
from scipy.integrate import quad

from hamr_bench.errors import ModelError
from hamr_bench.model import actuator as act
from hamr_bench.model import actuator_preset


def _gf_by_integration(wr: float, lr: float) -> float:
    """Blocked force of a linearly tapered cantilever with a rigid extension, over the untapered one (F0 = 3 m w / 2 l).

    Curvature = (m w(x) - F (L' - x)) / (D w(x)); the blocked tip has zero deflection:
    F = m int_0^l (L' - x) dx / int_0^l (L' - x)^2 / w(x) dx   (l = 1, w_nom = 1, L' = 1 + lr).
    """
    Lp = 1.0 + lr
    def w(x):
        return wr + (2.0 - 2.0 * wr) * x  # base wr, tip 2 - wr, mean 1
    num = quad(lambda x: Lp - x, 0, 1)[0]
    den = quad(lambda x: (Lp - x) ** 2 / w(x), 0, 1)[0]
    return (num / den) / 1.5


@pytest.mark.parametrize("wr,lr", [(1.5, 0.0), (1.5, 0.0063), (1.2, 0.1), (0.8, 0.05), (1.0, 0.0), (1.0, 0.2),
                                   (1.0005, 0.1)])
def test_force_geometric_factor_matches_integration(wr, lr):
    assert act.geometric_factor_force(wr, lr) == pytest.approx(_gf_by_integration(wr, lr), rel=1e-6)


def test_untapered_limit_is_unity():
    assert act.geometric_factor_force(1.0, 0.0) == pytest.approx(1.0, rel=1e-4)


# physics.md sanity table (Table I effective, 250 V, one-sided), computed independently of this code.
@pytest.mark.parametrize("layers,F_mN,d_um,k", [(1, 181, 118, 1540), (2, 210, 103, 2040), (3, 240, 88, 2740)])
def test_sanity_table(layers, F_mN, d_um, k):
    a = actuator_preset(layers, "effective")
    assert a.blocked_force_N(250.0) * 1e3 == pytest.approx(F_mN, rel=0.01)
    assert a.free_displacement_m(250.0) * 1e6 == pytest.approx(d_um, rel=0.01)
    assert a.stiffness_N_per_m == pytest.approx(k, rel=0.01)


def test_mass_is_dominated_by_pzt_and_about_80_mg():
    a = actuator_preset(2)
    pzt = 2 * a.pzt_thickness_m * a.length_m * a.width_nom_m * act.RHO_PZT_KG_PER_M3
    assert pzt < a.mass_kg < 1.1 * pzt


def test_vectorised_and_linear_in_voltage():
    a = actuator_preset(2)
    v = np.array([[0.0, 100.0], [200.0, 250.0]])
    f = a.blocked_force_N(v)
    assert f.shape == v.shape
    assert f[1, 0] == pytest.approx(2 * f[0, 1])
    assert np.allclose(a.energy_J(v), a.blocked_force_N(v) * a.free_displacement_m(v))


def test_bias_drive_ground_law():
    a = actuator_preset(2)
    Vb = 200.0
    Fb = a.blocked_force_N(Vb)
    assert a.tip_force_N(Vb, Vb / 2, 0.0) == pytest.approx(0.0, abs=1e-15)
    assert a.tip_force_N(0.0, 0.0, 0.0) == 0.0
    assert a.tip_force_N(Vb, Vb, 0.0) == pytest.approx(Fb)
    assert a.tip_force_N(Vb, 0.0, 0.0) == pytest.approx(-Fb)
    # proportional to 2 V_drive - V_bias
    assert a.tip_force_N(Vb, 0.75 * Vb, 0.0) == pytest.approx(0.5 * Fb)
    # free deflection: the tip force vanishes there, and equals the one-sided free displacement at V_d = V_b
    x = a.free_tip_deflection_m(Vb, 0.8 * Vb)
    assert a.tip_force_N(Vb, 0.8 * Vb, x) == pytest.approx(0.0, abs=1e-12)
    assert a.free_tip_deflection_m(Vb, Vb) == pytest.approx(a.free_displacement_m(Vb))


def test_thicker_core_trades_displacement_for_force():
    a1, a3 = actuator_preset(1), actuator_preset(3)
    assert a3.blocked_force_N(250) > a1.blocked_force_N(250)
    assert a3.free_displacement_m(250) < a1.free_displacement_m(250)


def test_negative_thickness_names_the_field():
    a = actuator_preset(2)
    with pytest.raises(ModelError, match="pzt_thickness_m"):
        act.with_changes(a, pzt_thickness_m=-1e-6)
    with pytest.raises(ModelError, match="width_ratio"):
        act.with_changes(a, width_ratio=2.5)


def test_bad_presets():
    with pytest.raises(ModelError, match="layers"):
        actuator_preset(4)
    with pytest.raises(ModelError, match="params"):
        actuator_preset(2, "guessed")
