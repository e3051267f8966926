"""One force baseline per shared clock (analysis.gap.problem `baselines`): the runs of a specimen evaluated on one
drive history share one drift curve, seen as one level per step; runs on their own clocks keep their own spline,
free within the run. Data: another lab's CSVs (tests/analysis/lab_traces.py) imported as a user would."""

from __future__ import annotations

import numpy as np
import pytest

from analysis.gap.features import load_gap_data
from analysis.gap.problem import Problem
from tests.analysis.lab_traces import Effects
from tests.gap.test_diagnosis import write_lab


@pytest.fixture(scope="module")
def lab_files(tmp_path_factory):
    return write_lab(tmp_path_factory.mktemp("baseline"), Effects(), seed=11)


def _force_runs_of(data, specimen):
    return [r for r in data.runs if r.specimen == specimen and any(row.quantity == "force_N" for row in r.rows)]


def _step_keys(run):
    return [(r.step, r.repetition, r.direction, r.mode) for r in run.rows]


def test_runs_on_their_own_clocks_keep_their_own_free_baseline(lab_files):
    p = Problem(load_gap_data(lab_files))
    force_runs = [k for k, e in enumerate(p.engines) if e.force_span_s() is not None]
    assert p.baselines == [(k,) for k in force_runs]
    k = force_runs[0]
    (_, cols), = p.drift_columns(p.baselines.index((k,)), 1.5)
    keys = _step_keys(p.engines[k].run)
    force = p.engines[k].is_force_row
    # free within the run: a step's phase windows see different values of the spline's columns
    same_step = [i for i, key in enumerate(keys) if force[i] and key == keys[int(np.flatnonzero(force)[0])]]
    assert len(same_step) > 1 and np.ptp(cols[same_step], axis=0).max() > 1e-6


def test_a_specimens_runs_on_one_clock_share_one_curve_seen_as_step_levels(lab_files):
    data = load_gap_data(lab_files)
    runs = _force_runs_of(data, data.runs[0].specimen)
    assert len(runs) >= 2
    # the specimen's files laid end to end on one clock, as a logger stamping one mounting's tests would
    start = 0.0
    for r in runs:
        first = min(float(row.eval_times_s.min()) for row in r.rows)
        last = max(float(row.eval_times_s.max()) for row in r.rows)
        r.clock_offset_s = first - start
        r.drive_history = "specimen shared"
        start += last - first + 5.0
    p = Problem(data)
    shared = tuple(sorted(r.index for r in runs))
    assert shared in p.baselines
    u = p.baselines.index(shared)
    per_run = p.drift_columns(u, 1.5)
    assert len({cols.shape[1] for _, cols in per_run}) == 1          # one set of coefficients for the curve
    lay = p.layout(("sensor_drift",))
    x = lay.vector()
    n_spline = per_run[0][1].shape[1] - 1
    for j in range(n_spline):                  # B-spline columns sum to 1: all ones is a flat baseline of 1 N
        x[lay.index[("drift", u, j)]] = 1.0
    moved = p.model(lay, x) - p.model(p.layout(()), p.layout(()).vector())
    for k, cols in per_run:
        e = p.engines[k]
        np.testing.assert_allclose(moved[p.slices[k]][e.is_force_row], 1.0, rtol=1e-9)
        np.testing.assert_array_equal(moved[p.slices[k]][~e.is_force_row], 0.0)
        keys = _step_keys(e.run)
        for i in np.flatnonzero(e.is_force_row):    # one level per step, whatever its phase windows
            same = [j for j in np.flatnonzero(e.is_force_row) if keys[j] == keys[i]]
            np.testing.assert_allclose(cols[same], np.broadcast_to(cols[i], cols[same].shape), atol=1e-12)
    # the runs of other specimens, on their own clocks, keep one baseline each
    others = [b for b in p.baselines if b != shared]
    assert others and all(len(b) == 1 for b in others)


def test_a_shared_baselines_wander_is_read_where_the_data_see_it(lab_files):
    data = load_gap_data(lab_files)
    runs = _force_runs_of(data, data.runs[0].specimen)
    start = 0.0
    for r in runs:
        first = min(float(row.eval_times_s.min()) for row in r.rows)
        last = max(float(row.eval_times_s.max()) for row in r.rows)
        r.clock_offset_s, r.drive_history = first - start, "specimen shared"
        start += last - first + 5.0
    p = Problem(data)
    u = p.baselines.index(tuple(sorted(r.index for r in runs)))
    lay = p.layout(("sensor_drift",))
    idx = [lay.index[("drift", u, j)] for j in range(p.drift_columns(u, 1.5)[0][1].shape[1])]
    x = lay.vector()
    x[idx] = np.random.default_rng(0).normal(0.0, 1e-4, len(idx))
    stacked = np.vstack([cols for _, cols in p.drift_columns(u, float(x[lay.index[("shape", "sensor_drift",
                                                                                      "warmup_log10_tau_s")]]))])
    _, sv, vt = np.linalg.svd(stacked)
    unseen = vt[int(np.sum(sv > 1e-9 * sv[0]))]        # a direction of the coefficients no row sees
    before = p.drift_strength(lay, x)
    assert before > 0
    x[idx] += 1e-3 * unseen
    assert p.drift_strength(lay, x) == pytest.approx(before, rel=1e-6)
