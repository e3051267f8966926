"""A fit's start a hair off zero (analysis.gap.problem `Problem.solve`): a grid's midpoint comes out at ~1e-21,
and the solver's finite-difference step, relative to the value, would vanish with it and freeze the parameter.
Data: another lab's CSVs (tests/analysis/lab_traces.py) imported as a user would."""

from __future__ import annotations

import numpy as np

from analysis.gap.features import load_gap_data
from analysis.gap.problem import Problem
from tests.analysis.lab_traces import Effects
from tests.gap.test_diagnosis import write_lab


def test_a_contact_shift_started_a_hair_off_zero_still_moves(tmp_path):
    p = Problem(load_gap_data(write_lab(tmp_path, Effects(), seed=3)))
    start = p.initial_nuisances()
    key = next(k for k in start if k[0] == "shift")
    at_zero = p.solve((), {**start, key: 0.0})
    lay = at_zero.layout
    i = lay.index[key]
    assert abs(at_zero.x[i]) > 1e-11         # the data want the shift somewhere (~0.5 nm): it moved from exactly 0
    off = p.solve((), {**start, key: 6.8e-21})
    assert np.linalg.norm(off.jac[:, i]) > 0.0
    np.testing.assert_allclose(off.x[i], at_zero.x[i], rtol=1e-6)
