"""The data-design study (`analysis.gap.design_study`): how many of the self-check's hidden shifts and springs a
design of layer counts and specimens can tell from fabrication scatter."""

from __future__ import annotations

import math

import pytest

from analysis.gap.design_study import Design, spring_loss, design_shares, effect_sigmas

SEEDS = range(205600000, 205600060)


def test_on_the_drawn_design_it_is_the_common_shift_measure_of_one_layer_count():
    """The self-check's design (three specimens of the 2-layer actuator): a fabrication shift's distance is the
    tolerances' common-shift measure, a sensor spring's and a clamp's that of the blocked-force loss the draw
    records, and the level is the diagnosis's DETECTION_SIGMAS."""
    import numpy as np

    from analysis.gap import tolerances as tol
    from analysis.gap.diagnose import DETECTION_SIGMAS
    from analysis.gap.families import FABRICATION
    from analysis.gap.selfcheck import draw_trial
    from hamr_bench.model import actuator as act
    from hamr_bench.model import actuator_preset

    drawn = Design((2,), 3)
    assert drawn.threshold_sigmas == pytest.approx(DETECTION_SIGMAS, rel=1e-12)
    a = actuator_preset(2, "effective")
    w = tol.whitening(a)
    compared = 0
    for seed in SEEDS:
        for e in draw_trial(seed).effects:
            name = e.library_name
            if e.decoy or name is None or e.library_strength is None:
                continue
            if name in FABRICATION:
                expected = tol.common_shift_sigmas(a, w, 3, name, e.library_strength)
            elif name in ("sensor_compliance", "base_compliance"):
                ck = e.library_strength * act.stiffness_N_per_m(a)
                loss = ck / (1 + ck) if name == "sensor_compliance" else e.observable["blocked_force_loss_250V"]
                expected = math.sqrt(3) * float(np.linalg.norm(w @ np.array([0.0, math.log1p(-loss)])))
            else:
                assert effect_sigmas(name, 0.1, e.shape, drawn) is None
                continue
            strength = e.strength if e.name == "base_compliance" else e.library_strength
            assert effect_sigmas(name, strength, e.shape, drawn) == pytest.approx(expected, rel=1e-9), (seed, name)
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
        loss = spring_loss("base_compliance", 0.2, shape, actuator_preset(n, "effective"))
        assert loss == pytest.approx(observables("base_compliance", 0.2, shape, n)["blocked_force_loss_250V"],
                                     rel=1e-9)
    c = 5e-5
    losses = [spring_loss("sensor_compliance", c, {}, actuator_preset(n, "effective")) for n in (1, 2, 3)]
    assert losses[0] < losses[1] < losses[2]


def test_more_specimens_or_layer_counts_never_detect_fewer_effects():
    designs = [Design((2,), 3), Design((2,), 6), Design((1, 2, 3), 6)]
    shares = design_shares(SEEDS, designs)
    assert shares[0].single == shares[1].single == shares[2].single > 0
    assert shares[0].single_gain_detectable <= shares[1].single_gain_detectable <= shares[2].single_gain_detectable
    assert shares[0].multi_gain_detectable <= shares[1].multi_gain_detectable
    assert 0.0 < shares[0].single_ceiling <= shares[2].single_ceiling <= 1.0
