"""Recordings -> phase-resolved observations for the gap diagnosis.

The fit's dataset (`analysis.dataset`) keeps one number per step (the high-plateau mean). The gap diagnosis needs
more: hysteresis shows as rise vs fall, creep as early vs late in a dwell, drift in the low dwell where the foot is
lifted. So each driven step is cut, per trapezoid cycle, into windows named by `hamr_bench.protocols.drive.
phase_labels`' phases:

    low_late   last half of the low dwell          rise_mid   second quarter of the up ramp
    rise       second half of the up ramp          high_early first 30 % of the high dwell
    high_late  last half of the high dwell         fall       first half of the down ramp
    fall_mid   third quarter of the down ramp

(the mid-ramp windows sample a hysteresis loop where it is widest, and a timing lag where it is uniform along
the ramp)

and an undriven step (the leg's static test, the actuator's stiffness sweep) into one `hold` window. A row is
the mean of the sensor over its window, averaged over the step's cycles of one ramp rate (`ramp_groups`: a step
driven at two rates gives a row per rate); its standard error comes from the
cycle-to-cycle scatter pooled over the run's steps of that phase (pure error), then moderated toward the other
runs' of that window kind (`moderation`). Camera rows are relative to the
same cycle's low_late window (the camera has no absolute zero).

Steps, their cycles and the timelines come from the recording contract's one step parser
(`hamr_bench.recording.steps.parse_run`, shared with `analysis.dataset`): each cycle's windows follow its own
corners, COMMANDED (the drive command stream) or INFERRED from the measured drive monitor (an imported trace), so
a lab's drive timing is used as it was, never the project's defaults.

For the model, each row carries `eval_times_s` (a few points in each of its windows; the prediction is their mean)
and the run carries the command timelines (bias, drive, stage targets), the contact and tare times, so any
candidate effect, including memory and stage effects, can be evaluated on exactly what the rig was told to do; for
an imported run these are the inferred drive and bias and the measured stage (`RunTrace.timelines` says which).

A recording with several specimens (an imported file) gives one RunTrace per specimen/session block, each with
its `specimen` label and its `session` (the nuisance group, `analysis.sessions`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Iterable

import numpy as np

from analysis.gap.history import history_notes, segments_of, share_specimen_history
from analysis.gap.moderation import squeeze
from analysis.sessions import session_key
from hamr_bench.errors import RecordingError
from hamr_bench.recording.contract import EventKind, Topic
from hamr_bench.recording.drive_timing import Cycle
from hamr_bench.recording.files import recording_files
from hamr_bench.recording.steps import (Block, DriveTiming, ParsedRun, StepRecord, Timelines, open_reader,
                                        parse_run, sorted_stream)

PHASES = ("low_late", "rise_mid", "rise", "high_early", "high_late", "fall", "fall_mid")
# Ramps within this fraction of each other are one ramp rate (the rows per rate here, the rates counted by
# `problem.Problem`): an inferred ramp's length carries the monitor's timing noise
RAMP_RATE_TOLERANCE = 0.1


@dataclass
class Row:
    run: int
    protocol: str
    quantity: str          # force_N | displacement_m
    mode: str              # blocked | free | ''
    voltage_V: float
    sag_m: float
    repetition: int
    direction: str
    step: int
    phase: str
    value: float
    n: int
    eval_times_s: np.ndarray
    eval_cycle: np.ndarray | None = None    # cycle label per eval time: the prediction is a mean of cycle means
    ref_times_s: np.ndarray | None = None   # camera rows: the same cycles' low-dwell sample times (subtracted)
    ref_cycle: np.ndarray | None = None
    se: float = math.nan
    pure_var: float = math.nan     # the run's cycle-to-cycle variance for this phase (pooled over its steps) ...
    pure_dof: int = 0              # ... on this many degrees of freedom, before moderation (`moderation`)
    # Standard error of the MODEL's value for this row that comes from an inferred drive (0 for a commanded one):
    # the step's V_bias and the ramps' timing are measured, with the monitor's noise; propagated with the data's
    # own sensitivities (value / V_bias for the level, the data's slope on a ramp for the timing). Independent of
    # `se` (the data's pure error): the row's total is sqrt(se^2 + drive_se^2).
    drive_se: float = 0.0
    # the ramp duration of this row's cycles (s; 0 for a hold): a step whose cycles were driven at two ramp rates
    # (an imported file holding both repetitions) gives one row per rate, not their mean
    ramp_s: float = 0.0

    @property
    def condition(self) -> tuple:
        """The step's condition without the repetition (replicates share it)."""
        return (self.run, self.protocol, self.mode, round(self.voltage_V, 6), round(self.sag_m, 9))


