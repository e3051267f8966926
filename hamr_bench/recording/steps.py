"""The one step parser: a recording's `step` events as typed `StepRecord`s with their drive timing, and the run's
command timelines (bias, drive, stage), COMMANDED where the recording holds them and INFERRED from what was
measured where it does not (an imported trace, a recording that lost its command streams); a drive monitor that
is exact (no noise: a logged command, held from one row to the next) is its own timeline, LOGGED, read as
played. Both the dataset (`analysis.dataset`) and the gap diagnosis (`analysis.gap.features`) stand on it, so a
step means the same to both.

A step's kind:
- `point`: an imported point table's step; its `measurement` event carries the values (`StepRecord.measured`);
- `driven`: a `drive_start` event inside it, or (no drive command stream) measured drive cycles inside it; its
  `DriveTiming` lists the complete trapezoid cycles with their own corners (hamr_bench.recording.drive_timing),
  from the commanded waveform (source `commanded`) or from `/amplifier/drive/monitor` (source `inferred`);
- `hold`: anything else (the leg's static test, the actuator's stiffness sweep): one averaging window, the
  protocol's `hold_s` (`stiffness.hold_s` for a stiffness step) after the step event, or, where the recording does
  not say (an imported trace), the second half of the step's span.

Specimens and sessions: an imported file may hold several specimens (and sessions) one after another; each step's
condition names its `specimen` and `session`, and `specimen` events mark where each block begins.
`ParsedRun.blocks()` gives those blocks; a native recording is one block.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any
from collections.abc import Iterator

import numpy as np

from hamr_bench.recording.contract import EventKind, Topic
from hamr_bench.recording.drive_timing import Cycle, WaveformStats, infer_cycles, waveform_stats
from hamr_bench.recording.run_metadata import RunMetadata

HOLD_SETTLE_FRACTION = 0.5     # an undriven step without a recorded hold time: the second half of its span
INFERRED_RAMP_DT_S = 1e-3      # the inferred drive timeline samples its ramps at least this finely
STAGE_TOLERANCE_M = 1e-6       # measured stage positions within this are one set-point
COMMANDED, INFERRED, LOGGED, MEASURED, ABSENT = "commanded", "inferred", "logged", "measured", "absent"


@dataclass(frozen=True)
class DriveTiming:
    """The drive of one step: its complete cycles and where they came from."""

    source: str                         # commanded | inferred
    bias_V: float                       # V_bias: the median high level of the cycles (nan without one)
    cycles: tuple[Cycle, ...]           # complete cycles only, in time order
    incomplete: int = 0                 # cycles of this step cut by the start or end of the data
    bias_se_V: float = 0.0              # standard error of an inferred bias_V (0 for a commanded one)

    def _median(self, name: str) -> float:
        return float(np.median([getattr(c, name) for c in self.cycles])) if self.cycles else math.nan

    @property
    def dwell_low_s(self) -> float:
        return self._median("dwell_low_s")

    @property
    def ramp_up_s(self) -> float:
        return self._median("ramp_up_s")

    @property
    def dwell_high_s(self) -> float:
        return self._median("dwell_high_s")

    @property
    def ramp_down_s(self) -> float:
        return self._median("ramp_down_s")

    def summary(self) -> dict[str, Any]:
        """JSON-ready: source, V_bias, cycle count and the median dwell / ramp lengths."""
        def num(x: float) -> float | None:
            return round(x, 6) if math.isfinite(x) else None

        return {"source": self.source, "bias_V": num(self.bias_V), "bias_se_V": num(self.bias_se_V),
                "cycles": len(self.cycles),
                "incomplete_cycles": self.incomplete, "dwell_low_s": num(self.dwell_low_s),
                "ramp_up_s": num(self.ramp_up_s), "dwell_high_s": num(self.dwell_high_s),
                "ramp_down_s": num(self.ramp_down_s)}


@dataclass(frozen=True)
class StepRecord:
    """One protocol step: its condition, its span, and how it is measured."""

    index: int
    start_s: float
    end_s: float                        # the next step's start, or the end of the data
    message: str
    condition: dict[str, Any]
    protocol: str
    fixture: str
    design: int | None
    layers: int
    mode: str                           # blocked | free | stiffness (actuator), '' otherwise
    voltage_V: float
    sag_m: float
    repetition: int
    direction: str
    specimen: str                       # '' = the recording names none (one specimen)
    session: str                        # explicit session label, '' = none given
    kind: str                           # driven | hold | point
    tracked: bool                       # the camera measured this step (free displacement)
    drive: DriveTiming | None = None
    hold_window_s: tuple[float, float] | None = None
    settle_s: float | None = None       # the protocol's drive.settle_s (None: half of each plateau)
    measured: dict[str, float] = field(default_factory=dict)


@dataclass(frozen=True)
class Timelines:
    """What the rig was driven with, per channel (time_s, value) in time order, and where each came from."""

    bias: tuple[np.ndarray, np.ndarray]
    drive: tuple[np.ndarray, np.ndarray]
    stage: tuple[np.ndarray, np.ndarray]
    sources: dict[str, str]             # bias / drive / stage -> commanded | inferred | measured | absent

    def window(self, start_s: float, end_s: float) -> Timelines:
        """The timelines cut to [start_s, end_s]; the value in force at start_s is kept as a sample there."""
        def cut(tv: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
            t, v = tv
            if t.size == 0:
                return tv
            i0 = int(np.searchsorted(t, start_s, "right"))
            i1 = int(np.searchsorted(t, end_s, "right"))
            if i0 > 0:
                return np.r_[start_s, t[i0:i1]], np.r_[v[i0 - 1], v[i0:i1]]
            return t[i0:i1], v[i0:i1]

        return replace(self, bias=cut(self.bias), drive=cut(self.drive), stage=cut(self.stage))


@dataclass(frozen=True)
class Block:
    """A contiguous part of a recording with one specimen and session (a native run is one block)."""

    specimen: str
    session: str
    start_s: float
    end_s: float


@dataclass
class ParsedRun:
    """A recording read once: metadata, events, steps and timelines."""

    path: str
    meta: RunMetadata
    events: list[Any]
    steps: list[StepRecord]
    timelines: Timelines
    start_s: float
    end_s: float

    def blocks(self) -> list[Block]:
        """Specimen/session blocks in time order (from `specimen` events, else from the steps' labels)."""
        marks = [e for e in self.events if e.kind == EventKind.SPECIMEN]
        out: list[Block] = []
        if marks:
            for k, e in enumerate(marks):
                end = marks[k + 1].time_s if k + 1 < len(marks) else self.end_s
                out.append(Block(str(e.data.get("specimen", "")), str(e.data.get("session", "")), e.time_s, end))
            return out
        for s in self.steps:
            if out and (out[-1].specimen, out[-1].session) == (s.specimen, s.session):
                continue
            if out:
                out[-1] = replace(out[-1], end_s=s.start_s)
            out.append(Block(s.specimen, s.session, s.start_s if out else self.start_s, self.end_s))
        return out or [Block("", self.meta.session, self.start_s, self.end_s)]


# ----------------------------------------------------------------------------------------------- reading
def _stream(reader: Any, topic: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    topics = reader.topics()
    if topic not in topics or not topics[topic].message_count:
        return np.empty(0), np.empty(0)
    s = reader.scalars(topic)
    t, x = np.asarray(s["time_s"], float), np.asarray(s[name], float)
    ok = np.isfinite(t)
    order = np.argsort(t[ok], kind="stable")
    return t[ok][order], x[ok][order]


def _num(cond: dict[str, Any], key: str, default: float) -> float:
    try:
        v = float(cond.get(key, default))
    except (TypeError, ValueError):
        return default
    return v if math.isfinite(v) else default


def _commanded_drive(t: np.ndarray, v: np.ndarray, start: Any) -> DriveTiming | None:
    """The cycles of the waveform a `drive_start` event announced: its `n_samples` command samples from the
    first at or after the event (1 ms tolerance)."""
    n = int(_num(start.data, "n_samples", 0))
    k = int(np.searchsorted(t, start.time_s - 1e-3, "left"))
    if k >= t.size:
        return None
    seg_t, seg_v = (t[k:k + n], v[k:k + n]) if n else (t[k:], v[k:])
    cycles = infer_cycles(seg_t, seg_v, start_s=float(seg_t[0]))
    return _timing(COMMANDED, cycles)


def _timing(source: str, cycles: list[Cycle]) -> DriveTiming:
    """A step's drive: its complete cycles, V_bias the mean of all their flat-top samples (a setpoint held through
    the step; pooling the cycles makes an inferred level as precise as the monitor allows) and its standard
    error."""
    complete = tuple(c for c in cycles if c.complete)
    if not complete:
        return DriveTiming(source, math.nan, (), len(cycles))
    n = np.array([max(c.level_samples, 1) for c in complete], dtype=float)
    levels = np.array([c.level_V for c in complete])
    bias = float(np.sum(n * levels) / np.sum(n))
    se = float(np.sqrt(np.sum((n * np.array([c.level_se_V for c in complete])) ** 2)) / np.sum(n))
    return DriveTiming(source, bias, complete, len(cycles) - len(complete), se)


def _data_span(reader: Any, events: list[Any]) -> tuple[float, float]:
    firsts = [ti.first_time_s for ti in reader.topics().values() if ti.first_time_s is not None]
    lasts = [ti.last_time_s for ti in reader.topics().values() if ti.last_time_s is not None]
    times = [e.time_s for e in events]
    start = min(firsts + times) if (firsts or times) else 0.0
    end = max(lasts + times) if (lasts or times) else 0.0
    return float(start), float(end)


@dataclass(frozen=True)
class _Monitor:
    """The recorded drive voltage's finite samples and their waveform statistics, read once per recording."""
    t_s: np.ndarray
    voltage_V: np.ndarray
    stats: WaveformStats | None

    @classmethod
    def read(cls, reader: Any) -> _Monitor:
        t, v = _stream(reader, Topic.DRIVE_MONITOR, "voltage_V")
        ok = np.isfinite(v)
        t, v = t[ok], v[ok]
        return cls(t, v, waveform_stats(v) if t.size >= 3 else None)


def _monitor_cycles(monitor: _Monitor) -> list[Cycle]:
    """Drive cycles inferred from the recorded drive voltage (a recording without a command stream)."""
    if monitor.stats is None:
        return []
    return infer_cycles(monitor.t_s, monitor.voltage_V, stats=monitor.stats)


def parse_run(reader: Any, meta: RunMetadata | None = None) -> ParsedRun:
    """Read a recording's steps and timelines (`reader`: a RecordingReader)."""
    where = str(reader.path)
    meta = meta or RunMetadata.read(reader.metadata(), where)
    events = sorted(reader.events(), key=lambda e: e.time_s)
    start_s, end_s = _data_span(reader, events)
    td, vd = _stream(reader, Topic.DRIVE_COMMAND, "voltage_V")
    commanded = td.size > 0
    monitor = None if commanded else _Monitor.read(reader)
    monitor_cycles = [] if monitor is None else _monitor_cycles(monitor)
    params = meta.protocol_params
    drive_p = params.get("drive")
    settle = drive_p.get("settle_s") if isinstance(drive_p, dict) else None
    hold_s = params.get("hold_s")
    stiff_p = params.get("stiffness")
    stiff_hold_s = stiff_p.get("hold_s") if isinstance(stiff_p, dict) else None
    tf = _stream(reader, Topic.FORCE, "force_N")[0]
    last_force = float(tf[-1]) if tf.size else end_s

    step_idx = [i for i, e in enumerate(events) if e.kind == EventKind.STEP]
    steps: list[StepRecord] = []
    for n, i in enumerate(step_idx):
        ev = events[i]
        nxt_i = step_idx[n + 1] if n + 1 < len(step_idx) else len(events)
        t_end = events[nxt_i].time_s if n + 1 < len(step_idx) else end_s
        inside = events[i + 1:nxt_i]
        cond = dict(ev.data)
        protocol = str(cond.get("protocol", meta.protocol))
        fixture = "actuator" if protocol == "actuator" else ("leg" if protocol != "mixed" else meta.fixture_kind)
        design_v = cond.get("design", meta.design)
        try:
            design = int(design_v) if design_v not in (None, "") else None
        except (TypeError, ValueError):
            design = None
        mode = str(cond.get("mode", ""))
        starts = [e for e in inside if e.kind == EventKind.DRIVE_START]
        measured_ev = [e for e in inside if e.kind == EventKind.MEASUREMENT]
        tracked = (bool(starts[0].data.get("track", False)) if starts else False) \
            or protocol == "free-displacement" or mode == "free"
        drive = None
        hold = None
        measured: dict[str, float] = {}
        if measured_ev:
            kind = "point"
            for q in ("force_N", "displacement_m"):
                value = measured_ev[0].data.get(q)
                if isinstance(value, (int, float)) and math.isfinite(float(value)):
                    measured[q] = float(value)
        elif commanded and starts:
            kind = "driven"
            drive = _commanded_drive(td, vd, starts[0])
        elif not commanded and (starts or any(ev.time_s <= c.rise_start_s < t_end for c in monitor_cycles)):
            kind = "driven"
            mine = [c for c in monitor_cycles if ev.time_s <= c.rise_start_s < t_end]
            drive = _timing(INFERRED, mine)
        else:
            kind = "hold"
            h = stiff_hold_s if mode == "stiffness" else hold_s
            if isinstance(h, (int, float)) and h > 0:
                hold = (ev.time_s, min(ev.time_s + float(h), t_end))
            else:
                end = min(t_end, last_force)
                hold = (ev.time_s + HOLD_SETTLE_FRACTION * max(end - ev.time_s, 0.0), end)
        steps.append(StepRecord(
            index=int(ev.step), start_s=float(ev.time_s), end_s=float(t_end), message=ev.message, condition=cond,
            protocol=protocol, fixture=fixture, design=design,
            layers=int(_num(cond, "layers", meta.layers)), mode=mode, voltage_V=_num(cond, "voltage_V", 0.0),
            sag_m=_num(cond, "sag_m", 0.0), repetition=int(_num(cond, "repetition", 0)),
            direction=str(cond.get("direction", "up")), specimen=str(cond.get("specimen", "")),
            session=str(cond.get("session", meta.session)), kind=kind, tracked=tracked, drive=drive,
            hold_window_s=hold, settle_s=float(settle) if isinstance(settle, (int, float)) else None,
            measured=measured))
    timelines = _timelines(reader, steps, monitor, monitor_cycles)
    return ParsedRun(where, meta, events, steps, timelines, start_s, end_s)


def iter_steps(reader: Any, meta: RunMetadata | None = None) -> Iterator[StepRecord]:
    """Every step of a recording, in time order (see the module docstring)."""
    yield from parse_run(reader, meta).steps


def open_reader(path: Path | str) -> Any:
    """A RecordingReader on `path`; a partial file reads up to its last complete record, silently (its finished
    steps are still steps). RecordingError names a missing file."""
    from hamr_bench.errors import RecordingError
    from hamr_bench.recording.reader import RecordingReader, RecordingWarning

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)
        return RecordingReader(path)


def read_run(path: Path | str) -> ParsedRun:
    """Open a recording and parse it (`open_reader`, `parse_run`)."""
    return parse_run(open_reader(path))


def sorted_stream(reader: Any, topic: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    """(time_s, field) of a scalar topic in time order (empty arrays when the topic is absent or empty)."""
    return _stream(reader, topic, name)


# ----------------------------------------------------------------------------------------------- timelines
def _trapezoids(cycles: list[Cycle], steps: list[StepRecord]) -> tuple[np.ndarray, np.ndarray]:
    """The drive through each cycle's corners (ground 0 V), ramps sampled finely: read with a zero-order hold it
    is the inferred waveform, as a command stream is read. A cycle of a step is at the step's V_bias (the pooled
    level), any other (cut by the data's edges) at its own."""
    level_of = {c.rise_start_s: s.drive.bias_V for s in steps if s.drive is not None for c in s.drive.cycles}
    ts: list[np.ndarray] = []
    vs: list[np.ndarray] = []
    for c in cycles:
        level = level_of.get(c.rise_start_s, c.level_V)
        for a, va, b, vb in ((c.rise_start_s, 0.0, c.high_start_s, level),
                             (c.fall_start_s, level, c.fall_end_s, 0.0)):
            if b > a:
                n = max(2, int(math.ceil((b - a) / min(INFERRED_RAMP_DT_S, (b - a) / 20.0))) + 1)
                ts.append(np.linspace(a, b, n))
                vs.append(np.linspace(va, vb, n))
            else:
                ts.append(np.array([a]))
                vs.append(np.array([vb]))
    if not ts:
        return np.empty(0), np.empty(0)
    t, v = np.concatenate(ts), np.concatenate(vs)
    order = np.argsort(t, kind="stable")
    return t[order], v[order]


def _logged_staircase(monitor: _Monitor) -> tuple[np.ndarray, np.ndarray] | None:
    """The drive column as the staircase it is, where it holds no noise (None where it does: a measured monitor).
    A noise-free drive column is what the lab's logger says its DAQ wrote, held from row to row; the amplifier
    played those steps, and a sensor sample saw the step in force when it was taken. Where the logger also wrote a
    row for each sensor sample, the sensor's clock falls against the command's at a phase of its own in every
    waveform, up to a command step late: a smooth trapezoid through the corners loses that phase, the steps keep
    it. Each value is kept from the row where it changed (a repeat holds no news)."""
    if monitor.stats is None or monitor.stats.noise_V > 0.0:
        return None
    t, v = monitor.t_s, monitor.voltage_V
    changed = np.r_[True, v[1:] != v[:-1]]
    return t[changed], v[changed]


def _setpoints(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Measured stage positions -> set-points: a new one where the position moves by more than the tolerance."""
    keep = []
    last = math.nan
    for i, xi in enumerate(x):
        if math.isfinite(xi) and not abs(xi - last) <= STAGE_TOLERANCE_M:
            keep.append(i)
            last = xi
    idx = np.asarray(keep, dtype=int)
    return t[idx], x[idx]


def _timelines(reader: Any, steps: list[StepRecord], monitor: _Monitor | None,
               monitor_cycles: list[Cycle]) -> Timelines:
    """Where there is no drive command (`monitor` is not None), the drive is the logged staircase or the
    trapezoids inferred from the monitor's cycles."""
    sources: dict[str, str] = {}
    empty = (np.empty(0), np.empty(0))
    drive = _stream(reader, Topic.DRIVE_COMMAND, "voltage_V")
    if monitor is None:
        sources["drive"] = COMMANDED
    elif monitor_cycles:
        logged = _logged_staircase(monitor)
        drive, sources["drive"] = (logged, LOGGED) if logged is not None else \
            (_trapezoids(monitor_cycles, steps), INFERRED)
    else:
        drive, sources["drive"] = empty, ABSENT
    bias = _stream(reader, Topic.BIAS_COMMAND, "voltage_V")
    if bias[0].size:
        sources["bias"] = COMMANDED
    elif any(s.kind == "driven" for s in steps):
        # V_bias held from each step's start (the runner sets it before the drive), 0 V on undriven steps
        t = np.array([s.start_s for s in steps if s.kind != "point"])
        v = np.array([s.drive.bias_V if s.drive is not None and math.isfinite(s.drive.bias_V) else 0.0
                      for s in steps if s.kind != "point"])
        bias, sources["bias"] = (t, v), INFERRED
    else:
        bias, sources["bias"] = empty, ABSENT
    stage = _stream(reader, Topic.STAGE_COMMAND, "target_m")
    if stage[0].size:
        sources["stage"] = COMMANDED
    else:
        measured = _stream(reader, Topic.STAGE_POSITION, "position_m")
        if measured[0].size and np.isfinite(measured[1]).any():
            stage, sources["stage"] = _setpoints(*measured), MEASURED
        else:
            stage, sources["stage"] = empty, ABSENT
    return Timelines(bias, drive, stage, sources)
