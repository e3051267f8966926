"""The diagnosis reads the ramp rates a lab drove per cycle: an imported step can hold repetitions at both rates,
and a step-level mean ramp would be neither (it made the diagnosis call hysteresis ambiguous with a timing lag on
data that had two rates)."""

from types import SimpleNamespace

import pytest

from analysis.gap.problem import Problem


def _engine(*steps):
    timing = {k: SimpleNamespace(ramp_up_s=sum(r) / len(r), cycles=[SimpleNamespace(ramp_up_s=x) for x in r])
              for k, r in enumerate(steps)}
    return SimpleNamespace(run=SimpleNamespace(step_timing=timing))


def test_two_ramp_rates_inside_one_imported_step_are_two_rates():
    fake = SimpleNamespace(engines=[_engine([0.05, 0.05, 0.15, 0.15])])
    assert Problem._ramp_rates(fake) == pytest.approx([0.05, 0.15])


def test_one_ramp_rate_with_timing_jitter_is_one_rate():
    fake = SimpleNamespace(engines=[_engine([0.100, 0.102, 0.099]), _engine([0.101])])
    assert len(Problem._ramp_rates(fake)) == 1