@dataclass
class RunTrace:
    index: int
    path: str
    protocol: str
    fixture: str
    design: int | None
    layers: int
    params_set: str
    model_params: dict[str, Any]
    bias_cmd: tuple[np.ndarray, np.ndarray]
    drive_cmd: tuple[np.ndarray, np.ndarray]
    stage_cmd: tuple[np.ndarray, np.ndarray]
    t_contact_s: float | None
    t_tare_s: float
    t_end_s: float
    rows: list[Row] = field(default_factory=list)
    # --- added for any lab's recordings (docs/log-format.md, Sessions; /work notes: import.md) ---
    specimen: str = ""                   # the specimen label ('' = the recording names none: one specimen)
    session: str = ""                    # nuisance group key (analysis.sessions): runs sharing it share a setup
    session_rule: str = "recording"      # recording | explicit | default: how `session` was decided
    timelines: dict[str, str] = field(default_factory=dict)   # bias/drive/stage -> commanded|inferred|measured|absent
    step_timing: dict[int, DriveTiming] = field(default_factory=dict)   # step index -> its drive timing
    source: str = "recorded"             # recorded | import-trace | import-points | ...
    contact: str = "none"                # search (contact_found event) | assumed (imported: zero sag at start) | none
    force_reads_pull: bool = False       # the force goes clearly negative: the sensor reads pull, no clip at 0
    clock_offset_s: float = 0.0          # the importer's shift of this block (its file's time = ours - offset)
    drive_history: str = "own"           # own | the runs whose timelines it shares (analysis.gap.history)
    recorded_s: tuple[tuple[float, float], ...] = ()   # the block's sensors' recorded stretches (start, end)

    def provenance(self) -> dict[str, Any]:
        """JSON-ready: where this run's data and timelines came from, and its grouping."""
        return {"run": self.index, "path": self.path, "specimen": self.specimen, "session": self.session,
                "session_rule": self.session_rule, "source": self.source, "timelines": dict(self.timelines),
                "contact": self.contact, "force_reads_pull": self.force_reads_pull,
                "drive_history": self.drive_history,
                "drive_timing": {str(k): v.summary() for k, v in sorted(self.step_timing.items())}}


@dataclass
class GapData:
    runs: list[RunTrace]
    rows: list[Row]

    def arrays(self) -> dict[str, np.ndarray]:
        keys = ("run", "protocol", "quantity", "mode", "voltage_V", "sag_m", "repetition", "direction", "phase",
                "value", "se", "n")
        return {k: np.array([getattr(r, k) for r in self.rows]) for k in keys}

    def sessions(self) -> dict[str, list[int]]:
        """Session key -> the indices of its runs (the nuisance groups)."""
        out: dict[str, list[int]] = {}
        for run in self.runs:
            out.setdefault(run.session, []).append(run.index)
        return out

    def specimens(self) -> dict[str, list[int]]:
        """Specimen label -> the indices of its runs."""
        out: dict[str, list[int]] = {}
        for run in self.runs:
            out.setdefault(run.specimen, []).append(run.index)
        return out

    def provenance(self) -> list[dict[str, Any]]:
        """Per run, `RunTrace.provenance()`: for `gap --json` and the report."""
        return [run.provenance() for run in self.runs]

    def specimen_notes(self) -> list[str]:
        """One line per fixture and protocol whose runs come from several recordings that name no specimen (they share
        one specimen's gains: right for one specimen measured again, wrong for several), and what the imported runs'
        drive history is (`history.history_notes`)."""
        unlabelled: dict[tuple[str, str], set[str]] = {}
        for run in self.runs:
            # one protocol recorded more than once: a repeat or another specimen (several protocols on one
            # fixture are the usual way to characterise one specimen, and need no note)
            if not run.specimen:
                what = f"{run.layers}-layer actuator" if run.fixture == "actuator" else f"design {run.design} leg"
                unlabelled.setdefault((what, run.protocol), set()).add(run.path)
        notes = [f"{len(paths)} {protocol} recordings of the {what} name no specimen and are treated as one "
                 f"specimen; if they hold different specimens, label them (`hamr-bench run --specimen LABEL`, or a "
                 f"`specimen` column in an imported trace)"
                 for (what, protocol), paths in sorted(unlabelled.items()) if len(paths) > 1]
        return notes + history_notes(self.runs)


