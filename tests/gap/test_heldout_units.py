"""Held-out z in one set of units (analysis.gap.heldout `Judge(reference=...)`): every model on a problem is
judged in the nominal fit's predictive spreads, so a model cannot look better held out by being vaguer. Data:
another lab's CSVs with no effect in them (tests/analysis/lab_traces.py), every file on its own clock, imported
as a user would."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from analysis.gap.diagnose import nominal_fit
from analysis.gap.features import load_gap_data
from analysis.gap.heldout import Judge
from analysis.gap.problem import Problem
from analysis.gap.screening import grid_start
from tests.analysis.lab_traces import Effects
from tests.gap.test_diagnosis import write_lab


def fresh(fit):
    """The fit without its cached held-out z (a judge keeps them on the fit)."""
    return dataclasses.replace(fit, extra={})


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    files = write_lab(tmp_path_factory.mktemp("units"), Effects(), seed=5, volts=(120.0, 185.0, 250.0))
    p = Problem(load_gap_data(files))
    nominal = nominal_fit(p)
    drift = p.solve(("sensor_drift",), grid_start(p, nominal, "sensor_drift"))
    return p, nominal, drift


def test_the_reference_fit_is_judged_in_its_own_spreads(fits):
    p, nominal, _ = fits
    own, ref = Judge(p), Judge(p, reference=nominal)
    np.testing.assert_allclose(ref.z(fresh(nominal)), own.z(fresh(nominal)), rtol=1e-12)


def test_a_baseline_no_training_row_sees_buys_no_held_out_gain(fits):
    """Each file is one condition and one run on its own clock: a condition fold leaves that run's baseline with
    nothing but its prior (2 mN, against a force noise of a few tenths of a mN). In its own spreads the drift
    model divides the left-out runs' force errors by that width and looks far better than the nominal; in the
    nominal's it predicts those runs no better, and no reduction of the held-out gap can be shown."""
    p, nominal, drift = fits
    force = np.array([r.quantity == "force_N" for r in p.rows])
    n = p.y.size
    own = Judge(p)
    z_own_nominal, z_own_drift = own.z(fresh(nominal))[:n], own.z(fresh(drift))[:n]
    # the vagueness the reference removes: in their own spreads the drift's force rows shrink well below the nominal's
    assert np.sqrt(np.mean(z_own_drift[force] ** 2)) < 0.5 * np.sqrt(np.mean(z_own_nominal[force] ** 2))
    ref = Judge(p, reference=nominal)
    lo, _hi = ref.reduction_ci(fresh(nominal), fresh(drift))
    assert lo <= 0.0
