"""A fabrication shift common to every specimen: the population test sees it where no single specimen is beyond
its tolerances, and a shift's (or a series spring's) fit starts where the specimens' gains hand it what they had
absorbed, so the rows are as they were and only the tolerance prior changes; and its interval keeps the variance
that only the prior pins."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from analysis.gap.diagnose import GAP_ALPHA, nominal_fit, population_test
from analysis.gap.features import load_gap_data
from analysis.gap.problem import Problem
from analysis.gap.screening import compensated, grid_best, prior_strength
from tests.gap.test_diagnosis import write_lab
from tests.analysis.lab_traces import Effects, Specimen


def _population(whitened: list[tuple[float, float]], layers: list[int]):
    """A stand-in problem and fit whose specimen groups have the given whitened gains (identity whitening)."""
    groups = [f"g{k}" for k in range(len(whitened))]
    p = SimpleNamespace(groups=groups, group_type=dict(zip(groups, layers, strict=True)),
                        gain_whitening={g: np.eye(2) for g in groups})
    values = {("gain", g, j): w[j] for g, w in zip(groups, whitened, strict=True) for j in (0, 1)}
    fit = SimpleNamespace(value=lambda kind, *key: values[(kind,) + key])
    return p, fit


def test_specimens_all_off_one_way_are_a_gap_where_none_is_alone():
    # five specimens each 2 tolerance sigmas off, all the same way: every one is ordinary (p = 0.14 alone), and
    # the sum over specimens is not beyond the gap level either; their mean is 4.5 sigmas of a mean off
    p, fit = _population([(2.0, 0.0)] * 5, [2] * 5)
    out = population_test(p, fit)
    assert stats.chi2.sf(4.0, 2) > 0.1
    assert out.p_total > GAP_ALPHA
    assert out.common_chi2 == pytest.approx(5 * 4.0)
    assert out.p_value < GAP_ALPHA


def test_specimens_scattered_every_way_are_not_a_common_shift():
    # the same distances from the centre, in opposite directions: no common shift, and no gap
    p, fit = _population([(2.0, 0.0), (-2.0, 0.0), (0.0, 2.0), (0.0, -2.0), (2.0, 0.0)], [2] * 5)
    out = population_test(p, fit)
    assert out.common_chi2 == pytest.approx(5 * 0.4 ** 2)   # 5 |mean|^2, the mean (0.4, 0)
    assert out.p_value > GAP_ALPHA


def test_each_layer_count_is_its_own_batch():
    # two layer counts off in opposite directions: each batch's mean is off, their pooled mean would not be
    p, fit = _population([(2.0, 0.0)] * 4 + [(-2.0, 0.0)] * 4, [1] * 4 + [3] * 4)
    out = population_test(p, fit)
    assert out.common_dof == 4
    assert out.common_chi2 == pytest.approx(2 * 4 * 4.0)


@pytest.fixture(scope="module")
def narrow_lab(tmp_path_factory):
    """Another lab's actuators, every one cut 20 % narrow (tests/analysis/lab_traces.py: its own laminate formulas)."""
    specimens = tuple(Specimen(label, d31, width) for label, d31, width in
                      (("A", 1.02, 0.79), ("B", 0.98, 0.81), ("C", 1.0, 0.80)))
    return write_lab(tmp_path_factory.mktemp("narrow"), Effects(), seed=7, specimens=specimens)


@pytest.mark.parametrize("name,strength", [("width_loss", 0.2), ("pzt_modulus", -0.15), ("pzt_thickness", 0.1),
                                           ("sensor_compliance", 1e-4), ("base_compliance", 0.2)])
def test_a_compensated_start_leaves_the_rows_as_they_were(narrow_lab, name, strength):
    p = Problem(load_gap_data(narrow_lab))
    nom = nominal_fit(p)
    lay = p.layout((name,))
    start = compensated(p, nom, name, strength)
    rows = p.residual(lay, lay.vector(start))[:lay.n_rows]
    moved = p.residual(lay, lay.vector({**nom.values(), ("strength", name): strength}))[:lay.n_rows]
    assert np.max(np.abs(rows - nom.residual[:lay.n_rows])) < 1e-6 * np.max(np.abs(moved - nom.residual[:lay.n_rows]))