def _samples_in(t: np.ndarray, a: float, b: float) -> np.ndarray:
    """The sensor's own sample times inside [a, b]: the model is evaluated exactly where the sensor was read."""
    return t[np.searchsorted(t, a, "left"):np.searchsorted(t, b, "right")]


def _mean_in(t: np.ndarray, y: np.ndarray, a: float, b: float) -> float:
    i0, i1 = np.searchsorted(t, a, "left"), np.searchsorted(t, b, "right")
    return float(np.mean(y[i0:i1])) if i1 > i0 else math.nan


def cycle_windows(c: Cycle) -> dict[str, tuple[float, float]]:
    """The phase windows of one cycle, from its own corners (absolute times)."""
    dl, dh = c.dwell_low_s, c.dwell_high_s
    return {"low_late": (c.low_start_s + 0.5 * dl, c.rise_start_s),
            "rise_mid": (c.rise_start_s + 0.25 * c.ramp_up_s, c.rise_start_s + 0.5 * c.ramp_up_s),
            "rise": (c.rise_start_s + 0.5 * c.ramp_up_s, c.high_start_s),
            "high_early": (c.high_start_s, c.high_start_s + 0.3 * dh),
            "high_late": (c.high_start_s + 0.5 * dh, c.fall_start_s),
            "fall": (c.fall_start_s, c.fall_start_s + 0.5 * c.ramp_down_s),
            "fall_mid": (c.fall_start_s + 0.5 * c.ramp_down_s, c.fall_start_s + 0.75 * c.ramp_down_s)}


def _in_block(t: np.ndarray, y: np.ndarray, block: Block) -> tuple[np.ndarray, np.ndarray]:
    i0, i1 = np.searchsorted(t, block.start_s, "left"), np.searchsorted(t, block.end_s, "left")
    return t[i0:i1], y[i0:i1]


def reads_pull(force_N: np.ndarray) -> bool:
    """True when the force goes clearly negative: a sensor that reads pull (fixed to the tip), not one that only
    reads push (0 off contact, noise around it)."""
    f = force_N[np.isfinite(force_N)]
    if f.size < 10:
        return False
    from hamr_bench.recording.drive_timing import noise_sigma

    top = float(np.percentile(f, 99))
    return float(np.percentile(f, 1)) < -max(6.0 * noise_sigma(f), 0.05 * max(top, 0.0))


def ramp_groups(cycles: tuple[Cycle, ...] | list[Cycle], tolerance: float = RAMP_RATE_TOLERANCE
                ) -> list[list[int]]:
    """The cycles' indices grouped by ramp rate: cycles whose up and down ramps are both within `tolerance` of a
    group's first are one group, in order of first appearance. A timing lag delays a ramp by the ramp's slope times
    the lag, rate-independent hysteresis by the same voltage at any rate: a mean over cycles of two rates reads one
    combination of the two, and only rows per rate tell them apart."""
    groups: list[list[int]] = []
    for i, c in enumerate(cycles):
        for g in groups:
            first = cycles[g[0]]
            if (abs(c.ramp_up_s - first.ramp_up_s) <= tolerance * first.ramp_up_s
                    and abs(c.ramp_down_s - first.ramp_down_s) <= tolerance * first.ramp_down_s):
                g.append(i)
                break
        else:
            groups.append([i])
    return groups


