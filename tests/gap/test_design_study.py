"""The data-design study (`analysis.gap.design_study`): how many of the self-check's hidden shifts and springs a
design of layer counts and specimens can tell from fabrication scatter."""

from __future__ import annotations

import math

import pytest

from analysis.gap.design_study import Design, _spring_loss, design_shares, effect_sigmas

SEEDS = range(205600000, 205600060)


def test_on_the_drawn_design_it_is_the_self_checks_own_detection_measure():
    """The self-check's design (three specimens of the 2-layer actuator) gives `selfcheck.gain_sigmas` for every
    hidden shift and spring, and its level is the diagnosis's DETECTION_SIGMAS."""
    from analysis.gap.diagnose import DETECTION_SIGMAS
    from analysis.gap.selfcheck import draw_trial, gain_sigmas

    drawn = Design((2,), 3)
    assert drawn.threshold_sigmas == pytest.approx(DETECTION_SIGMAS, rel=1e-12)
    compared = 0
    for seed in SEEDS:
        expected = gain_sigmas(seed)
        for e in draw_trial(seed).effects:
            if e.library_name in expected:
                strength = e.strength if e.name == "base_compliance" else e.library_strength
                assert effect_sigmas(e.library_name, strength, e.shape, drawn) == \
                    pytest.approx(expected[e.library_name], rel=1e-9), (seed, e.name)
                compared += 1
    assert compared >= 20


def test_the_level_for_three_layer_counts_is_the_six_dof_quantile():
    # chi^2 with 6 dof at 1 - 1e-3 is 22.458 (statistical tables)
    assert Design((1, 2, 3), 3).threshold_sigmas == pytest.approx(math.sqrt(22.458), abs=2e-3)


def test_a_clamp_loses_what_the_draw_says_on_each_actuator_and_a_sensor_spring_costs_a_stiffer_one_more():
    from hamr_bench.model import actuator_preset
    from sim_devices.scenarios import observables

    shape = {"form": 0.0, "hardening": 1.0, "pull_ratio": 1.0}
    for n in (1, 2, 3):
        loss = _spring_loss("base_compliance", 0.2, shape, actuator_preset(n, "effective"))
        assert loss == pytest.approx(observables("base_compliance", 0.2, shape, n)["blocked_force_loss_250V"],
                                     rel=1e-9)
    c = 5e-5
    losses = [_spring_loss("sensor_compliance", c, {}, actuator_preset(n, "effective")) for n in (1, 2, 3)]
    assert losses[0] < losses[1] < losses[2]


def test_more_specimens_or_layer_counts_never_detect_fewer_effects():
    designs = [Design((2,), 3), Design((2,), 6), Design((1, 2, 3), 6)]
    shares = design_shares(SEEDS, designs)
    assert shares[0].single == shares[1].single == shares[2].single > 0
    assert shares[0].single_gain_detectable <= shares[1].single_gain_detectable <= shares[2].single_gain_detectable
    assert shares[0].multi_gain_detectable <= shares[1].multi_gain_detectable
    assert 0.0 < shares[0].single_ceiling <= shares[2].single_ceiling <= 1.0
