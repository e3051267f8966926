"""The self-check's scores from hand-made trials (no simulation): what each figure counts."""

import pytest

from analysis.gap.selfcheck import Trial, score


def _trial(kind, truth, best=None, named=None, sets=None, decoys=()):
    return Trial(seed=0, kind=kind, truth=list(truth), decoys=list(decoys), truth_strength={n: None for n in truth},
                 best=best, named=dict(named or {}), ambiguous_sets=[list(s) for s in (sets or [])])


def test_multi_effect_names_and_coverage_are_also_counted_per_effect():
    trials = [_trial("multi", ["creep", "width_loss"], best="creep", named={"creep": "attributed"}),
              _trial("multi", ["creep", "hysteresis"], best="hysteresis",
                     named={"hysteresis": "attributed", "creep": "unexplained"})]
    trials[0].truth_strength["creep"] = 0.02
    trials[0].strength_ci95["creep"] = (0.025, 0.03)        # attributed, its interval above the truth
    trials[1].truth_strength["hysteresis"] = 0.1
    trials[1].strength_ci95["hysteresis"] = (0.08, 0.12)
    trials[1].truth_strength["creep"] = 0.01
    trials[1].strength_ci95["creep"] = (0.0, 0.02)          # covers, but named `unexplained`: not counted
    s = score(trials)
    assert s["multi_effects_named_by_effect"] == {"creep": [1, 2], "width_loss": [0, 1], "hysteresis": [1, 1]}
    assert s["interval_coverage_by_effect"] == {"creep": [0, 1], "hysteresis": [1, 1]}
    assert s["interval_coverage"] == pytest.approx(0.5)


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


def test_an_effect_attributed_beside_the_hidden_ones_counts_as_an_extra_attribution():
    # a drift attributed after the hidden d31 curve (as on self-check trial 205600007), a best that leads a set
    # the truth is not in; `unexplained` and `ambiguous` names without a best are not claims, and neither is a
    # best that leads a set holding the truth
    trials = [_trial("multi", ["field_dependent_d31", "pzt_thickness"], best="field_dependent_d31",
                     named={"field_dependent_d31": "attributed", "sensor_drift": "attributed"}),
              _trial("single", ["width_loss"], best="cf_thickness", named={"cf_thickness": "ambiguous"},
                     sets=[["cf_thickness", "pzt_modulus"]]),
              _trial("single", ["creep"], best="creep", named={"creep": "attributed", "hysteresis": "unexplained",
                                                               "width_loss": "ambiguous"}),
              _trial("single", ["base_compliance"], best="width_loss", named={"width_loss": "ambiguous"},
                     sets=[["width_loss", "base_compliance"]]),
              _trial("null", [], best="creep", named={"creep": "attributed"})]
    s = score(trials)
    assert s["extra_attribution_rate_effect_trials"] == pytest.approx(2 / 4)
    assert s["extra_attributions_by_effect"] == {"sensor_drift": 1, "cf_thickness": 1}


def test_an_ambiguous_best_counts_as_an_answer_right_or_wrong():
    # `best` can be the leader of a set the data cannot split: the truth leading it is top-1, another leading it
    # leaves the truth in the set; on a null it is a false attribution however it is labelled
    trials = [_trial("single", ["width_loss"], best="width_loss", named={"width_loss": "ambiguous"},
                     sets=[["width_loss", "base_compliance"]]),
              _trial("single", ["width_loss"], best="base_compliance", named={"base_compliance": "ambiguous"},
                     sets=[["base_compliance", "width_loss"]]),
              _trial("null", [], best="base_compliance", named={"base_compliance": "ambiguous"},
                     sets=[["base_compliance", "sensor_compliance"]]),
              _trial("null", [], named={"base_compliance": "ambiguous"},
                     sets=[["base_compliance", "sensor_compliance"]])]
    s = score(trials)
    assert s["top1_single"] == pytest.approx(0.5)
    assert s["truth_in_ambiguous_set_single"] == pytest.approx(0.5)
    assert s["false_attribution_rate_null"] == pytest.approx(0.5)