def test_a_width_loss_is_started_at_what_the_gains_absorbed(narrow_lab):
    p = Problem(load_gap_data(narrow_lab))
    nom = nominal_fit(p)
    s = prior_strength(p, nom, "width_loss")
    objective, start = grid_best(p, nom, "width_loss")
    # the lab cut every plate ~20 % narrow (its nominal width is not the presets', so not exactly 0.2)
    assert 0.1 < s < 0.35
    assert start[("strength", "width_loss")] == pytest.approx(s)
    assert nom.objective - objective > 10.0


def test_a_direction_only_the_prior_pins_keeps_its_variance():
    # two parameters whose data columns are 1e8 and equal (they trade exactly on the rows, as a shift and the
    # gains do) and a prior row of 1 on the second: (J^T J)^-1 is [[1 + 2e-17, -1], [-1, 1]] exactly, but J^T J's
    # condition number is ~1e17 and a pseudo-inverse of it drops the weak direction (variance ~0)
    from analysis.gap.problem import Fit, Layout, Param

    rows = np.array([[1e8, 1e8], [2e8, 2e8], [0.0, 1.0]])
    layout = Layout((), [Param("gain", (str(i),), -1.0, 1.0, 1.0, 0.0) for i in range(2)], {}, 2, 1)
    fit = Fit((), layout, np.zeros(2), np.zeros(3), rows, {})
    assert np.allclose(fit.covariance(), [[1.0, -1.0], [-1.0, 1.0]], rtol=1e-6)


def test_a_shift_at_its_detection_limit_moves_the_mean_gains_to_the_population_tests_edge():
    from analysis.gap import tolerances as tol
    from analysis.gap.diagnose import DETECTION_SIGMAS, detection_limits
    from analysis.gap.families import FAMILIES
    from hamr_bench.model import actuator_preset

    a = actuator_preset(2, "effective")

    def problem(n):
        groups = [f"g{k}" for k in range(n)]
        return SimpleNamespace(groups=groups, group_type={g: 2 for g in groups},
                               group_engine={g: SimpleNamespace(actuator=a) for g in groups},
                               gain_whitening={g: tol.whitening(a) for g in groups})

    one = detection_limits(problem(1))["layers=2"]
    four = detection_limits(problem(4))["layers=2"]
    assert one.specimens == 1 and four.specimens == 4
    for name, limit in four.smallest_common_shift.items():
        # more specimens see smaller shifts (about 1 / sqrt(n): exactly so for a change linear in the shift)
        assert limit < one.smallest_common_shift[name] or one.smallest_common_shift[name] is None
        # four specimens all shifted by their limit (the sign it was found on): the common test's chi^2 is at the
        # detection level; half that shift, either way, stays below it
        def common_sigmas(s, name=name):
            g = tol.whitening(a) @ (tol.log_outputs(tol.scaled(a, name, s)) - tol.log_outputs(a))
            return float(np.sqrt(population_test(*_population([tuple(g)] * 4, [2] * 4)).common_chi2))

        lo, hi = FAMILIES[name].bounds
        signs = [x for x in (1.0, -1.0) if lo <= x * limit <= hi]
        assert max(common_sigmas(x * limit) for x in signs) == pytest.approx(DETECTION_SIGMAS, rel=1e-4), name
        assert all(common_sigmas(0.5 * x * limit) < DETECTION_SIGMAS for x in signs), name


def test_detection_limits_stay_within_what_the_actuator_can_take():
    # a plate whose tip is 1.9 x its base: a 50 % kerf loss (the family's bound) would leave the tip wider than the
    # model allows; the limit is searched within what it can take instead of stopping the diagnosis
    from analysis.gap import tolerances as tol
    from analysis.gap.diagnose import detection_limits
    from hamr_bench.model import actuator as act
    from hamr_bench.model import actuator_preset

    a = act.with_changes(actuator_preset(2, "effective"), width_ratio=1.9)
    with pytest.raises(Exception, match="width_ratio"):
        tol.scaled(a, "width_loss", 0.5)
    p = SimpleNamespace(groups=["g"], group_type={"g": 2}, group_engine={"g": SimpleNamespace(actuator=a)},
                        gain_whitening={"g": tol.whitening(a)})
    limits = detection_limits(p)["layers=2"].smallest_common_shift
    assert set(limits) >= {"width_loss", "pzt_thickness"}
