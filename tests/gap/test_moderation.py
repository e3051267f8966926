"""Pure-error moderation (analysis.gap.moderation): sample variances drawn from known chi-square laws, the
moderated ones checked against the truth that drew them (not against the module's own formulas)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from analysis.gap.features import Row, moderate_standard_errors
from analysis.gap.moderation import squeeze

DOF = 7   # a run of 8 cycles


def _draw(true_var: np.ndarray, dof: int, rng: np.random.Generator) -> np.ndarray:
    return true_var * rng.chisquare(dof, true_var.size) / dof


def test_a_common_level_pools_every_unit_toward_it() -> None:
    rng = np.random.default_rng(1)
    true = np.full(40, 2.0e-12)
    raw = _draw(true, DOF, rng)
    sq = squeeze(raw, np.full(raw.size, DOF))
    assert sq.prior_dof > 40
    # each unit's error against the truth shrinks: the raw ones scatter by sqrt(2/7) ~ 53 %
    assert np.sqrt(np.mean(np.log(sq.variance / true) ** 2)) < 0.5 * np.sqrt(np.mean(np.log(raw / true) ** 2))


def test_truly_different_units_keep_their_own() -> None:
    rng = np.random.default_rng(2)
    true = np.exp(rng.uniform(np.log(1e-13), np.log(1e-10), 40))     # a factor 1000 apart
    raw = _draw(true, DOF, rng)
    sq = squeeze(raw, np.full(raw.size, DOF))
    assert sq.prior_dof < 10
    assert np.corrcoef(np.log(sq.variance), np.log(true))[0, 1] > 0.9
    # moderated lies between the unit's own and the level: never further from the truth than both
    assert np.mean(np.abs(np.log(sq.variance / true))) <= np.mean(np.abs(np.log(raw / true))) + 0.05


def test_the_level_follows_the_voltage_where_the_scatter_does() -> None:
    rng = np.random.default_rng(3)
    volts = np.repeat([100.0, 175.0, 250.0], 24)
    true = 1e-12 * (volts / 100.0) ** 2          # a ramp window: scatter grows with the slope
    raw = _draw(true, DOF, rng)
    sq = squeeze(raw, np.full(raw.size, DOF), np.log(volts))
    assert sq.trend
    ratio = np.mean(sq.variance[volts == 250.0]) / np.mean(sq.variance[volts == 100.0])
    # each voltage's mean log variance has a sampling sd of ~0.12 here: 0.4 is over three of them
    assert abs(math.log(ratio) - math.log(6.25)) < 0.4


def test_too_few_units_or_no_dof_are_left_alone() -> None:
    raw = np.array([1.0, 4.0])
    assert np.array_equal(squeeze(raw, np.array([7, 7])).variance, raw)
    sq = squeeze(np.array([1.0, 1.2, 0.9, 5.0]), np.array([7, 7, 7, 0]))
    assert math.isfinite(sq.variance[3])          # no dof of its own: the level


def _row(phase: str, voltage_V: float, var: float, n: int = 8) -> Row:
    return Row(run=0, protocol="actuator", quantity="displacement_m", mode="free", voltage_V=voltage_V, sag_m=0.0,
               repetition=0, direction="up", step=0, phase=phase, value=0.0, n=n, eval_times_s=np.zeros(1),
               se=math.sqrt(var / n), pure_var=var, pure_dof=n - 1)


def test_rows_take_the_moderated_standard_error() -> None:
    rng = np.random.default_rng(4)
    variances = _draw(np.full(12, 1e-12), DOF, rng)
    runs = [SimpleNamespace(fixture="actuator", rows=[_row("high_late", 100.0, v)]) for v in variances]
    before = np.array([r.rows[0].se for r in runs])
    prior = moderate_standard_errors(runs)  # type: ignore[arg-type]
    after = np.array([r.rows[0].se for r in runs])
    assert prior[("actuator", "displacement_m", "high_late")] > DOF
    assert np.std(np.log(after)) < np.std(np.log(before))
    assert all(r.rows[0].pure_var == v for r, v in zip(runs, variances, strict=True))   # the raw figure kept
