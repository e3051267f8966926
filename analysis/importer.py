"""CSV -> recordings: measurements made elsewhere (another lab's table, a spreadsheet, a data logger's export) become
MCAP recordings with the same metadata and events as a run, so every later command treats them alike. The formats
and rules are in docs/log-format.md ("Importing CSV measurements"); reading the CSV itself (encodings, delimiters,
decimal commas, one-line errors) is analysis/csv_table.py.

- points: one row per measurement. Each row becomes a `step` event with its condition, followed by a `measurement`
  event carrying the measured value(s); the values are also written as single samples on /force and
  /camera/displacement (one second apart) so the file plots in Foxglove. There are no raw traces to reduce.
- trace: one time series of one protocol. The drive voltage goes to /amplifier/drive/monitor, the rest to
  /stage/position, /force, /camera/displacement. The drive's cycles are found by the recording contract's
  drive-timing inference (hamr_bench.recording.drive_timing, the same the readers use), grouped into steps (same
  level, stage position and mode), and written as `step`, `drive_start` (with the inferred timing) and
  `drive_end` events; static: each stage plateau is a step.

Both formats take optional `specimen` and `session` columns: each contiguous block of rows with one (specimen,
session) gets a `specimen` event and its label in every step's condition. Time may restart in a new block; the
block is then shifted to follow the previous one (`time_offset_s` in its `specimen` event).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from analysis.csv_table import Table, read_table
from hamr_bench.errors import ConfigError
from hamr_bench.recording.contract import EventKind, Topic
from hamr_bench.recording.drive_timing import Cycle, infer_cycles, waveform_stats
from hamr_bench.recording.run_metadata import RunMetadata

POINT_COLUMNS = ("protocol", "design", "layers", "voltage_V", "sag_m", "repetition", "force_N", "displacement_m")
TRACE_COLUMNS = ("time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m")
LABEL_COLUMNS = ("specimen", "session")
PROTOCOLS = ("actuator", "blocked-force", "sag-sweep", "free-displacement", "static")
STAGE_TOLERANCE_M = 1e-6      # two stage readings within this are the same set-point
MIN_STATIC_PLATEAU_S = 0.05
SAME_LEVEL_FRACTION = 0.02    # cycles within 2 % of a step's level (and 6 noise sigmas) belong to it
BLOCK_GAP_S = 1.0             # at least this much time (and 100 sample spacings) between two blocks' data


# ----------------------------------------------------------------------------------------------- blocks
@dataclass(frozen=True)
class BlockRows:
    """Rows [start, stop) of one specimen/session block (row indices into the table's rows)."""

    specimen: str
    session: str
    start: int
    stop: int
    first_line: int
    last_line: int


def _label(text: str) -> str:
    """A label as given; a number written as a float ('1.0', '1,0') is the integer it names."""
    t = text.strip()
    try:
        v = float(t.replace(",", "."))
    except ValueError:
        return t
    return str(int(v)) if math.isfinite(v) and v.is_integer() else t


def _labels(table: Table, column: str, default: str) -> list[str]:
    """Per row, the column's label; a blank cell holds the label above it (a spreadsheet's merged cells), and
    blank cells before any label take `default` (no specimen named: '')."""
    if not table.has(column):
        return [default] * len(table.rows)
    out, last = [], default
    for text in table.cells(column):
        if text:
            last = _label(text)
        out.append(last)
    return out


def _blocks(table: Table, session: str | None) -> list[BlockRows]:
    specimens = _labels(table, "specimen", "")
    sessions = _labels(table, "session", session or "")
    blocks: list[BlockRows] = []
    seen: dict[tuple[str, str], int] = {}
    for i, key in enumerate(zip(specimens, sessions, strict=True)):
        line = table.rows[i][0]
        if blocks and (blocks[-1].specimen, blocks[-1].session) == key:
            blocks[-1] = BlockRows(*key, blocks[-1].start, i + 1, blocks[-1].first_line, line)
            continue
        if key in seen:
            what = f"specimen {key[0]!r}" + (f" (session {key[1]!r})" if key[1] else "")
            raise ConfigError(f"{table.path}:{line}: column specimen: {what} again after other rows (its rows "
                              f"must be contiguous; first block from line {seen[key]})")
        seen[key] = line
        blocks.append(BlockRows(*key, i, i + 1, line, line))
    return blocks


def _metadata(protocol: str, design: int | None, layers: int, source: str, csv_path: Path, table: Table,
              session: str | None, params: dict | None = None, extra: dict[str, str] | None = None) -> RunMetadata:
    fixture = "actuator" if protocol == "actuator" else ("mixed" if protocol == "mixed" else "leg")
    return RunMetadata(
        protocol=protocol, protocol_params=params or {}, design=design, layers=layers, fixture=fixture,
        params_set="effective", rig_name="imported", rig_path=str(csv_path), rig_kind="imported", clock="imported",
        source=source, imported_from=str(csv_path), session=session or "",
        run_extra={"delimiter": "tab" if table.delimiter == "\t" else table.delimiter,
                   "decimal_comma": "true" if table.decimal_comma else "false", **(extra or {})})


def _specimen_event(rec: Any, t: float, block: BlockRows, csv_name: str, **data: Any) -> None:
    what = f"specimen {block.specimen!r}" if block.specimen else "the specimen"
    rec.write_event(t, EventKind.SPECIMEN, 0, f"{what}: {csv_name} lines {block.first_line}-{block.last_line}",
                    specimen=block.specimen, session=block.session, first_line=block.first_line,
                    last_line=block.last_line, **data)


# ----------------------------------------------------------------------------------------------- points
@dataclass(frozen=True)
class PointRow:
    line: int
    protocol: str
    design: int | None
    layers: int
    voltage_V: float
    sag_m: float
    repetition: int
    force_N: float | None
    displacement_m: float | None
    mode: str = ""
    specimen: str = ""
    session: str = ""


def read_points(path: Path, session: str | None = None, delimiter: str | None = None) -> list[PointRow]:
    table = read_table(Path(path), POINT_COLUMNS, delimiter)
    path = table.path
    specimens = _labels(table, "specimen", "")
    sessions = _labels(table, "session", session or "")
    _blocks(table, session)   # contiguity of each specimen's rows
    out = []
    for k, (line, row) in enumerate(table.rows):
        col = dict(zip(table.header, row, strict=True))

        def num(name: str, **kw: Any) -> float | None:
            return table.number(line, name, col.get(name, ""), **kw)  # noqa: B023 (used at once)

        protocol = col["protocol"].strip()
        if protocol not in PROTOCOLS:
            raise ConfigError(f"{path}:{line}: column protocol: expected one of {', '.join(PROTOCOLS)}, "
                              f"got {protocol[:40]!r}")
        design = num("design", blank_ok=protocol == "actuator", integer=True)
        if design is not None and design not in (1, 2, 3, 4, 5):
            raise ConfigError(f"{path}:{line}: column design: expected 1..5, got {col['design'].strip()[:40]!r}")
        layers = num("layers", blank_ok=protocol != "actuator", integer=True)
        layers = 2 if layers is None else int(layers)
        if layers not in (1, 2, 3):
            raise ConfigError(f"{path}:{line}: column layers: expected 1, 2 or 3, got "
                              f"{col['layers'].strip()[:40]!r}")
        voltage = num("voltage_V", blank_ok=protocol == "static", lo=0.0)
        sag = num("sag_m", lo=-0.01)
        rep = num("repetition", integer=True, lo=0)
        force = num("force_N")
        disp = num("displacement_m")
        if force is None and disp is None:
            raise ConfigError(f"{path}:{line}: column force_N: blank, and displacement_m is blank too "
                              "(nothing measured)")
        if protocol == "free-displacement" and disp is None:
            raise ConfigError(f"{path}:{line}: column displacement_m: free-displacement rows need a displacement")
        if protocol in ("blocked-force", "sag-sweep", "static") and force is None:
            raise ConfigError(f"{path}:{line}: column force_N: {protocol} rows need a force")
        out.append(PointRow(line, protocol, None if design is None else int(design), layers,
                            0.0 if voltage is None else voltage, 0.0 if sag is None else sag,
                            0 if rep is None else int(rep), force, disp, specimen=specimens[k],
                            session=sessions[k]))
    return out


def import_points(csv_path: Path, out_path: Path, overwrite: bool = False, session: str | None = None,
                  delimiter: str | None = None) -> int:
    """Write the points table as one recording; returns the number of steps written."""
    from hamr_bench.recording import Recorder

    csv_path, out_path = Path(csv_path), Path(out_path)
    table = read_table(csv_path, POINT_COLUMNS, delimiter)
    rows = read_points(csv_path, session, delimiter)
    protocols = sorted({r.protocol for r in rows})
    designs = sorted({r.design for r in rows if r.design is not None})
    layer_set = sorted({r.layers for r in rows})
    protocol = protocols[0] if len(protocols) == 1 else "mixed"
    design = designs[0] if len(designs) == 1 else None
    meta = _metadata(protocol, design, layer_set[0] if len(layer_set) == 1 else 2, "import-points", csv_path,
                     table, session)
    rec = Recorder(out_path, overwrite=overwrite, start_time_ns=0)
    step = 0
    try:
        meta.write(rec)
        rec.write_event(0.0, EventKind.RUN_START, 0, f"imported from {csv_path.name}")
        starts = {b.start: b for b in _blocks(table, session)}
        for i, r in enumerate(rows):
            if i in starts:
                _specimen_event(rec, float(step + 1) - 0.5, starts[i], csv_path.name)
            for mode, f, d in _point_modes(r):
                t = float(step + 1)
                cond: dict[str, Any] = {"protocol": r.protocol, "layers": r.layers, "voltage_V": r.voltage_V,
                                        "sag_m": r.sag_m, "repetition": r.repetition, "direction": "up",
                                        "source_line": r.line, "specimen": r.specimen, "session": r.session}
                if r.design is not None:
                    cond["design"] = r.design
                if mode:
                    cond["mode"] = mode
                rec.write_event(t, EventKind.STEP, step, f"{csv_path.name} line {r.line}", **cond)
                data = {}
                if f is not None:
                    data["force_N"] = f
                    rec.write_scalar(Topic.FORCE, t, force_N=f)
                if d is not None:
                    data["displacement_m"] = d
                    rec.write_scalar(Topic.CAMERA_DISPLACEMENT, t, displacement_m=d, x_px=math.nan, y_px=math.nan)
                rec.write_event(t, EventKind.MEASUREMENT, step, "", **data)
                step += 1
        rec.write_event(float(step + 1), EventKind.RUN_END, 0, "imported", exit_status="success")
    except BaseException:
        rec.close("failed", "import failed")
        raise
    rec.close("success", "")
    return step


def _point_modes(r: PointRow) -> list[tuple[str, float | None, float | None]]:
    """(mode, force, displacement) of the steps one point row becomes."""
    if r.protocol == "actuator" and r.voltage_V == 0 and r.sag_m > 0:
        # undriven, pushed past contact: a stiffness-sweep row (its force; a camera reading is not used)
        return [("stiffness", r.force_N, None)] if r.force_N is not None else []
    if r.protocol == "actuator":
        modes: list[tuple[str, float | None, float | None]] = []
        if r.force_N is not None:
            modes.append(("blocked", r.force_N, None))
        if r.displacement_m is not None:
            modes.append(("free", None, r.displacement_m))
        return modes
    return [("", r.force_N, r.displacement_m)]


# ----------------------------------------------------------------------------------------------- trace
@dataclass
class Trace:
    """A trace read from CSV: columns on the recording's time axis (blocks shifted apart), and its blocks."""

    table: Table
    time_s: np.ndarray
    columns: dict[str, np.ndarray]
    blocks: list[BlockRows]
    offsets_s: list[float]


def read_trace(path: Path, protocol: str = "blocked-force", session: str | None = None,
               delimiter: str | None = None) -> Trace:
    """Read and check a trace CSV: `time_s` on every row, strictly increasing within a block; the drive voltage
    (driven protocols) or the stage position (static), and a force or a displacement."""
    required = ("time_s", "stage_position_m") if protocol == "static" else ("time_s", "voltage_V")
    table = read_table(Path(path), required, delimiter)
    path = table.path
    if not (table.has("force_N") or table.has("displacement_m")):
        raise ConfigError(f"{path}:{table.rows[0][0] - 1}: header lacks column(s) force_N or displacement_m "
                          "(nothing measured)")
    t = table.column("time_s", blank_ok=False)
    columns = {name: table.column(name) for name in TRACE_COLUMNS[1:]}
    if np.all(np.isnan(columns["force_N"])) and np.all(np.isnan(columns["displacement_m"])):
        raise ConfigError(f"{path}: columns force_N and displacement_m are blank on every row (nothing measured)")
    blocks = _blocks(table, session)
    dts = np.diff(t)
    dt = float(np.median(dts[dts > 0])) if np.any(dts > 0) else 1e-3
    offsets, shifted, last = [], t.copy(), -math.inf
    for b in blocks:
        seg = t[b.start:b.stop]
        bad = np.flatnonzero(np.diff(seg) <= 0)
        if bad.size:
            line = table.rows[b.start + int(bad[0]) + 1][0]
            raise ConfigError(f"{path}:{line}: column time_s: {float(seg[bad[0] + 1])!r} does not increase "
                              f"(previous {float(seg[bad[0]])!r})")
        gap = max(BLOCK_GAP_S, 100.0 * dt)
        offset = 0.0 if seg[0] >= last + gap else last + gap - seg[0]
        offsets.append(offset)
        shifted[b.start:b.stop] = seg + offset
        last = float(shifted[b.stop - 1])
    return Trace(table, shifted, columns, blocks, offsets)


def _hold(x: np.ndarray) -> np.ndarray:
    """Blank cells of a slowly read channel take the last value read (sample-and-hold)."""
    out = x.copy()
    valid = np.isfinite(out)
    if not valid.any():
        return out
    idx = np.where(valid, np.arange(out.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = out[idx]
    first = int(np.argmax(valid))
    out[:first] = out[first]
    return out


@dataclass
class FoundStep:
    """A step found in a trace: its time span and what identifies it."""

    start_s: float
    end_s: float
    level_V: float
    stage_m: float
    mode: str
    cycles: list[Cycle]
    block: int
    first_row: int
    last_row: int


def _steps_driven(trace: Trace, protocol: str, cycles: list[Cycle], level_noise_V: float) -> list[FoundStep]:
    """Consecutive complete cycles of one block with the same level (within 2 %), stage position and mode."""
    t = trace.time_s
    stage = trace.columns["stage_position_m"]
    force, disp = trace.columns["force_N"], trace.columns["displacement_m"]
    steps: list[FoundStep] = []
    for k, b in enumerate(trace.blocks):
        t0, t1 = t[b.start], t[b.stop - 1]
        held = _hold(stage[b.start:b.stop])
        mine = [c for c in cycles if c.complete and t0 <= c.rise_start_s <= t1]
        block_steps: list[FoundStep] = []
        for c in mine:
            i0 = b.start + int(np.searchsorted(t[b.start:b.stop], c.low_start_s, "left"))
            i1 = b.start + int(np.searchsorted(t[b.start:b.stop], c.fall_end_s, "right"))
            span = held[i0 - b.start:i1 - b.start]
            pos = float(np.median(span)) if span.size and np.isfinite(span).any() else math.nan
            has_force = bool(np.isfinite(force[i0:i1]).any())
            has_disp = bool(np.isfinite(disp[i0:i1]).any())
            mode = ("free" if has_disp and not has_force else "blocked") if protocol == "actuator" else ""
            if block_steps:
                s = block_steps[-1]
                same_level = abs(c.level_V - s.level_V) <= max(SAME_LEVEL_FRACTION * s.level_V,
                                                                6.0 * level_noise_V)
                same_stage = not (math.isfinite(pos) and math.isfinite(s.stage_m)) \
                    or abs(pos - s.stage_m) <= STAGE_TOLERANCE_M
                if same_level and same_stage and mode == s.mode:
                    s.cycles.append(c)
                    s.last_row = i1 - 1
                    continue
            block_steps.append(FoundStep(0.0, 0.0, c.level_V, pos, mode, [c], k, i0, i1 - 1))
        for n, s in enumerate(block_steps):
            s.level_V = float(np.median([c.level_V for c in s.cycles]))
            s.start_s = float(t0) if n == 0 else 0.5 * (block_steps[n - 1].cycles[-1].fall_end_s
                                                          + s.cycles[0].rise_start_s)
            s.end_s = float(t1) if n + 1 == len(block_steps) else 0.5 * (s.cycles[-1].fall_end_s
                                                                         + block_steps[n + 1].cycles[0].rise_start_s)
        steps += block_steps
    return steps


def _steps_static(trace: Trace) -> list[FoundStep]:
    """Each stage plateau of at least MIN_STATIC_PLATEAU_S, per block."""
    t = trace.time_s
    out = []
    for k, b in enumerate(trace.blocks):
        stage = np.nan_to_num(_hold(trace.columns["stage_position_m"][b.start:b.stop]), nan=0.0)
        tb = t[b.start:b.stop]
        a = 0
        for i in range(1, tb.size + 1):
            if i == tb.size or abs(stage[i] - stage[a]) > STAGE_TOLERANCE_M:
                if tb[i - 1] - tb[a] >= MIN_STATIC_PLATEAU_S:
                    out.append(FoundStep(float(tb[a]), float(tb[i - 1]), 0.0, float(np.median(stage[a:i])), "",
                                         [], k, b.start + a, b.start + i - 1))
                a = i
    return out


def import_trace(csv_path: Path, out_path: Path, protocol: str, design: int | None = None, layers: int = 2,
                 zero_sag_m: float | None = None, overwrite: bool = False, toward_leg_sign: float = 1.0,
                 session: str | None = None, delimiter: str | None = None) -> int:
    """Write one time series as a recording of `protocol`; returns the number of steps found.

    Sag = (stage position - zero) x toward_leg_sign; the zero is `zero_sag_m`, else each block's first step's
    stage position (the paper's protocols start at zero sag). The actuator protocol's mode is taken from the data:
    a step with a displacement reading and no force is 'free', otherwise 'blocked'."""
    from hamr_bench.recording import Recorder

    if protocol not in PROTOCOLS:
        raise ConfigError(f"--protocol {protocol!r}: expected one of {', '.join(PROTOCOLS)}")
    if protocol != "actuator" and design is None:
        raise ConfigError(f"--design is required for the leg protocol {protocol}")
    csv_path, out_path = Path(csv_path), Path(out_path)
    trace = read_trace(csv_path, protocol, session, delimiter)
    t = trace.time_s
    if protocol == "static":
        found = _steps_static(trace)
        stats = None
    else:
        # the samples the recording will hold (blank cells are not samples): the readers infer from the same
        v = trace.columns["voltage_V"]
        ok = np.isfinite(v)
        stats = waveform_stats(v[ok]) if ok.sum() >= 3 else None
        below = stats.ground_V - float(np.percentile(v[ok], 0.1)) if stats is not None else 0.0
        if stats is not None and below > max(2.0 * stats.range_V, 10.0 * stats.noise_V):
            raise ConfigError(f"{csv_path}: column voltage_V: the drive swings below ground more than above it "
                              "(expected ground -> V_bias trapezoids; a monitor of inverted sign?)")
        cycles = infer_cycles(t[ok], v[ok], stats=stats) if stats is not None else []
        level_noise = stats.noise_V if stats is not None else 0.0
        found = _steps_driven(trace, protocol, cycles, level_noise)
    if not found:
        raise ConfigError(f"{csv_path}: no {'stage plateaus' if protocol == 'static' else 'complete drive cycles'} "
                          f"found (column {'stage_position_m' if protocol == 'static' else 'voltage_V'})")
    zeros = {}
    for k in range(len(trace.blocks)):
        first = next((s.stage_m for s in found if s.block == k and math.isfinite(s.stage_m)), math.nan)
        zeros[k] = zero_sag_m if zero_sag_m is not None else (first if math.isfinite(first) else 0.0)
    extra = {"zero_sag_m": repr(zeros[0]), "toward_leg_sign": repr(float(toward_leg_sign))} \
        if len(trace.blocks) == 1 else {"toward_leg_sign": repr(float(toward_leg_sign))}
    meta = _metadata(protocol, design if protocol != "actuator" else None, layers, "import-trace", csv_path,
                     trace.table, session, {"hold_s": None} if protocol == "static" else {}, extra)
    rec = Recorder(out_path, overwrite=overwrite, start_time_ns=0)
    try:
        meta.write(rec)
        _write_trace(rec, trace, found, zeros, protocol, toward_leg_sign, csv_path.name)
    except BaseException:
        rec.close("failed", "import failed")
        raise
    rec.close("success", "")
    return len(found)


def _write_trace(rec: Any, trace: Trace, found: list[FoundStep], zeros: dict[int, float], protocol: str,
                 toward_leg_sign: float, csv_name: str) -> None:
    t = trace.time_s
    cols = trace.columns
    rec.write_event(float(t[0]), EventKind.RUN_START, 0, f"imported from {csv_name}")
    for k, b in enumerate(trace.blocks):
        _specimen_event(rec, float(t[b.start]), b, csv_name, time_offset_s=trace.offsets_s[k],
                        zero_sag_m=zeros[k], toward_leg_sign=float(toward_leg_sign))
    for name, topic, field_name in (("voltage_V", Topic.DRIVE_MONITOR, "voltage_V"),
                                    ("stage_position_m", Topic.STAGE_POSITION, "position_m"),
                                    ("force_N", Topic.FORCE, "force_N")):
        ok = np.isfinite(cols[name])
        for ti, xi in zip(t[ok], cols[name][ok], strict=True):
            rec.write_scalar(topic, float(ti), **{field_name: float(xi)})
    ok = np.isfinite(cols["displacement_m"])
    for ti, xi in zip(t[ok], cols["displacement_m"][ok], strict=True):
        rec.write_scalar(Topic.CAMERA_DISPLACEMENT, float(ti), displacement_m=float(xi), x_px=math.nan,
                         y_px=math.nan)
    seen: list[tuple[int, str, float, float]] = []
    prev: tuple[int, float] | None = None
    for n, s in enumerate(found):
        block = trace.blocks[s.block]
        sag = (s.stage_m - zeros[s.block]) * toward_leg_sign if math.isfinite(s.stage_m) else 0.0
        cond: dict[str, Any] = {"voltage_V": round(s.level_V, 6), "sag_m": sag, "specimen": block.specimen,
                                "session": block.session}
        if protocol == "actuator":
            cond["mode"] = s.mode
        # a repetition of an earlier step of the block: same mode, level within 2 %, stage within 1 um
        cond["repetition"] = sum(1 for b_i, m, lv, sg in seen if b_i == s.block and m == s.mode
                                 and abs(lv - s.level_V) <= SAME_LEVEL_FRACTION * max(lv, 1e-9)
                                 and abs(sg - sag) <= STAGE_TOLERANCE_M)
        seen.append((s.block, s.mode, s.level_V, sag))
        cond["direction"] = "down" if prev is not None and prev[0] == s.block and s.level_V < prev[1] * (
            1 - SAME_LEVEL_FRACTION) else "up"
        prev = (s.block, s.level_V)
        lines = f"lines {trace.table.rows[s.first_row][0]}-{trace.table.rows[s.last_row][0]}"
        rec.write_event(s.start_s, EventKind.STEP, n, f"{csv_name} {lines}", **cond)
        if protocol != "static" and s.cycles:
            # the drive spans the step (to the next step's start), as replay plays it: the next step's
            # operations then follow the drive's end, as the rows show them
            t_a, t_b = max(s.cycles[0].low_start_s, s.start_s), s.end_s
            i0, i1 = int(np.searchsorted(t, t_a, "left")), int(np.searchsorted(t, t_b, "right"))
            rate = (i1 - i0 - 1) / (t[i1 - 1] - t[i0]) if i1 - i0 > 1 and t[i1 - 1] > t[i0] else 0.0
            timing = _summary(s.cycles)
            rec.write_event(t_a, EventKind.DRIVE_START, n, "drive timing inferred from voltage_V",
                            sample_rate_Hz=rate, n_samples=int(i1 - i0), peak_V=round(s.level_V, 6),
                            track=protocol == "free-displacement" or s.mode == "free", timing="inferred", **timing)
            rec.write_event(t_b, EventKind.DRIVE_END, n, "")
    rec.write_event(float(t[-1]), EventKind.RUN_END, 0, "imported", exit_status="success")


def _summary(cycles: list[Cycle]) -> dict[str, float]:
    def med(name: str) -> float:
        return round(float(np.median([getattr(c, name) for c in cycles])), 6)

    return {"cycles": len(cycles), "dwell_low_s": med("dwell_low_s"), "ramp_up_s": med("ramp_up_s"),
            "dwell_high_s": med("dwell_high_s"), "ramp_down_s": med("ramp_down_s")}

