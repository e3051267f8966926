"""The actuator protocol's undriven stiffness sweep through the analysis: the dataset keeps its rows as their own
mode (never taken for free-displacement rows), the observation model predicts them (k_act x push + the run's
tip-zero offset), and the actuator fit reports the directly measured stiffness. Expectations come from the model
(hamr_bench.model.actuator) evaluated here, not from stored outputs."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.dataset import load_dataset
from analysis.fit import fit_actuator
from analysis.observations import actuator_prediction
from hamr_bench.model import actuator as act
from hamr_bench.model import actuator_preset
from hamr_bench.protocols.session import RunRequest, run_protocol


@pytest.fixture(scope="module")
def actuator_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("act") / "actuator.mcap"
    result = run_protocol(RunRequest(protocol="actuator", out=out, layers=2, seed=5, set_options=[
        "repetitions=1", "voltages_V=100,175,250", "drive.cycles=2", "drive.dwell_high_s=0.3",
        "drive.dwell_low_s=0.3"]))
    assert result.ok, result.reason
    return load_dataset([out])


def test_stiffness_rows_are_their_own_mode_with_the_hold_force(actuator_run):
    rows = actuator_run.select(mode="stiffness")
    a = actuator_preset(2, "effective")
    assert [round(o.sag_m * 1e6, 6) for o in rows] == [5, 10, 15, 20, 25, 30, 25, 20, 15, 10, 5]
    assert [o.direction for o in rows] == ["up"] * 6 + ["down"] * 5
    assert all(o.quantity == "force_N" and o.voltage_V == 0.0 for o in rows)
    # no stage play on the default bench: force = k_act x push, up to the contact search's accuracy (a fraction
    # of a um on ~2000 N/m: ~1 mN), the same offset for every row
    k = act.stiffness_N_per_m(a)
    resid = np.array([o.value - k * o.sag_m for o in rows])
    assert np.all(np.abs(resid) < 2e-3)
    assert np.ptp(resid) < 1e-3
    # the free rows are still exactly the camera strokes (3 voltages x 1 repetition)
    assert len(actuator_run.select(mode="free", quantity="displacement_m")) == 3
    assert not actuator_run.select(mode="stiffness", quantity="displacement_m")


def test_observation_model_of_each_mode():
    a = actuator_preset(3, "effective")
    mode = np.array(["blocked", "free", "stiffness", "stiffness", "mystery"])
    v = np.array([200.0, 200.0, 0.0, 0.0, 200.0])
    push = np.array([0.0, 0.0, 10e-6, -10e-6, 0.0])
    f0 = np.full(5, 1e-3)
    y = actuator_prediction(a, mode, v, f0, push)
    assert y[0] == pytest.approx(float(act.tip_force_N(a, 200.0, 200.0, 0.0)) + 1e-3)
    assert y[1] == pytest.approx(2 * float(act.free_tip_deflection_m(a, 200.0, 200.0)))
    # the undriven tip pushed 10 um: k_act x 10 um + f0 (tip_force_N at 0 V and deflection -10 um)
    assert y[2] == pytest.approx(float(act.tip_force_N(a, 0.0, 0.0, -10e-6)) + 1e-3)
    assert y[3] == 0.0            # the surface is clear of the tip: the sensor cannot pull
    assert np.isnan(y[4])         # an unknown mode is never silently a free-displacement row


def test_fit_uses_the_sweep_and_reports_the_direct_stiffness(actuator_run):
    g = fit_actuator(actuator_run, 2, "least-squares")
    k = act.stiffness_N_per_m(actuator_preset(2, "effective"))
    direct = g.derived["stiffness_direct"]
    assert direct["unit"] == "N/m" and direct["ci95"][0] <= k <= direct["ci95"][1]
    assert direct["value"] == pytest.approx(k, rel=0.03)
    # the stroke-per-volt regression still uses the free rows only (a stiffness row taken as free would put a
    # ~mN force among ~100 um strokes)
    s = g.derived["displacement_per_volt"]
    assert s["ci95"][0] <= act.displacement_per_volt(actuator_preset(2, "effective")) <= s["ci95"][1]


def test_imported_undriven_pushed_actuator_rows_are_stiffness_rows(tmp_path):
    import csv

    from analysis.importer import POINT_COLUMNS, import_points

    path = tmp_path / "points.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(POINT_COLUMNS)
        w.writerow(["actuator", "", 2, 0, 10e-6, 0, 0.0204, ""])        # undriven, pushed 10 um: stiffness
        w.writerow(["actuator", "", 2, 200, 0, 0, 0.168, 165e-6])        # driven: blocked + free
    import_points(path, tmp_path / "points.mcap")
    ds = load_dataset([tmp_path / "points.mcap"])
    modes = sorted((o.mode, o.quantity) for o in ds.observations)
    assert modes == [("blocked", "force_N"), ("free", "displacement_m"), ("stiffness", "force_N")]
    (row,) = ds.select(mode="stiffness")
    assert row.sag_m == pytest.approx(10e-6) and row.value == pytest.approx(0.0204)
