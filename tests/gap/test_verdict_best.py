"""The verdict a named effect would get could the data split its set (analysis.gap.verdict.settled_verdict), which
decides whether an ambiguous set's leader is `best`: only a set that would be attributed gives one."""

from __future__ import annotations

from analysis.gap import tolerances as tol
from analysis.gap.families import FAMILIES
from analysis.gap.results import NamedEffect
from analysis.gap.verdict import CLOSED_MIN, best_of, settled_verdict


def test_a_size_told_from_none_that_closes_enough_is_attributed():
    assert settled_verdict("hysteresis", (0.05, 0.12), CLOSED_MIN + 0.1) == ("attributed", [])


def test_an_interval_through_zero_or_too_little_closed_is_unexplained():
    verdict, why = settled_verdict("hysteresis", (-0.01, 0.12), 0.9)
    assert verdict == "unexplained" and "includes 0" in why[0]
    verdict, why = settled_verdict("hysteresis", (0.05, 0.12), CLOSED_MIN - 0.1)
    assert verdict == "unexplained" and "close" in why[0]
    # a drift's wander interval starts at 0 whenever the noise adds as much as the drift: only 0 - 0 says none
    assert settled_verdict("sensor_drift", (0.0, 2e-5), 0.9)[0] == "attributed"
    assert settled_verdict("sensor_drift", (0.0, 0.0), 0.9)[0] == "unexplained"


def test_a_shift_inside_its_tolerance_band_is_scatter():
    band = tol.band("width_loss", FAMILIES["width_loss"].tolerance)
    assert settled_verdict("width_loss", (-0.5 * band, 0.5 * band), 0.9)[0] == "within tolerance"
    assert settled_verdict("width_loss", (1.5 * band, 3 * band), 0.9)[0] == "attributed"


def _named(name: str, verdict: str, explains: bool) -> NamedEffect:
    return NamedEffect(name, verdict, 0.1, (0.05, 0.15), {}, 2.0, 1.2, 0.4, (0.2, 0.6), 0.8, explains=explains)


def test_best_is_the_first_effect_that_explains_the_gap_even_when_its_set_cannot_be_split():
    leader = _named("width_loss", "ambiguous", True)
    assert best_of([leader, _named("hysteresis", "attributed", True)]) == "width_loss"
    # an ambiguous set that would not be attributed (too small, or closing too little) gives no best
    assert best_of([_named("width_loss", "ambiguous", False), _named("hysteresis", "attributed", True)]) \
        == "hysteresis"
    assert best_of([_named("creep", "unexplained", False)]) is None
