"""`gap --json`'s ranking (analysis.gap.results.Diagnosis.ranking): the others of an ambiguous set rank beside the
effect named for it, with the figures of the step that tried them, not among the candidates turned down."""

from __future__ import annotations

from analysis.gap.results import (Diagnosis, HeldOut, LackOfFit, NamedEffect, Remainder, Screened, StepCandidate,
                                   WaterfallStep)


def _row(name: str, rms: float, improvement: float, strength: float) -> StepCandidate:
    return StepCandidate(name, improvement, HeldOut(rms, (rms - 0.1, rms + 0.1)), (0.3, 0.6), strength)


def _diagnosis() -> Diagnosis:
    tried = [_row("width_loss", 1.1, 900.0, 0.2), _row("base_compliance", 1.12, 890.0, 3e-4),
             _row("hysteresis", 2.9, 40.0, 0.01)]
    waterfall = [WaterfallStep(None, (), HeldOut(3.0, (2.8, 3.2)), 0.0),
                 WaterfallStep("width_loss", ("width_loss",), HeldOut(1.1, (1.0, 1.2)), 0.95,
                               ("base_compliance",), tried)]
    named = [NamedEffect("width_loss", "ambiguous", 0.2, (0.1, 0.3), {}, 3.0, 1.1, 0.63, (0.5, 0.7), 0.95,
                         ambiguous_with=("base_compliance", "timing_lag"), separated_by=("leg protocol", ""))]
    # screened alone, the spring looked weaker than the hysteresis: tried in the lead's place it did as well
    screening = [Screened("hysteresis", 0.01, {}, 40.0, 30.0, True), Screened("base_compliance", 3e-4, {}, 20.0,
                 30.0, False), Screened("width_loss", 0.2, {}, 895.0, 30.0, True),
                 Screened("creep", 0.0, {}, 1.0, 30.0, False)]
    return Diagnosis(where=[], gap_above_noise=True, nominal_lack_of_fit=LackOfFit(0.0, 0, 0, 0, 1.0, 0.0),
                     specimens={}, screening=screening,
                     waterfall=waterfall, named=named, best=None,
                     unexplained=Remainder(HeldOut(1.0, (1.0, 1.0)), 1.0, 0.0), cannot_separate=[],
                     sensor_lag_s={}, ramp_rates_s=[], elapsed_s=0.0)


def test_a_set_member_ranks_next_to_the_effect_named_for_its_set():
    ranking = _diagnosis().ranking()
    assert [e["effect"] for e in ranking] == ["width_loss", "base_compliance", "hysteresis", "creep"]
    member = ranking[1]
    assert member["verdict"] == "ambiguous" and member["in_set_of"] == "width_loss"
    assert member["heldout_rms_after"] == 1.12 and member["strength"] == 3e-4
    assert member["confusable_with"] == ["width_loss", "timing_lag"]
    assert [e["verdict"] for e in ranking[2:]] == ["not named", "not named"]
