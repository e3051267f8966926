"""Recordings -> a tidy per-condition table, plus access to the raw traces.

One `Observation` per protocol step and measured quantity: the condition (protocol, design, layers, mode, voltage,
sag, repetition, direction), the value the protocol measures (the mean over the drive's cycles) and its spread over
cycles. What "the value" is, per protocol, is documented in `analysis/observations.py` and docs/analysis.md:

- driven steps: each trapezoid cycle's LOW and HIGH plateaus (from the recorded drive waveform, the last
  `drive.settle_s` of each plateau); force = mean /force over the high plateau (the sensor was tared with nothing
  touching, so this is absolute); stroke = mean /camera/displacement over the high plateau minus over the
  preceding low plateau (peak-to-peak, taken as a magnitude: the camera's sign convention is not used);
- static steps: mean /force over the step's hold (`hold_s` after the step event); the actuator protocol's
  undriven stiffness steps (mode 'stiffness', sag_m = push past contact) the same, with `stiffness.hold_s`;
- imported point tables: the `measurement` event of each step carries the value itself (one "cycle").

Steps and their cycles come from the recording contract's one step parser (`hamr_bench.recording.steps`, shared
with the gap diagnosis): a cycle's plateaus are its own corners, from the commanded drive waveform or, where the
recording has none (an imported trace), inferred from the measured drive monitor. A recording with several
specimens (an imported file) gives one `Run` per specimen/session block; `RunInfo.session` is the nuisance group
of `analysis.sessions` (the fit's zero offsets are per session, not per file).

The force the contact search left on the sensor (`preload_N`: mean force over the last 0.1 s before
`contact_found`) is kept per run, because the observation model needs it (zero sag is where the force dropped
below the release threshold, not where it is exactly zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from collections.abc import Iterable, Sequence

import numpy as np

from analysis.sessions import session_key
from hamr_bench.errors import HamrBenchError
from hamr_bench.recording.contract import EventKind, Topic
from hamr_bench.recording.drive_timing import Cycle, infer_cycles
from hamr_bench.recording.files import recording_files
from hamr_bench.recording.run_metadata import RunMetadata
from hamr_bench.recording.steps import StepRecord, open_reader, parse_run, sorted_stream

FORCE_WINDOW_S = 0.1          # the runner's averaging window during the contact search
DEFAULT_SETTLE_FRACTION = 0.5  # of a plateau, when the recording does not say how long to let it settle
LEG_PROTOCOLS = ("blocked-force", "sag-sweep", "free-displacement", "static")
KNOWN_PROTOCOLS = ("actuator",) + LEG_PROTOCOLS


@dataclass(frozen=True)
class RunInfo:
    """What a recording's metadata says about the run."""

    path: str
    protocol: str
    fixture: str                 # 'leg' | 'actuator'
    design: int | None
    layers: int
    params_set: str
    model_params: dict[str, Any]
    protocol_params: dict[str, Any]
    seed: str
    effects: dict[str, float]
    exit_status: str | None
    source: str                  # 'recorded' | 'import-points' | 'import-trace'
    preload_N: float
    preload_sd_N: float = 0.0    # standard error of preload_N (sample scatter in its window / sqrt(n))
    specimen: str = ""           # specimen label ('' = the recording names none: one specimen)
    session: str = ""            # nuisance group key (analysis.sessions); '' = the run alone
    session_rule: str = "recording"   # recording | explicit | default
    timelines: dict[str, str] = field(default_factory=dict)   # bias/drive/stage -> commanded|inferred|measured|absent
    span_s: tuple[float, float] | None = None   # this run's part of the file (several specimens in one file)


@dataclass(frozen=True)
class Observation:
    """One measured quantity at one protocol step (mean and spread over the drive's cycles)."""

    run: int                     # index into Dataset.runs
    protocol: str
    fixture: str
    design: int | None
    layers: int
    mode: str                    # 'blocked' | 'free' | 'stiffness' for the actuator protocol, '' otherwise
    quantity: str                # 'force_N' | 'displacement_m'
    voltage_V: float
    sag_m: float
    repetition: int
    direction: str
    step: int
    value: float
    spread: float                # standard deviation over cycles (nan with one cycle)
    n_cycles: int
    preload_N: float
    specimen: str = ""           # the run's specimen label
    session: str = ""            # the run's session key (analysis.sessions)


@dataclass
class Run:
    info: RunInfo
    observations: list[Observation] = field(default_factory=list)

    def reader(self):
        from hamr_bench.recording import RecordingReader

        return RecordingReader(self.info.path)

    def trace(self, topic: str) -> dict[str, np.ndarray]:
        """Raw stream of one topic (`{'time_s': ..., field: ...}`) within this run's part of the file; empty dict
        if the topic is absent."""
        reader = self.reader()
        if topic not in reader.topics():
            return {}
        data = reader.scalars(topic)
        if self.info.span_s is None:
            return data
        a, b = self.info.span_s
        keep = (data["time_s"] >= a) & (data["time_s"] < b)
        return {k: v[keep] for k, v in data.items()}


