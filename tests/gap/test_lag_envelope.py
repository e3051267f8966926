"""A sensor chain's lag fitted without a drive effect, freed when the effect is added (analysis.gap.lag_envelope).

Data: another lab's CSVs (tests/analysis/lab_traces.py, independent of analysis/: its own two-term Prony creep)
with the drive logged as the exact command, a staircase of 2 ms steps, as the simulated bench's exported traces
and a DAQ's logged command are. On such data the rows are a staircase in the lag, and a creep fitted from the
nominal fit's lag stopped at a sixth of its size."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import csr_matrix

from analysis.gap.diagnose import nominal_fit
from analysis.gap.features import load_gap_data
from analysis.gap.lag_envelope import SecantJacobian
from analysis.gap.problem import Problem
from analysis.gap.screening import fit_added, grid_start
from tests.analysis.lab_traces import Effects, Lab
from tests.gap.test_diagnosis import write_lab

CREEP_LATE = 0.1     # the lab's creep: the share of a step that arrives late (0.08 s and 1.5 s, equal shares)


def _lab_creep_per_decade(fraction: float) -> float:
    """The lab's creep in the family's unit: growth from 50 to 400 ms after a step per decade, over the value
    at 1 s, from the lab's own step response."""
    def step(t: float) -> float:
        return 1 - fraction + 0.5 * fraction * (2 - math.exp(-t / 0.08) - math.exp(-t / 1.5))

    return (step(0.4) - step(0.05)) / step(1.0) / math.log10(0.4 / 0.05)


@pytest.fixture(scope="module")
def logged_creep(tmp_path_factory):
    lab = Lab(ramp_s=0.05, monitor_noise_V=0.0, monitor_lag_s=1e-7)   # the drive column is the command itself
    p = Problem(load_gap_data(write_lab(tmp_path_factory.mktemp("logged"), Effects(creep=CREEP_LATE), seed=11,
                                        lab=lab)))
    return p, nominal_fit(p)


def test_the_creep_added_to_a_lag_fitted_without_it_takes_its_size(logged_creep):
    p, nominal = logged_creep
    truth = _lab_creep_per_decade(CREEP_LATE)
    held = p.solve(("creep",), grid_start(p, nominal, "creep"), max_nfev=25)   # the lags left where they were
    freed = fit_added(p, nominal, "creep", None, 25)
    # the case is the one guarded against: from the nominal fit's lags the creep stops far below its size
    assert held.effects["creep"].strength < 0.5 * truth, "the lab's data no longer hold the lag in its interval"
    assert freed.effects["creep"].strength == pytest.approx(truth, rel=0.15)
    assert freed.objective < 0.1 * held.objective
    assert freed.chi2_rows < 2.0 * p.y.size


def test_the_secant_column_is_the_staircase_envelope_and_the_others_are_differences():
    width = 1e-3

    def fun(x: np.ndarray) -> np.ndarray:
        # row 0: a staircase in x[0] (steps of `width`, slope 2 on average); rows 1-2: smooth in x[1] and x[2]
        return np.array([2.0 * width * np.floor(x[0] / width), 3.0 * x[1] ** 2, np.sin(x[2])])

    pattern = csr_matrix(np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]]))
    lo, hi = np.full(3, -1.0), np.full(3, 1.0)
    jac = SecantJacobian(pattern, {0: width}, lo, hi)
    assert len(jac.groups) == 1                           # x[1] and x[2] touch no row in common: one evaluation
    for lag in (0.3e-3, 0.5e-3, 0.9e-3):                  # anywhere in the interval
        j = jac(fun, np.array([lag, 0.2, 0.4])).toarray()
        assert j[0, 0] == pytest.approx(2.0)              # a fine difference reads 0 here
        assert j[1, 1] == pytest.approx(1.2, rel=1e-3)
        assert j[2, 2] == pytest.approx(math.cos(0.4), rel=1e-3)
        assert j[0, 1] == j[1, 0] == 0.0
