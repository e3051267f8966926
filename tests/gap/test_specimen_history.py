"""A specimen's drive history across imported files (analysis.gap.history): each run keeps its own levels where it
was recorded and sees the other files' levels in between; files whose clocks restart, native runs and unlabelled
specimens keep their own timelines."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from analysis.gap.timebase import zoh
from analysis.gap.history import HISTORY_S, history_notes, segments, share_specimen_history


def _run(index, segs, level, offset=0.0, specimen="1", source="import-trace"):
    """A run recorded in `segs` (file clock: start, end), its bias at `level` stated once at its first sample and
    once at its closing point, its drive a trapezoid-like staircase inside each segment."""
    t_rows = [np.arange(a + 0.1, b, 0.01) + offset for a, b in segs]
    rows = [SimpleNamespace(eval_times_s=t, ref_times_s=None) for t in t_rows]
    td = np.concatenate([[a + offset, a + 0.3 + offset, b - 0.3 + offset] for a, b in segs])
    vd = np.tile([0.0, level, 0.0], len(segs))
    bias = (np.array([segs[0][0], segs[-1][1] + 1.0]) + offset, np.array([level, level]))
    return SimpleNamespace(index=index, rows=rows, drive_cmd=(td, vd), bias_cmd=bias, clock_offset_s=offset,
                           specimen=specimen, source=source, fixture="actuator", layers=2, design=None,
                           drive_history="own")


def test_interleaved_files_share_one_history():
    # two files of one specimen: 100 V recorded at 0-4 s and 20-24 s, 250 V at 8-12 s and 28-32 s; the second file's
    # block was shifted by 50 s on import
    low = _run(0, [(0.0, 4.0), (20.0, 24.0)], 100.0)
    high = _run(1, [(8.0, 12.0), (28.0, 32.0)], 250.0, offset=50.0)
    own = {k: (r.bias_cmd, r.drive_cmd) for k, r in enumerate((low, high))}
    share_specimen_history([low, high])
    for k, run in enumerate((low, high)):
        assert run.drive_history == "specimen 1: runs 0, 1"
        t = np.concatenate([r.eval_times_s for r in run.rows])
        for which, j in (("bias_cmd", 0), ("drive_cmd", 1)):
            np.testing.assert_array_equal(zoh(*getattr(run, which), t), zoh(*own[k][j], t))
    # between its own repetitions the 250 V file sees the 100 V file's second repetition (its clock + 50 s)
    assert zoh(*high.bias_cmd, np.array([50.0 + 22.0]))[0] == 100.0
    assert zoh(*high.drive_cmd, np.array([50.0 + 22.0]))[0] == 100.0
    # and the 100 V file, in its pause, the 250 V file's first repetition (held at 250 V across the 250 V file's
    # own pause, where the 100 V file's first repetition ended)
    assert zoh(*low.bias_cmd, np.array([10.0]))[0] == 250.0


def test_the_history_reaches_back_history_s_with_the_level_held_then():
    early = _run(0, [(0.0, 4.0)], 100.0)
    late = _run(1, [(60.0, 64.0)], 250.0)
    share_specimen_history([early, late])
    t, v = late.bias_cmd
    assert t[0] == 60.0 - HISTORY_S and v[0] == 100.0     # the early file's level, held since its segment
    assert early.bias_cmd[0][0] == 0.0                     # nothing before the specimen's first sample


def test_restarting_clocks_native_runs_and_unlabelled_specimens_keep_their_own():
    a = _run(0, [(0.0, 4.0)], 100.0)
    b = _run(1, [(1.0, 5.0)], 250.0)              # overlaps a: the files' clocks restart
    c = _run(2, [(0.0, 4.0)], 100.0, source="recorded")
    d = _run(3, [(10.0, 14.0)], 250.0, source="recorded")
    e = _run(4, [(0.0, 4.0)], 100.0, specimen="")
    f = _run(5, [(10.0, 14.0)], 250.0, specimen="")
    before = [(r.bias_cmd, r.drive_cmd) for r in (a, b, c, d, e, f)]
    share_specimen_history([a, b, c, d, e, f])
    for r, (bias, drive) in zip((a, b, c, d, e, f), before, strict=True):
        assert r.drive_history == "own"
        assert r.bias_cmd is bias and r.drive_cmd is drive


def test_a_stretch_starts_at_the_first_sensor_sample_not_at_the_first_cycle():
    # the 100 V file's sensors (and its bias step) start 0.3 s before its first ramp, in its low dwell; the 250 V
    # file was recorded just before. A lag reads that dwell: it must hold the run's own bias, not the other file's
    high = _run(1, [(5.0, 9.6)], 250.0)
    low = _run(0, [(10.0, 14.0)], 100.0)
    low.bias_cmd = (np.array([9.7, 15.0]), np.array([100.0, 100.0]))
    low.recorded_s = ((9.7, 14.0),)
    assert segments(low) == [(9.7, 14.0)]
    share_specimen_history([low, high])
    assert zoh(*low.bias_cmd, np.array([9.72]))[0] == 100.0
    assert zoh(*low.bias_cmd, np.array([9.65]))[0] == 250.0     # before it, the 250 V file's level still holds


def test_segments_split_at_pauses():
    run = _run(0, [(0.0, 4.0), (20.0, 24.0)], 100.0)
    (a0, b0), (a1, b1) = segments(run)
    assert a0 == 0.0 and 3.9 < b0 <= 4.0 and a1 == 20.0 and 23.9 < b1 <= 24.0


def test_the_notes_say_which_specimens_share_a_history():
    shared = [_run(0, [(0.0, 4.0)], 100.0), _run(1, [(10.0, 14.0)], 250.0)]
    apart = [_run(2, [(0.0, 4.0)], 100.0, specimen="2"), _run(3, [(1.0, 5.0)], 250.0, specimen="2")]
    alone = [_run(4, [(0.0, 4.0)], 100.0, specimen="3")]
    runs = shared + apart + alone
    share_specimen_history(runs)
    (line,) = history_notes(runs)
    assert line.startswith("1 of 2 imported specimens recorded in several files share one drive history; 1 do not")
    assert history_notes(alone) == []