@dataclass
class Dataset:
    runs: list[Run]
    observations: list[Observation]

    def select(self, **where: Any) -> list[Observation]:
        """Observations whose fields equal every given value (a tuple/list value means 'any of')."""
        out = []
        for o in self.observations:
            ok = True
            for k, v in where.items():
                have = getattr(o, k)
                ok = have in v if isinstance(v, (tuple, list, set)) else have == v
                if not ok:
                    break
            if ok:
                out.append(o)
        return out

    def table(self) -> list[dict[str, Any]]:
        """The tidy table as a list of rows (one dict per observation, run path included)."""
        rows = []
        for o in self.observations:
            row = {k: getattr(o, k) for k in Observation.__dataclass_fields__}
            row["path"] = self.runs[o.run].info.path
            rows.append(row)
        return rows

    def write_csv(self, path: Path) -> None:
        import csv

        rows = self.table()
        with open(path, "w", newline="", encoding="utf-8") as fh:
            if not rows:
                return
            w = csv.DictWriter(fh, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)


# ----------------------------------------------------------------------------------------------- metadata
def run_info(path: Path, reader: Any, preload_N: float = 0.0, preload_sd_N: float = 0.0) -> RunInfo:
    """What a recording's metadata says about the run (the whole file: one block)."""
    return _info(path, RunMetadata.read(reader.metadata(), str(path)), reader.exit_status, preload_N, preload_sd_N)


def _info(path: Path | str, meta: RunMetadata, exit_status: str | None, preload_N: float = 0.0,
          preload_sd_N: float = 0.0, **extra: Any) -> RunInfo:
    return RunInfo(
        path=str(path), protocol=meta.protocol, fixture=meta.fixture_kind, design=meta.design, layers=meta.layers,
        params_set=meta.params_set, model_params=meta.model_params, protocol_params=meta.protocol_params,
        seed=meta.seed, effects=meta.effects, exit_status=exit_status, source=meta.source,
        preload_N=float(preload_N), preload_sd_N=float(preload_sd_N), **extra)


# ----------------------------------------------------------------------------------------------- traces -> cycles
def plateau_windows(time_s: np.ndarray, volts: np.ndarray, settle_s: float | None
                    ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """Per trapezoid cycle of a drive waveform, the averaging windows ((low_a, low_b), (high_a, high_b)): the
    cycles found by the recording contract's drive-timing inference (`infer_cycles`), each plateau minus its first
    `settle_s` (or minus half of it when `settle_s` is None or longer than half the plateau)."""
    return [_windows(c, settle_s) for c in infer_cycles(time_s, volts, start_s=float(time_s[0]) if len(time_s)
                                                         else None) if c.complete]


def _windows(c: Cycle, settle_s: float | None) -> tuple[tuple[float, float], tuple[float, float]]:
    def window(a: float, b: float) -> tuple[float, float]:
        span = b - a
        s = DEFAULT_SETTLE_FRACTION * span if settle_s is None else min(settle_s, DEFAULT_SETTLE_FRACTION * span)
        return a + s, b

    return window(c.low_start_s, c.rise_start_s), window(c.high_start_s, c.fall_start_s)


def _mean_in(t: np.ndarray, y: np.ndarray, a: float, b: float) -> float:
    i0, i1 = np.searchsorted(t, a, "left"), np.searchsorted(t, b, "right")
    if i1 <= i0:
        return math.nan
    return float(np.mean(y[i0:i1]))


def _stats(values: Sequence[float]) -> tuple[float, float, int]:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), (float(v.std(ddof=1)) if v.size > 1 else math.nan), int(v.size)


def _preload(tf: np.ndarray, force: np.ndarray, events: list[Any]) -> tuple[float, float]:
    """Mean force over the contact search's last averaging window, and its standard error."""
    contact = [e for e in events if e.kind == EventKind.CONTACT_FOUND]
    if not contact or not tf.size:
        return 0.0, 0.0
    i0 = np.searchsorted(tf, contact[0].time_s - FORCE_WINDOW_S, "left")
    i1 = np.searchsorted(tf, contact[0].time_s + 1e-9, "right")
    if i1 <= i0:
        return 0.0, 0.0
    window = force[i0:i1]
    return float(window.mean()), float(window.std(ddof=1) / math.sqrt(window.size)) if window.size > 1 else 0.0