def _driven_rows(run: RunTrace, step: StepRecord, base: dict[str, Any], sensors: dict[str, tuple]) -> None:
    if step.drive is None or not step.drive.cycles:
        return
    quantity = "displacement_m" if step.tracked else "force_N"
    t_s, y_s = sensors[quantity]
    if t_s.size == 0:
        return
    for group in ramp_groups(step.drive.cycles):
        drive = dataclasses.replace(step.drive, cycles=tuple(step.drive.cycles[i] for i in group))
        made = _cycle_rows(run, quantity, step.tracked, group, drive, base, t_s, y_s)
        if drive.source == "inferred":
            _drive_uncertainty(made, drive)


def _cycle_rows(run: RunTrace, quantity: str, tracked: bool, labels: list[int], drive: DriveTiming,
                base: dict[str, Any], t_s: np.ndarray, y_s: np.ndarray) -> dict[str, Row]:
    """One row per phase from the given cycles of a step (`labels`: their indices in the step), appended to the
    run's rows."""
    cycles = drive.cycles
    windows = [cycle_windows(c) for c in cycles]
    refs = [_samples_in(t_s, *w["low_late"]) for w in windows] if tracked else None
    made: dict[str, Row] = {}
    for p in PHASES:
        if tracked and p == "low_late":
            continue
        vals, pts = [], []
        for w in windows:
            ref = _mean_in(t_s, y_s, *w["low_late"]) if tracked else 0.0
            vals.append(_mean_in(t_s, y_s, *w[p]) - ref)
            pts.append(_samples_in(t_s, *w[p]))
        v = np.asarray(vals)
        v = v[np.isfinite(v)]
        if v.size == 0:
            continue
        keep = [c for c in range(len(cycles)) if pts[c].size and (refs is None or refs[c].size)]
        if not keep:
            continue
        row = Row(quantity=quantity, phase=p, value=float(v.mean()), n=int(v.size),
                  eval_times_s=np.concatenate([pts[c] for c in keep]),
                  eval_cycle=np.concatenate([np.full(pts[c].size, labels[c]) for c in keep]),
                  ref_times_s=None if refs is None else np.concatenate([refs[c] for c in keep]),
                  ref_cycle=None if refs is None else np.concatenate([np.full(refs[c].size, labels[c])
                                                                      for c in keep]),
                  ramp_s=drive.ramp_up_s, **base)
        row._cycle_values = v  # type: ignore[attr-defined]
        run.rows.append(row)
        made[p] = row
    return made


def _drive_uncertainty(rows: dict[str, Row], drive: DriveTiming) -> None:
    """`Row.drive_se` of one inferred step's rows: the level's error (shared by the step's cycles) scales every
    row's value; a ramp's timing error (independent per cycle) moves a ramp row by the data's slope there."""
    low = rows["low_late"].value if "low_late" in rows else 0.0
    high = rows["high_early"].value if "high_early" in rows else math.nan
    n = len(drive.cycles)
    ramps = {"rise": (drive.ramp_up_s, [c.rise_se_s for c in drive.cycles]),
             "fall": (drive.ramp_down_s, [c.fall_se_s for c in drive.cycles])}
    for phase, row in rows.items():
        level = abs(row.value) * drive.bias_se_V / drive.bias_V if drive.bias_V > 0 else 0.0
        timing = 0.0
        if phase in ramps and math.isfinite(high):
            ramp_s, ses = ramps[phase]
            slope = abs(high - low) / ramp_s if ramp_s > 0 else 0.0
            timing = slope * math.sqrt(float(np.mean(np.square(ses)))) / math.sqrt(n) if ses else 0.0
        row.drive_se = math.hypot(level, timing) if math.isfinite(level) and math.isfinite(timing) else 0.0


def _hold_row(run: RunTrace, step: StepRecord, base: dict[str, Any], tf: np.ndarray, force: np.ndarray) -> None:
    if step.hold_window_s is None or tf.size == 0:
        return
    a, b = step.hold_window_s
    i0, i1 = np.searchsorted(tf, a, "left"), np.searchsorted(tf, b, "right")
    if i1 - i0 < 2:
        return
    seg = force[i0:i1]
    row = Row(quantity="force_N", phase="hold", value=float(seg.mean()), n=int(seg.size),
              eval_times_s=tf[i0:i1], eval_cycle=np.zeros(i1 - i0, int), **base)
    # white-noise standard error of the hold mean; pooled below like the cycles
    row._cycle_values = seg  # type: ignore[attr-defined]
    run.rows.append(row)


