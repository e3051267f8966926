"""How the gap's text output and report word a step's share of the held-out gap."""

from analysis.gap.results import closed_share_text


def test_a_step_that_takes_the_gap_below_the_noise_floor_reads_as_all_of_it():
    # the share's denominator is the gap above the noise floor, so a step ending below the floor passes 100 %
    assert closed_share_text(1.31, " of the held-out gap") == "all of the held-out gap, to below the noise floor"
    assert closed_share_text(1.0) == "all, to below the noise floor"
    assert closed_share_text(0.524, " of the held-out gap") == "52% of the held-out gap"
    assert closed_share_text(None) == "-"


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