def test_detectability_splits_by_how_far_a_hidden_effect_moves_the_specimens_mean_gains():
    from analysis.gap.diagnose import DETECTION_SIGMAS
    from analysis.gap.selfcheck import _draw_pool, detectability_breakdown, gain_sigmas
    from sim_devices.scenarios import draw_scenario

    # find single-effect draws of a weak sensor spring, a strong base spring and a creep (no simulation)
    picked: dict[str, int] = {}
    for seed in range(400):
        sc = draw_scenario(seed, fixtures=("actuator",), pool=_draw_pool())
        if sc.kind != "single":
            continue
        name = sc.effects[0].name
        sig = gain_sigmas(seed).get(name)
        if name == "sensor_compliance" and sig < DETECTION_SIGMAS:
            picked.setdefault("weak_spring", seed)
        if name == "base_compliance" and sig > DETECTION_SIGMAS:
            picked.setdefault("strong_spring", seed)
        if name == "creep":
            assert sig is None      # not an effect on the gains
            picked.setdefault("creep", seed)
    assert set(picked) == {"weak_spring", "strong_spring", "creep"}

    def trial(seed, truth, best=None, sets=()):
        return Trial(seed=seed, kind="single", truth=[truth], decoys=[], truth_strength={truth: None}, best=best,
                     named={}, ambiguous_sets=[list(s) for s in sets])

    trials = [trial(picked["weak_spring"], "sensor_compliance"),
              trial(picked["strong_spring"], "base_compliance", sets=[["base_compliance", "width_loss"]]),
              trial(picked["creep"], "creep", best="creep")]
    rows = detectability_breakdown(trials)["top1_single"]
    assert rows["gain_below_limit"] == {"right": 0, "in_set": 0, "of": 1}
    assert rows["gain_above_limit"] == {"right": 0, "in_set": 1, "of": 1}
    assert rows["other"] == {"right": 1, "in_set": 0, "of": 1}


def test_a_pair_entered_together_is_recorded_once_and_counted():
    from analysis.gap.results import HeldOut, WaterfallStep
    from analysis.gap.selfcheck import joint_pairs

    ho = HeldOut(1.0, (0.9, 1.1))
    waterfall = [WaterfallStep(None, (), ho, 0.0),
                 WaterfallStep("field_dependent_d31", ("field_dependent_d31",), ho, 0.1, joint_with=("bias_error",)),
                 WaterfallStep("bias_error", ("field_dependent_d31", "bias_error"), ho, 0.8,
                               joint_with=("field_dependent_d31",)),
                 WaterfallStep("hysteresis", ("field_dependent_d31", "bias_error", "hysteresis"), ho, 0.9)]
    assert joint_pairs(waterfall) == [["bias_error", "field_dependent_d31"]]
    trials = [_trial("multi", ["hysteresis"]), _trial("multi", ["creep"])]
    trials[0].joint = joint_pairs(waterfall)
    assert score(trials)["trials_with_a_joint_entry"] == 1


def test_specimens_as_built_sit_where_the_drawn_strength_says_once_their_scatter_is_taken_away():
    import dataclasses

    from analysis.gap.selfcheck import built_sigmas, draw_trial, gain_sigmas
    from hamr_bench.model import actuator_preset

    seed = next(s for s in range(400) if draw_trial(s).kind == "single"
                and draw_trial(s).effects[0].name == "pzt_thickness")
    sc = draw_trial(seed)
    preset = actuator_preset(sc.layers, sc.params_set)
    exact = tuple(dataclasses.replace(spec, actuator={k: getattr(preset, k) for k in spec.actuator})
                  for spec in sc.specimens)
    # every specimen built exactly to the presets: only the shift is left, as the drawn strength has it (the
    # bench's own form of the thicker plate against the diagnosis's `tolerances.scaled`)
    assert built_sigmas(dataclasses.replace(sc, specimens=exact)) == pytest.approx(
        gain_sigmas(seed)["pzt_thickness"], rel=1e-9)
    assert built_sigmas(dataclasses.replace(sc, specimens=exact, effects=())) == 0.0
    # with their scatter the specimens sit elsewhere: the mean of three specimens' scatter is not zero
    assert built_sigmas(sc) != pytest.approx(gain_sigmas(seed)["pzt_thickness"], rel=1e-3)


def test_the_command_builds_as_many_specimens_as_the_check_does_unless_told():
    from analysis.commands import selfcheck as command
    from analysis.gap import selfcheck

    assert command.TRIAL_SPECIMENS == selfcheck.TRIAL_SPECIMENS
