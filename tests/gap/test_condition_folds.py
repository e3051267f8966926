"""The condition folds (analysis.gap.heldout `folds`): whole conditions held out, each condition's undriven dwell
in another fold from its driven rows, so a file's force baseline, read at its undriven dwell, is seen by the
training rows when its driven rows are predicted."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from analysis.gap.features import PHASES
from analysis.gap.heldout import UNDRIVEN_PHASE, condition_ids, folds


def _problem(voltages=(100.0, 150.0, 200.0, 250.0, 300.0, 350.0), specimens=3):
    runs, rows = [], []
    for v in voltages:
        for _ in range(specimens):      # one file per voltage, its specimens' runs
            k = len(runs)
            runs.append(SimpleNamespace(fixture="actuator", layers=2, design=None))
            rows += [SimpleNamespace(run=k, protocol="actuator", mode="blocked", voltage_V=v, sag_m=0.0,
                                     quantity="force_N", phase=ph) for ph in PHASES]
    return SimpleNamespace(rows=rows, data=SimpleNamespace(runs=runs))


def test_every_row_is_held_out_once_and_a_conditions_undriven_dwell_apart_from_the_rest():
    p = _problem()
    masks = folds(p)
    assert len(masks) == 5
    np.testing.assert_array_equal(np.sum(masks, axis=0), np.ones(len(p.rows), int))
    fold_of = np.argmax(np.array(masks), axis=0)
    cid = condition_ids(p)
    undriven = np.array([r.phase == UNDRIVEN_PHASE for r in p.rows])
    for c in np.unique(cid):
        driven, dwell = set(fold_of[(cid == c) & ~undriven]), set(fold_of[(cid == c) & undriven])
        assert len(driven) == 1 and len(dwell) == 1       # a condition's rows of each kind stay together
        assert driven != dwell                            # its baseline is seen while the rest is predicted


def test_one_condition_gives_no_fold():
    # nothing left to predict it from: one condition's driven rows and dwell fall in one fold, which is all rows
    assert folds(_problem(voltages=(200.0,))) == []
