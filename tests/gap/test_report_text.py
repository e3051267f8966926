"""How the gap's text output and report word a step's share of the held-out gap."""

from analysis.gap.results import closed_share_text


def test_a_step_that_takes_the_gap_below_the_noise_floor_reads_as_all_of_it():
    # the share's denominator is the gap above the noise floor, so a step ending below the floor passes 100 %
    assert closed_share_text(1.31, " of the held-out gap") == "all of the held-out gap, to below the noise floor"
    assert closed_share_text(1.0) == "all, to below the noise floor"
    assert closed_share_text(0.524, " of the held-out gap") == "52% of the held-out gap"
    assert closed_share_text(None) == "-"