def _stage_as_sag(parsed: ParsedRun, timelines: Timelines, t_contact_s: float) -> tuple[np.ndarray, np.ndarray]:
    """An imported run's measured stage set-points as sag (the importer's zero and sign), with a zero-sag sample
    at the assumed contact time, so RunEngine's 'position relative to the contact' is the sag."""
    t, x = timelines.stage
    if t.size == 0:
        return t, x
    extra = parsed.meta.run_extra
    try:
        zero = float(extra.get("zero_sag_m", "nan"))
        sign = float(extra.get("toward_leg_sign", "1") or 1.0)
    except ValueError:
        zero, sign = math.nan, 1.0
    if not math.isfinite(zero):
        zero = float(x[0])
    return np.r_[t_contact_s, t], np.r_[0.0, (x - zero) * sign]


def load_runs(path: Path | str, first_index: int = 0) -> list[RunTrace]:
    """One RunTrace per specimen/session block of a recording (a native run: one), indexed from `first_index`."""
    reader = open_reader(path)
    parsed = parse_run(reader)
    reader_streams = {"force_N": sorted_stream(reader, Topic.FORCE, "force_N"),
                      "displacement_m": sorted_stream(reader, Topic.CAMERA_DISPLACEMENT, "displacement_m")}
    meta = parsed.meta
    blocks = parsed.blocks()
    contact_events = [e.time_s for e in parsed.events if e.kind == EventKind.CONTACT_FOUND]
    tare = [e.time_s for e in parsed.events if e.kind == EventKind.TARE]
    out = []
    for b_i, block in enumerate(blocks):
        steps = [s for s in parsed.steps if block.start_s <= s.start_s < block.end_s] if len(blocks) > 1 \
            else parsed.steps
        timelines = parsed.timelines.window(block.start_s, block.end_s) if len(blocks) > 1 else parsed.timelines
        contact = [t for t in contact_events if block.start_s <= t < block.end_s] if len(blocks) > 1 \
            else contact_events
        tf, force = _in_block(*reader_streams["force_N"], block)
        tc, disp = _in_block(*reader_streams["displacement_m"], block)
        if contact:
            t_contact: float | None = contact[0]
            contact_kind = "search"
            stage = timelines.stage
        elif steps and meta.imported:
            # no contact search: the stage reference is the importer's zero sag, assumed touching at the start
            t_contact = min(s.start_s for s in steps) - 1e-3
            contact_kind = "assumed"
            stage = _stage_as_sag(parsed, timelines, t_contact) if timelines.sources.get("stage") == "measured" \
                else timelines.stage
        else:
            t_contact, contact_kind, stage = None, "none", timelines.stage
        specimen = block.specimen
        fixture = meta.fixture_kind
        session, rule = session_key(parsed.path, meta, specimen, block.session, fixture,
                                    contact_kind == "search")
        run = RunTrace(
            index=first_index + b_i, path=parsed.path, protocol=meta.protocol, fixture=fixture, design=meta.design,
            layers=meta.layers, params_set=meta.params_set, model_params=meta.model_params,
            bias_cmd=timelines.bias, drive_cmd=timelines.drive, stage_cmd=stage,
            t_contact_s=t_contact, t_tare_s=tare[0] if tare else 0.0,
            t_end_s=float(parsed.events[-1].time_s) if parsed.events else 0.0,
            specimen=specimen, session=session, session_rule=rule, timelines=dict(timelines.sources),
            source=meta.source, contact=contact_kind, force_reads_pull=reads_pull(force),
            clock_offset_s=_clock_offset(parsed.events, block),
            recorded_s=tuple(segments_of(np.concatenate([tf, tc]))))
        if len(blocks) > 1:
            run.t_end_s = block.end_s
        sensors = {"force_N": (tf, force), "displacement_m": (tc, disp)}
        for step in steps:
            base = dict(run=run.index, protocol=step.protocol, mode=step.mode, voltage_V=step.voltage_V,
                        sag_m=step.sag_m, repetition=step.repetition, direction=step.direction, step=step.index)
            if step.kind == "driven":
                if step.drive is not None:
                    run.step_timing[step.index] = step.drive
                _driven_rows(run, step, base, sensors)
            elif step.kind == "hold" and (step.protocol == "static" or step.mode == "stiffness"):
                _hold_row(run, step, base, tf, force)
        _pool_standard_errors(run)
        out.append(run)
    return out


