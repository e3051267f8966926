"""The self-check's scores from hand-made trials (no simulation): what each figure counts."""

import pytest

from analysis.gap.selfcheck import Trial, score


def _trial(kind, truth, best=None, named=None, sets=None, decoys=()):
    return Trial(seed=0, kind=kind, truth=list(truth), decoys=list(decoys), truth_strength={n: None for n in truth},
                 best=best, named=dict(named or {}), ambiguous_sets=[list(s) for s in (sets or [])])


def test_a_set_member_counts_only_in_the_looser_multi_effect_figure():
    trials = [_trial("multi", ["creep", "width_loss"], best="creep", named={"creep": "attributed",
                                                                           "pzt_modulus": "ambiguous"},
                     sets=[["pzt_modulus", "width_loss"]])]
    s = score(trials)
    assert s["multi_effects_named"] == pytest.approx(0.5)
    assert s["multi_effects_named_or_in_set"] == pytest.approx(1.0)


def test_top1_needs_the_truth_attributed_first_and_nulls_count_attributions_only():
    trials = [_trial("single", ["hysteresis"], best="hysteresis", named={"hysteresis": "attributed"}),
              _trial("single", ["width_loss"], named={"pzt_modulus": "ambiguous"},
                     sets=[["pzt_modulus", "width_loss"]]),
              _trial("null", [], named={"creep": "unexplained"}),
              _trial("null", [], best="creep", named={"creep": "attributed"})]
    s = score(trials)
    assert s["top1_single"] == pytest.approx(0.5)
    assert s["truth_in_ambiguous_set_single"] == pytest.approx(0.5)
    assert s["false_attribution_rate_null"] == pytest.approx(0.5)