def _driven_observations(step: StepRecord, base: dict[str, Any], tf: np.ndarray, force: np.ndarray,
                         tc: np.ndarray, disp: np.ndarray) -> list[Observation]:
    """A driven step: stroke (camera, high dwell minus low dwell) and force (high dwells), averaged over cycles."""
    out: list[Observation] = []
    if step.drive is None or not step.drive.cycles:
        return out
    cycles = [_windows(c, step.settle_s) for c in step.drive.cycles]
    if step.tracked and tc.size:
        strokes = [_mean_in(tc, disp, *hi) - _mean_in(tc, disp, *lo) for lo, hi in cycles]
        mean, spread, k = _stats(strokes)
        if k:
            out.append(Observation(quantity="displacement_m", value=mean, spread=spread, n_cycles=k, **base))
    if (not step.tracked or step.mode == "blocked") and tf.size:
        mean, spread, k = _stats([_mean_in(tf, force, *hi) for _lo, hi in cycles])
        if k:
            out.append(Observation(quantity="force_N", value=mean, spread=spread, n_cycles=k, **base))
    return out


def _step_observations(step: StepRecord, base: dict[str, Any], tf: np.ndarray, force: np.ndarray,
                       tc: np.ndarray, disp: np.ndarray) -> list[Observation]:
    """What one step measures (module docstring)."""
    out = []
    if step.kind == "point":
        for q, v in step.measured.items():
            out.append(Observation(quantity=q, value=v, spread=math.nan, n_cycles=1, **base))
    elif step.kind == "driven":
        out += _driven_observations(step, base, tf, force, tc, disp)
    elif step.hold_window_s is not None and tf.size:
        # undriven step (static leg, or the actuator's stiffness sweep): the force over its hold window
        a, b = step.hold_window_s
        i0, i1 = np.searchsorted(tf, a, "left"), np.searchsorted(tf, b, "right")
        if i1 > i0:
            seg = force[i0:i1]
            out.append(Observation(quantity="force_N", value=float(seg.mean()),
                                   spread=float(seg.std(ddof=1)) if seg.size > 1 else math.nan, n_cycles=1,
                                   **base))
    # stroke magnitude: the camera's sign convention is a rig setting, not physics
    return [Observation(**{**o.__dict__, "value": -o.value}) if o.quantity == "displacement_m" and o.value < 0
            else o for o in out]


# ----------------------------------------------------------------------------------------------- one recording
def load_runs(path: Path | str, first_index: int = 0) -> list[Run]:
    """Read one recording into Runs with their observations: one per specimen/session block (a native run: one).
    Raises RecordingError naming the file."""
    path = Path(path)
    reader = open_reader(path)
    parsed = parse_run(reader)
    tf, force = sorted_stream(reader, Topic.FORCE, "force_N")
    tc, disp = sorted_stream(reader, Topic.CAMERA_DISPLACEMENT, "displacement_m")
    preload, preload_sd = _preload(tf, force, parsed.events)
    blocks = parsed.blocks()
    runs = []
    for b_i, block in enumerate(blocks):
        several = len(blocks) > 1
        steps = [s for s in parsed.steps if block.start_s <= s.start_s < block.end_s] if several else parsed.steps
        searched = any(e.kind == EventKind.CONTACT_FOUND and block.start_s <= e.time_s < block.end_s
                       for e in parsed.events) if several else \
            any(e.kind == EventKind.CONTACT_FOUND for e in parsed.events)
        session, rule = session_key(str(path), parsed.meta, block.specimen, block.session,
                                    parsed.meta.fixture_kind, searched)
        info = _info(path, parsed.meta, reader.exit_status, preload, preload_sd, specimen=block.specimen,
                     session=session, session_rule=rule, timelines=dict(parsed.timelines.sources),
                     span_s=(block.start_s, block.end_s) if several else None)
        run = Run(info)
        index = first_index + b_i
        for step in steps:
            fixture = "actuator" if step.protocol == "actuator" else "leg"
            base = dict(run=index, protocol=step.protocol, fixture=fixture, design=step.design, layers=step.layers,
                        mode=step.mode, voltage_V=step.voltage_V, sag_m=step.sag_m, repetition=step.repetition,
                        direction=step.direction, step=step.index, preload_N=preload, specimen=block.specimen,
                        session=session)
            run.observations += _step_observations(step, base, tf, force, tc, disp)
        runs.append(run)
    return runs


def load_run(path: Path | str, index: int = 0) -> Run:
    """The first (for a native run: the only) Run of a recording; `load_runs` gives every specimen's."""
    return load_runs(path, index)[0]


def load_dataset(paths: Iterable[Path | str], skip_failed: bool = False) -> Dataset:
    """Read recordings (files, or directories searched for *.mcap) into one Dataset."""
    files = recording_files(paths)
    runs: list[Run] = []
    for f in files:
        try:
            runs.extend(load_runs(f, len(runs)))
        except HamrBenchError:
            if skip_failed:
                continue
            raise
    obs = [o for r in runs for o in r.observations]
    return Dataset(runs, obs)
