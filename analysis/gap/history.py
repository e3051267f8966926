"""One drive history per specimen across the files of an import.

A lab hands over one file per test and voltage, each holding a specimen's windows of that test. The actuator's
memory (creep, hysteresis) does not stop at a file's edge: the cycles of the test run just before, and the bias
steps between tests, still act on the next one. Evaluated on its own file alone, a run sees its bias step from 0
at its first sample and nothing driven between its repetitions, and a creep fitted there absorbs the difference
(docs/gap.md, "Creep coverage").

When the imported runs of one labelled specimen share a clock (their recorded segments, each file's import shift
undone, never overlap), each such run is evaluated on the specimen's recorded drive: the bias and drive timelines
of all its runs merged in time order, from HISTORY_S before the run's own first sample. Between the recorded
segments a level holds, as a staircase does; what the lab did there unrecorded (a bias set to 0 while the stage
moved) is not known. Runs whose segments overlap (each file's clock restarting) keep their own timelines."""

from __future__ import annotations

from typing import Any

import numpy as np

SEGMENT_GAP_S = 0.5     # a pause longer than this between samples ends a recorded segment
# How far back a run's shared history reaches before its own first segment: the cycles of the test just before
# (a few seconds) are what still moves it; older ones cancel in pairs and only lengthen every evaluation
HISTORY_S = 10.0


def segments_of(times: np.ndarray) -> list[tuple[float, float]]:
    """Sample times as recorded stretches: split where nothing was recorded for SEGMENT_GAP_S."""
    t = np.unique(np.asarray(times, float))
    if t.size == 0:
        return []
    cut = np.flatnonzero(np.diff(t) > SEGMENT_GAP_S)
    starts = np.r_[0, cut + 1]
    ends = np.r_[cut, t.size - 1]
    return [(float(t[a]), float(t[b])) for a, b in zip(starts, ends, strict=True)]


def segments(run: Any) -> list[tuple[float, float]]:
    """The run's recorded stretches in its own clock: its sensors' (`run.recorded_s`, where the loader gave them),
    its drive timeline's and its rows' sample times (reference samples included). A stretch starts at its first
    sample, not at its first cycle: a lab's file holds the low dwell before the first ramp, and a later file's
    level would otherwise hold over it."""
    parts = [run.drive_cmd[0]] + [r.eval_times_s for r in run.rows] \
        + [r.ref_times_s for r in run.rows if r.ref_times_s is not None]
    recorded = [np.asarray(p, float) for p in parts if len(p)]
    own = segments_of(np.concatenate(recorded)) if recorded else []
    spans = sorted(own + [tuple(map(float, s)) for s in getattr(run, "recorded_s", ())])
    out: list[tuple[float, float]] = []
    for a, b in spans:
        if out and a - out[-1][1] <= SEGMENT_GAP_S:
            out[-1] = (out[-1][0], max(out[-1][1], b))
        else:
            out.append((a, b))
    return out


def _specimen_key(run: Any) -> tuple | None:
    """The specimen an imported, labelled run belongs to (None for a native or unlabelled one: its own history)."""
    if run.source.startswith("import") and run.specimen:
        return (run.specimen, run.fixture, run.layers, run.design)
    return None


def _shares_a_clock(runs: list[Any], segs: list[list[tuple[float, float]]]) -> bool:
    """True when no two runs' recorded segments (`segs`, per run) overlap once each run's import shift is undone."""
    spans = sorted((a - r.clock_offset_s, b - r.clock_offset_s, k)
                   for k, (r, rs) in enumerate(zip(runs, segs, strict=True)) for a, b in rs)
    return all(nxt[0] > cur[1] or nxt[2] == cur[2] for cur, nxt in zip(spans, spans[1:], strict=False))


def _merged(runs: list[Any], segs: list[list[tuple[float, float]]], which: str) -> tuple[np.ndarray, np.ndarray]:
    """The runs' timelines `which` in one staircase (undone shifts). Each run also restates its own level at the
    start of each of its segments: a level it held unchanged across a pause (one bias for both repetitions) is
    otherwise overwritten by the other runs recorded in that pause."""
    ts, vs = [], []
    for r, rs in zip(runs, segs, strict=True):
        t, v = (np.asarray(a, float) for a in getattr(r, which))
        if t.size == 0:
            continue
        starts = np.array([a for a, _ in rs])
        at = np.clip(np.searchsorted(t, starts, "right") - 1, 0, None)
        # a point outside every segment (a block's closing point) would hold into another run's segment
        inside = np.zeros(t.size, bool)
        for a, b in rs:
            inside |= (t >= a) & (t <= b)
        ts += [t[inside] - r.clock_offset_s, starts - r.clock_offset_s]
        vs += [v[inside], v[at]]
    t, v = np.concatenate(ts), np.concatenate(vs)
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def _from(timeline: tuple[np.ndarray, np.ndarray], start: float, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The staircase from `start` on (its level there restated at `start`), shifted into a run's clock."""
    t, v = timeline
    i = int(np.searchsorted(t, start, "right"))
    if i == 0:
        return t + offset, v
    return np.r_[start, t[i:]] + offset, np.r_[v[i - 1], v[i:]]


def share_specimen_history(runs: list[Any]) -> None:
    """Give every imported run of a labelled specimen, where that specimen's runs share a clock, the specimen's
    merged bias and drive timelines (in the run's own clock); `drive_history` says which runs it came from."""
    groups: dict[tuple, list[Any]] = {}
    for run in runs:
        key = _specimen_key(run)
        if key is not None:
            groups.setdefault(key, []).append(run)
    for members in groups.values():
        segs = [segments(r) for r in members]
        if len(members) < 2 or not all(segs) or not _shares_a_clock(members, segs):
            continue
        bias, drive = _merged(members, segs, "bias_cmd"), _merged(members, segs, "drive_cmd")
        label = f"specimen {members[0].specimen}: runs {', '.join(str(r.index) for r in members)}"
        for run, rs in zip(members, segs, strict=True):
            first = rs[0][0] - run.clock_offset_s - HISTORY_S
            run.bias_cmd = _from(bias, first, run.clock_offset_s)
            run.drive_cmd = _from(drive, first, run.clock_offset_s)
            run.drive_history = label


def history_notes(runs: list[Any]) -> list[str]:
    """One line on the imported, labelled specimens recorded in more than one file: how many were evaluated on a
    shared drive history, and how many could not be (their files' clocks overlap)."""
    counts: dict[tuple, int] = {}
    shared: set[tuple] = set()
    for run in runs:
        key = _specimen_key(run)
        if key is not None:
            counts[key] = counts.get(key, 0) + 1
            if run.drive_history != "own":
                shared.add(key)
    several = [k for k, n in counts.items() if n > 1]
    if not several:
        return []
    apart = len(several) - len(shared)
    line = f"{len(shared)} of {len(several)} imported specimens recorded in several files share one drive history"
    if apart:
        line += (f"; {apart} do not (their files' times overlap, as when each file's clock restarts): each of their "
                 f"files is evaluated as if nothing was driven before it")
    return [line]
