"""A named effect's strength interval held wide enough for the models the data do not rule out
(analysis.gap.ranking `within_unruled_models`): the final model with one more candidate that passed the in-sample
test and failed the held-out one. Stand-in fits carry only the strengths the rule reads."""

from __future__ import annotations

from types import SimpleNamespace

from analysis.gap.ranking import within_unruled_models


def _fit(**strengths: float) -> SimpleNamespace:
    return SimpleNamespace(effects={n: SimpleNamespace(strength=s) for n, s in strengths.items()})


def test_the_interval_reaches_the_strength_an_unruled_model_gives_and_keeps_its_point():
    unruled = [_fit(hysteresis=0.110, sensor_compliance=1e-4), _fit(hysteresis=0.121, creep=0.01)]
    assert within_unruled_models("hysteresis", (0.123, (0.120, 0.126)), unruled) == (0.123, (0.110, 0.126))


def test_an_unruled_model_inside_the_interval_or_without_the_effect_leaves_it_as_it_was():
    unruled = [_fit(hysteresis=0.122), _fit(creep=0.02)]
    assert within_unruled_models("hysteresis", (0.123, (0.120, 0.126)), unruled) == (0.123, (0.120, 0.126))
    assert within_unruled_models("hysteresis", (0.123, (0.120, 0.126)), []) == (0.123, (0.120, 0.126))


def test_the_drift_wander_derived_from_its_coefficients_is_not_widened_by_a_strength_parameter():
    unruled = [_fit(sensor_drift=9.0)]
    assert within_unruled_models("sensor_drift", (2e-5, (1e-5, 3e-5)), unruled) == (2e-5, (1e-5, 3e-5))
