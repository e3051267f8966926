"""How the gap's text output and report word a step's share of the held-out gap."""

from analysis.gap.results import closed_share_text, floor_text


def test_a_step_that_takes_the_gap_below_the_noise_floor_reads_as_all_of_it():
    # the share's denominator is the gap above the noise floor, so a step ending below the floor passes 100 %
    assert closed_share_text(1.31, " of the held-out gap") == "all of the held-out gap, to below the noise floor"
    assert closed_share_text(1.0) == "all, to below the noise floor"
    assert closed_share_text(0.524, " of the held-out gap") == "52% of the held-out gap"
    assert closed_share_text(None) == "-"


def test_a_remainder_whose_interval_reaches_the_floor_is_not_called_at_it():
    # external-lab case 4509: 4.40 x noise, interval 0.96-7.41 from few held-out conditions
    wide = {"heldout_rms": 4.40, "heldout_rms_ci95": [0.96, 7.41], "at_noise_floor": True}
    assert floor_text(wide) == " (its 95 % interval, 0.96-7.41, reaches the noise floor)"
    assert floor_text({**wide, "heldout_rms": 0.98}) == " (at the noise floor)"
    assert floor_text({**wide, "heldout_rms_ci95": [1.4, 7.41], "at_noise_floor": False}) == ""


def test_each_named_effects_notes_reach_the_terminal_text():
    from analysis.commands.gap import format_text

    effect = {"effect": "sensor_drift", "verdict": "unexplained", "strength": 0.0, "strength_ci95": [0.0, 0.0],
              "unit": "N/sqrt(s)", "closed_fraction": 0.2, "confusable_with": [],
              "notes": ["the fitted wander is no more than the baseline's noise puts there (interval 0 - 0)",
                        "the fitted force baseline moves by up to 0.2 mN within one run or shared clock"]}
    result = {"nominal_lack_of_fit": {"p_value": 1e-5, "z_rms": 1.5}, "gap_above_noise": True, "where": [],
              "waterfall": [], "named": [effect], "cannot_separate": [], "best": None,
              "unexplained": {"heldout_rms": 1.2, "at_noise_floor": False}}
    lines = format_text(result).splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().startswith("sensor_drift"))
    assert [line.strip() for line in lines[at + 1:at + 3]] == effect["notes"]


def test_a_candidate_turned_down_says_which_test_it_failed():
    from analysis.gap.results import HeldOut, StepCandidate

    fails_heldout = StepCandidate("hysteresis", 1449.0, HeldOut(3.27, (1.9, 4.4)), (-0.55, 0.37), 0.012, bar=103.0)
    fails_both = StepCandidate("creep", 50.0, HeldOut(3.0, (2.0, 4.0)), (-0.1, 0.2), 0.001, bar=103.0)
    fails_bar = StepCandidate("width_loss", 80.0, HeldOut(2.5, (2.0, 3.0)), (0.05, 0.2), 0.1, bar=103.0)
    assert "held-out reduction is not above 0 with 95 % confidence (-0.55 to 0.37" in fails_heldout.why_not()
    assert "bar" not in fails_heldout.why_not()
    assert "held-out" in fails_both.why_not() and "below the step's bar 103" in fails_both.why_not()
    assert "held-out" not in fails_bar.why_not() and "80 is below the step's bar 103" in fails_bar.why_not()


def test_the_terminal_text_lists_what_was_tried_when_nothing_passed():
    from analysis.commands.gap import format_text

    result = {"nominal_lack_of_fit": {"p_value": 1e-9, "z_rms": 4.5}, "gap_above_noise": True, "where": [],
              "waterfall": [], "named": [], "cannot_separate": [], "best": None,
              "unexplained": {"heldout_rms": 3.07, "at_noise_floor": False},
              "turned_down": [{"effect": "hysteresis", "why": "it does not lower the held-out gap"}]}
    lines = [line.strip() for line in format_text(result).splitlines()]
    at = lines.index("tried next, none passing:")
    assert lines[at + 1].split() == ["hysteresis", "it", "does", "not", "lower", "the", "held-out", "gap"]
    del result["turned_down"]    # a result from before the field existed still prints
    assert "tried next, none passing:" not in format_text(result)
