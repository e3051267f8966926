"""A force baseline's drift judged on what the held-out folds can test (analysis.gap.verdict `baseline_closure`).

Data: another lab's files (tests/analysis/lab_traces.py, no code shared with analysis/), stamped on one logger
clock, each specimen's load cell wandering as a random walk from its tare (a Brownian path added to the force
here, a form the diagnosis's spline baseline does not share). A left-out specimen's own baseline is seen by no
other specimen's rows, so the specimen folds cannot credit a drift; the condition folds predict a left-out file's
baseline from the same specimen's files either side of it in time."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.gap.diagnose import diagnose, nominal_fit
from analysis.gap.features import load_gap_data
from analysis.gap.heldout import Judge, rms
from analysis.gap.problem import Problem
from analysis.gap.verdict import baseline_closure
from tests.analysis.lab_traces import Effects, Lab, LabFile, specimen_rows
from tests.gap.test_diagnosis import SPECIMENS, import_lab_file

WANDER_N_PER_SQRT_S = 5e-6       # a load cell warming up by 0.3 mN over minutes, wandering a little about it
WARMUP_N, WARMUP_S = 3e-4, 150.0
GAP_BETWEEN_FILES_S = 20.0
FORCE_NOISE_N = 2.5e-4


def write_drifting_lab(directory, seed: int, volts=(100.0, 150.0, 200.0, 250.0)) -> list:
    """One CSV per test and voltage, the specimens one after another, every file on the logger's one clock; each
    specimen's force sensor has its own baseline from its tare at t = 0: a warm-up (tanh, a form the diagnosis's
    t / (t + tau) does not share) and a random walk."""
    rng = np.random.default_rng(seed)
    lab = Lab(force_noise_N=FORCE_NOISE_N)
    t_end = 2000.0
    grid = np.arange(0.0, t_end, 0.05)
    baselines = {}
    for sp in SPECIMENS:
        walk = np.concatenate([[0.0], np.cumsum(rng.normal(0.0, WANDER_N_PER_SQRT_S * np.sqrt(0.05), grid.size - 1))])
        level = walk + WARMUP_N * np.tanh(grid / WARMUP_S)           # warming up from the tare at t = 0
        baselines[sp.label] = lambda t, level=level: np.interp(t, grid, level)
    clock = 5.0
    out = []
    for v in volts:
        for test in ("blocked", "free"):
            f = LabFile()
            for sp in SPECIMENS:
                rows = specimen_rows(sp, 2, test, v, lab, Effects(), rng, t0=clock, baseline_N=baselines[sp.label])
                clock = float(rows[-1]["time_s"]) + GAP_BETWEEN_FILES_S
                f.rows += rows
            assert clock < t_end
            out.append(import_lab_file(f, directory / f"{test}_{int(v)}V.csv"))
    return out


@pytest.fixture(scope="module")
def drifting_lab(tmp_path_factory):
    return write_drifting_lab(tmp_path_factory.mktemp("drift"), seed=6)


def test_a_drift_is_judged_with_each_left_out_specimens_own_baseline_known(drifting_lab):
    p = Problem(load_gap_data(drifting_lab))
    assert all(len(u) > 1 for u in p.baselines)          # each specimen's files on one clock, one baseline
    nominal = nominal_fit(p)
    judge = Judge(p, reference=nominal)
    drift = p.solve(("sensor_drift",), nominal.values(), max_nfev=60)
    n = p.y.size
    force = np.concatenate([e.is_force_row for e in p.engines])
    z0, z1 = judge.z(nominal), judge.z(drift)

    # a left-out specimen's force rows: its baseline predicted at 0 by both models, no better with the drift
    assert rms(z1[n:][force]) > 0.95 * rms(z0[n:][force])
    # a left-out condition's force rows: the drift predicts them from the specimen's files either side in time
    assert rms(z1[:n][force]) < 0.5 * rms(z0[:n][force])
    # so judged as it is the drift closes under half of the gap; with each left-out specimen's own baseline
    # known to both models, over half
    whole = (rms(z0) - rms(z1)) / (rms(z0) - 1.0)
    assert whole < 0.5 < baseline_closure(p, nominal, drift, judge)


def test_a_drift_on_one_clock_is_attributed(drifting_lab):
    d = diagnose(load_gap_data(drifting_lab), jobs=1)
    named = {e.name: e for e in d.named}
    assert "sensor_drift" in named, [e.name for e in d.named]
    assert named["sensor_drift"].verdict == "attributed", named["sensor_drift"].notes
    assert d.best == "sensor_drift"