def _clock_offset(events: list[Any], block: Any) -> float:
    """The importer's time shift of a specimen block (0 for a native run or an unshifted block)."""
    for e in events:
        if e.kind == EventKind.SPECIMEN and abs(e.time_s - block.start_s) < 1e-9:
            return float(e.data.get("time_offset_s", 0.0) or 0.0)
    return 0.0


def load_run(path: Path | str, index: int) -> RunTrace:
    """The first (for a native run: the only) RunTrace of a recording; `load_runs` gives every specimen's."""
    return load_runs(path, index)[0]


def _pool_standard_errors(run: RunTrace) -> None:
    """Standard error per row from the pure error pooled over the run's rows of the same phase and quantity."""
    for rows in _phase_groups(run).values():
        ss = sum(float(np.sum((r._cycle_values - r._cycle_values.mean()) ** 2)) for r in rows)  # type: ignore
        dof = sum(r._cycle_values.size - 1 for r in rows)  # type: ignore[attr-defined]
        var = ss / dof if dof > 0 else math.nan
        for r in rows:
            r.pure_var, r.pure_dof = var, dof
            r.se = math.sqrt(var / r.n) if np.isfinite(var) else math.nan


def _phase_groups(run: RunTrace) -> dict[tuple[str, str], list[Row]]:
    groups: dict[tuple[str, str], list[Row]] = {}
    for r in run.rows:
        groups.setdefault((r.quantity, r.phase), []).append(r)
    return groups


def moderate_standard_errors(runs: list[RunTrace]) -> dict[tuple[str, str, str], float]:
    """Each run's pure error of a window kind (fixture, quantity, phase) moderated toward the other runs'
    (`moderation.squeeze`, with a trend in log |V_bias|); the rows' `se` follow. Returns each kind's prior dof."""
    units: dict[tuple[str, str, str], list[list[Row]]] = {}
    for run in runs:
        for (quantity, phase), rows in _phase_groups(run).items():
            units.setdefault((run.fixture, quantity, phase), []).append(rows)
    prior: dict[tuple[str, str, str], float] = {}
    for kind, groups in units.items():
        var = np.array([g[0].pure_var for g in groups])
        dof = np.array([g[0].pure_dof for g in groups], float)
        volts = np.array([np.mean([math.log(max(abs(r.voltage_V), 1.0)) for r in g]) for g in groups])
        sq = squeeze(var, dof, volts)
        prior[kind] = sq.prior_dof
        for g, v in zip(groups, sq.variance, strict=True):
            for r in g:
                r.se = math.sqrt(v / r.n) if np.isfinite(v) else r.se
    return prior


def _load_runs_task(path: Path) -> list[RunTrace]:
    return load_runs(path, 0)


def load_gap_data(paths: Iterable[Path | str], jobs: int | None = 1, scheduler: Any = None) -> GapData:
    """Read recordings (files, or directories searched for *.mcap); `jobs` local processes or a Dask `scheduler`
    read them in parallel (analysis.parallel; jobs=1 reads in this process). Runs are numbered in file order,
    each file's specimen blocks in time order."""
    files = recording_files(paths)
    if jobs == 1 and scheduler is None:
        per_file = [load_runs(f, 0) for f in files]
    else:
        from analysis.parallel import parallel_map

        per_file = parallel_map(_load_runs_task, files, jobs=jobs, scheduler=scheduler)
    runs = [run for group in per_file for run in group]
    for k, run in enumerate(runs):
        run.index = k
        for row in run.rows:
            row.run = k
    share_specimen_history(runs)
    moderate_standard_errors(runs)
    rows = [r for run in runs for r in run.rows]
    if not rows:
        raise RecordingError(f"{files[0]}: no driven or static steps to compare with the model")
    return GapData(runs, rows)
