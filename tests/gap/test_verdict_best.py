"""The verdict a named effect would get could the data split its set (analysis.gap.verdict.settled_verdict), which
decides whether an ambiguous set's leader is `best`: only a set that would be attributed gives one; and the closure
that verdict reads, counted over the named effects that are real on their own (`verdict.real_closure`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from analysis.gap import tolerances as tol
from analysis.gap.families import FAMILIES
from analysis.gap.results import NamedEffect
from analysis.gap.heldout import rms
from analysis.gap.verdict import (CLOSED_MIN, KNOWN_BASELINE_GAP, WHOLE_GAP, best_of, real_closure,
                                  settled_verdict)


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


def _selection(*pairs):
    """A selection's waterfall: (added, held-out RMS after it), the nominal first; cumulative closures as
    `ranking` writes them."""
    rms0 = pairs[0][1]
    steps = [SimpleNamespace(added=a, heldout=SimpleNamespace(rms=r),
                             closed_fraction=(rms0 - r) / (rms0 - 1.0) if rms0 > 1.0 else 0.0) for a, r in pairs]
    return SimpleNamespace(steps=steps, fits=[SimpleNamespace(values=dict)])


class _Refits:
    """Stand-ins for the problem and the judge: a refit of a set of effects is judged at the held-out RMS given
    for that set."""

    def __init__(self, heldout_by_names):
        self.heldout_by_names = heldout_by_names
        self.refitted = []

    def solve(self, names, start, max_nfev):
        self.refitted.append(tuple(names))
        return SimpleNamespace(names=tuple(names))

    def heldout(self, fit):
        return SimpleNamespace(rms=self.heldout_by_names[fit.names])


def test_only_effects_real_on_their_own_count_toward_the_closure():
    # the null of self-check trial 204900029: a hysteresis closes 13 % and a d31 curve whose interval holds 0 the
    # rest; refitted alone the hysteresis leaves 1.29, and it does not explain half the gap
    sel = _selection((None, 1.334), ("hysteresis", 1.29), ("field_dependent_d31", 1.095))
    est = {"hysteresis": (0.018, (0.004, 0.032)), "field_dependent_d31": (0.006, (-0.008, 0.021))}
    refits = _Refits({("hysteresis",): 1.29})
    closed, read_on = real_closure(refits, sel, est, refits)
    assert refits.refitted == [("hysteresis",)]
    assert closed == pytest.approx((1.334 - 1.29) / 0.334) and read_on == WHOLE_GAP
    assert settled_verdict("hysteresis", est["hysteresis"][1], closed)[0] == "unexplained"
    # external-lab case 4316: the d31 curve named first ends at zero once the hysteresis is in, and the
    # hysteresis refitted alone closes the gap: its own late step's share does not decide
    sel = _selection((None, 3.0), ("field_dependent_d31", 1.6), ("hysteresis", 1.05))
    est = {"field_dependent_d31": (0.001, (-0.01, 0.012)), "hysteresis": (0.06, (0.03, 0.09))}
    closed, _ = real_closure(_Refits({("hysteresis",): 1.08}), sel, est, _Refits({("hysteresis",): 1.08}))
    assert closed == pytest.approx((3.0 - 1.08) / 2.0)
    # every named effect real: the final model's closure, no refit
    refits = _Refits({})
    est["field_dependent_d31"] = (0.3, (0.1, 0.5))
    assert real_closure(refits, sel, est, refits)[0] == pytest.approx((3.0 - 1.05) / 2.0) and not refits.refitted
    # a fabrication shift within its tolerance band is specimen scatter and does not count either
    band = tol.band("width_loss", FAMILIES["width_loss"].tolerance)
    sel = _selection((None, 3.0), ("width_loss", 1.5), ("hysteresis", 1.4))
    est = {"width_loss": (0.0, (-0.5 * band, 0.5 * band)), "hysteresis": (0.1, (0.05, 0.15))}
    refits = _Refits({("hysteresis",): 2.8})
    assert real_closure(refits, sel, est, refits)[0] == pytest.approx(0.2 / 2.0)
    # nothing real, or no gap above the floor: nothing closed
    est = {"width_loss": (0.0, (-0.5 * band, 0.5 * band)), "hysteresis": (0.0, (-0.05, 0.15))}
    assert real_closure(_Refits({}), sel, est, _Refits({}))[0] == 0.0
    assert real_closure(_Refits({}), _selection((None, 0.9), ("hysteresis", 0.8)),
                        {"hysteresis": (0.1, (0.05, 0.15))}, _Refits({}))[0] == 0.0


def test_with_a_drift_the_closure_takes_each_left_out_specimens_baseline_as_known():
    # the specimen folds' errors of both models lose the baseline the drift fitted to the left-out specimen's own
    # rows (no model can predict it); what else a left-out specimen shows still counts, as do the condition folds
    n = 4
    sel = _selection((None, 2.0), ("sensor_drift", 1.5))
    nominal, final = sel.fits[0], SimpleNamespace(values=dict, layout=None, x=None)
    sel.fits.append(final)
    z = {id(nominal): np.array([3.0, 1.0, 1.0, 1.0, 4.0, 1.0, 1.0, 1.0]),
         id(final): np.array([1.0, 1.0, 1.0, 1.0, 4.0, 1.0, 1.0, 1.0])}
    baseline = np.array([0.0, 0.0, 0.0, 0.0])
    problem = SimpleNamespace(y=np.zeros(n), sigma=np.ones(n), drift_rows=lambda lay, x: baseline)
    judge = SimpleNamespace(z=lambda fit: z[id(fit)], spread=np.ones(2 * n))
    est = {"sensor_drift": (2e-5, (0.0, 3.7e-5))}
    # no baseline fitted on the left-out specimen's rows: the drift is judged as any model is
    closed, read_on = real_closure(problem, sel, est, judge)
    assert read_on == KNOWN_BASELINE_GAP and closed == pytest.approx((rms(z[id(nominal)]) - rms(z[id(final)])) /
                                                                  (rms(z[id(nominal)]) - 1.0))
    assert closed < CLOSED_MIN
    # the left-out specimen's 4-noise-width offset is its own baseline: known, it is no longer gap for either
    baseline[0] = 3.0
    closed, _ = real_closure(problem, sel, est, judge)
    assert closed == pytest.approx(1.0)
    assert settled_verdict("sensor_drift", (0.0, 3.7e-5), closed, read_on)[0] == "attributed"
    verdict, why = settled_verdict("sensor_drift", (0.0, 3.7e-5), 0.3, read_on)
    assert verdict == "unexplained" and KNOWN_BASELINE_GAP in why[0]
