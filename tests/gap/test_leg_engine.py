"""A leg run's predictions do not depend on what the engine evaluated before: the linkage held at a run's sensor
heights is reused across evaluations that leave those heights alone (`RunEngine._leg_values`), so a stale reuse
would show as a prediction that differs from a fresh engine's."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from analysis.gap.engine import EffectValue, RunEngine, RunNuisance
from analysis.gap.features import load_gap_data
from tests.replay.conftest import record

SHORT_LEG = ["repetitions=1", "voltages_V=150,250", "drive.cycles=1", "drive.dwell_high_s=0.2",
             "drive.dwell_low_s=0.2"]


@pytest.fixture(scope="module")
def leg_run(tmp_path_factory):
    path = record(tmp_path_factory.mktemp("leg") / "blocked.mcap", "blocked-force", SHORT_LEG, effects={})
    (run,) = [r for r in load_gap_data([path]).runs if r.fixture == "leg"]
    return run


def test_a_leg_runs_prediction_is_the_same_whatever_was_evaluated_before(leg_run):
    sensor = {"sensor_compliance": EffectValue(1e-3)}
    bias = {"bias_error": EffectValue(20e-6)}
    cases = [({}, RunNuisance()), ({}, RunNuisance(shift_m=5e-6)), (sensor, RunNuisance(shift_m=5e-6)),
             ({}, RunNuisance(gains=(0.03, -0.02), shift_m=5e-6)), (bias, RunNuisance()),
             ({}, RunNuisance(lag_s={"force_N": 2e-3})), ({}, RunNuisance())]
    warm = RunEngine(leg_run)
    seen = [warm.predict(effects, nuis) for effects, nuis in cases]
    for (effects, nuis), got in zip(cases, seen, strict=True):
        fresh = RunEngine(leg_run).predict(effects, nuis)
        assert np.array_equal(got, fresh, equal_nan=True)
    # and the cases differ from each other: each one moves the prediction
    for a, b in zip(seen[:-2], seen[1:-1], strict=True):
        assert not np.allclose(a, b, equal_nan=True)
    assert np.array_equal(seen[0], seen[-1], equal_nan=True)
    # the compliant sensor reads lower (the foot sits lower by the sensor's give), by a little on a soft leg
    pressed = seen[1] > 1e-4
    assert np.all(seen[2][pressed] < seen[1][pressed])
    assert np.all(seen[2][pressed] > 0.99 * seen[1][pressed])


def test_a_stage_level_the_foot_never_meets_changes_nothing(leg_run):
    """The linkage is solved at the carriage levels the force samples see, not at every level the stage took: a
    move far out of the leg's reach (as a contact search starts) before any sample leaves the prediction alone."""
    ts, xs = leg_run.stage_cmd
    first = min(float(r.eval_times_s.min()) for r in leg_run.rows)
    far = copy.copy(leg_run)
    far.stage_cmd = (np.r_[first - 5.0, ts], np.r_[xs[0] + 0.05, xs]) if ts.size else (np.array([first - 5.0]),
                                                                                      np.array([0.05]))
    if far.t_contact_s is None:
        far.t_contact_s = first - 4.0
    for effects, nuis in (({}, RunNuisance()), ({}, RunNuisance(shift_m=5e-6, lag_s={"force_N": 2e-3}))):
        assert np.array_equal(RunEngine(far).predict(effects, nuis), RunEngine(leg_run).predict(effects, nuis),
                              equal_nan=True)


def test_a_compliant_force_sensor_lowers_a_legs_reading_by_its_give():
    """The sensor gives way by C F, so the foot sits lower than the stage says: F = F(h) / (1 + C dF/dh), with
    dF/dh > 0 (pushing the foot up raises the force)."""
    from hamr_bench.model.powertrain import powertrain

    p = powertrain(1)
    h, dh, c = np.array([0.0, 30e-6]), 1e-6, 1e-3
    k = (p.foot_force_N(0.0, 150.0, h + dh) - p.foot_force_N(0.0, 150.0, h - dh)) / (2 * dh)
    assert np.all(k > 0)
    # the leg's own reading with the sensor's give taken out, solved by fixed point
    f = p.foot_force_N(0.0, 150.0, h)
    for _ in range(50):
        f = p.foot_force_N(0.0, 150.0, h - c * f)
    # the engine's first-order form against it (the leg run's predictions use that form)
    assert p.foot_force_N(0.0, 150.0, h) / (1.0 + c * k) == pytest.approx(f, rel=1e-5)
