"""CSV -> recordings: measurements made elsewhere (another lab's table, a spreadsheet, a data logger's export) become
MCAP recordings with the same metadata and events as a run, so every later command treats them alike.
The two formats are specified in docs/log-format-import.md.

- points: one row per measurement (`protocol, design, layers, voltage_V, sag_m, repetition, force_N,
  displacement_m`, blank where not measured). Each row becomes a `step` event with its condition, followed by a
  `measurement` event carrying the measured value(s); the values are also written as single samples on /force and
  /camera/displacement (one second apart) so the file plots in Foxglove. There are no raw traces to reduce.
- trace: one time series (`time_s, voltage_V, stage_position_m, force_N, displacement_m`) of one protocol run.
  The drive voltage goes to /amplifier/drive/monitor, the rest to /stage/position, /force, /camera/displacement;
  the importer finds the steps (a change of drive peak or of stage position; static: each stage plateau) and
  writes `step`, `drive_start` and `drive_end` events, so the dataset reduces it exactly as a recorded run.

Every malformed row raises ConfigError naming the file, the line and the column.
"""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.errors import ConfigError

POINT_COLUMNS = ("protocol", "design", "layers", "voltage_V", "sag_m", "repetition", "force_N", "displacement_m")
TRACE_COLUMNS = ("time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m")
PROTOCOLS = ("actuator", "blocked-force", "sag-sweep", "free-displacement", "static")
STAGE_TOLERANCE_M = 1e-6      # two stage readings within this are the same set-point
MIN_STATIC_PLATEAU_S = 0.05


def _read(path: Path, required: tuple[str, ...]) -> tuple[list[str], list[tuple[int, list[str]]]]:
    try:
        fh = open(path, newline="", encoding="utf-8-sig")
    except OSError as exc:
        raise ConfigError(f"{path}: cannot open ({exc.strerror or exc})") from None
    with fh:
        rows = []
        reader = csv.reader(fh)
        header = None
        for row in reader:
            line = reader.line_num
            if not row or all(not c.strip() for c in row) or row[0].lstrip().startswith("#"):
                continue
            if header is None:
                header = [c.strip() for c in row]
                missing = [c for c in required if c not in header]
                if missing:
                    raise ConfigError(f"{path}:{line}: header lacks column(s) {', '.join(missing)} "
                                      f"(expected {', '.join(required)})")
                continue
            if len(row) > len(header):
                raise ConfigError(f"{path}:{line}: {len(row)} fields but the header has {len(header)}")
            rows.append((line, row + [""] * (len(header) - len(row))))
    if header is None:
        raise ConfigError(f"{path}: empty file (expected a header line with {', '.join(required)})")
    if not rows:
        raise ConfigError(f"{path}: no data rows after the header")
    return header, rows


def _number(path: Path, line: int, column: str, text: str, *, blank_ok: bool = True, integer: bool = False,
            lo: float | None = None) -> float | None:
    t = text.strip()
    if not t:
        if blank_ok:
            return None
        raise ConfigError(f"{path}:{line}: column {column}: value required, got a blank")
    try:
        v = float(t)
    except ValueError:
        raise ConfigError(f"{path}:{line}: column {column}: expected a number, got {t!r}") from None
    if not math.isfinite(v):
        raise ConfigError(f"{path}:{line}: column {column}: expected a finite number, got {t!r}")
    if integer and not v.is_integer():
        raise ConfigError(f"{path}:{line}: column {column}: expected an integer, got {t!r}")
    if lo is not None and v < lo:
        raise ConfigError(f"{path}:{line}: column {column}: expected >= {lo:g}, got {t!r}")
    return v


def _metadata(rec: Any, protocol: str, design: int | None, layers: int, source: str, csv_path: Path,
              params: dict | None = None) -> None:
    fixture = "actuator" if protocol == "actuator" else ("mixed" if protocol == "mixed" else "leg")
    rec.add_metadata("rig", {"name": "imported", "path": str(csv_path), "text": "", "kind": "imported"})
    rec.add_metadata("design", {"design": "" if design is None else str(design), "layers": str(layers),
                                "fixture": fixture, "params_set": "effective", "model_params": "{}"})
    rec.add_metadata("protocol", {"name": protocol, "params": json.dumps(params or {}), "protocol_file": ""})
    rec.add_metadata("run", {"seed": "", "clock": "imported", "effects": "{}", "source": source,
                             "imported_from": str(csv_path)})


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


def read_points(path: Path) -> list[PointRow]:
    path = Path(path)
    header, rows = _read(path, POINT_COLUMNS)
    col = {name: header.index(name) for name in header}
    out = []
    for line, row in rows:
        def cell(name: str) -> str:
            return row[col[name]] if name in col else ""

        protocol = cell("protocol").strip()
        if protocol not in PROTOCOLS:
            raise ConfigError(f"{path}:{line}: column protocol: expected one of {', '.join(PROTOCOLS)}, "
                              f"got {protocol!r}")
        design = _number(path, line, "design", cell("design"), blank_ok=protocol == "actuator", integer=True)
        if design is not None and design not in (1, 2, 3, 4, 5):
            raise ConfigError(f"{path}:{line}: column design: expected 1..5, got {cell('design').strip()!r}")
        layers = _number(path, line, "layers", cell("layers"), blank_ok=protocol != "actuator", integer=True)
        layers = 2 if layers is None else int(layers)
        if layers not in (1, 2, 3):
            raise ConfigError(f"{path}:{line}: column layers: expected 1, 2 or 3, got {cell('layers').strip()!r}")
        voltage = _number(path, line, "voltage_V", cell("voltage_V"), blank_ok=protocol == "static", lo=0.0)
        sag = _number(path, line, "sag_m", cell("sag_m"), lo=-0.01)
        rep = _number(path, line, "repetition", cell("repetition"), integer=True, lo=0)
        force = _number(path, line, "force_N", cell("force_N"))
        disp = _number(path, line, "displacement_m", cell("displacement_m"))
        if force is None and disp is None:
            raise ConfigError(f"{path}:{line}: column force_N: blank, and displacement_m is blank too "
                              "(nothing measured)")
        if protocol == "free-displacement" and disp is None:
            raise ConfigError(f"{path}:{line}: column displacement_m: free-displacement rows need a displacement")
        if protocol in ("blocked-force", "sag-sweep", "static") and force is None:
            raise ConfigError(f"{path}:{line}: column force_N: {protocol} rows need a force")
        out.append(PointRow(line, protocol, None if design is None else int(design), layers,
                            0.0 if voltage is None else voltage, 0.0 if sag is None else sag,
                            0 if rep is None else int(rep), force, disp))
    return out


def import_points(csv_path: Path, out_path: Path, overwrite: bool = False) -> int:
    """Write the points table as one recording; returns the number of steps written."""
    from hamr_bench.recording import Recorder

    csv_path, out_path = Path(csv_path), Path(out_path)
    rows = read_points(csv_path)
    protocols = sorted({r.protocol for r in rows})
    designs = sorted({r.design for r in rows if r.design is not None})
    layer_set = sorted({r.layers for r in rows})
    protocol = protocols[0] if len(protocols) == 1 else "mixed"
    design = designs[0] if len(designs) == 1 else None
    rec = Recorder(out_path, overwrite=overwrite, start_time_ns=0)
    step = 0
    try:
        _metadata(rec, protocol, design, layer_set[0] if len(layer_set) == 1 else 2, "import-points", csv_path)
        rec.write_event(0.0, "run_start", 0, f"imported from {csv_path.name}")
        for r in rows:
            modes = []
            if r.protocol == "actuator" and r.voltage_V == 0 and r.sag_m > 0:
                # undriven, pushed past contact: a stiffness-sweep row (its force; a camera reading is not used)
                if r.force_N is not None:
                    modes.append(("stiffness", r.force_N, None))
            elif r.protocol == "actuator":
                if r.force_N is not None:
                    modes.append(("blocked", r.force_N, None))
                if r.displacement_m is not None:
                    modes.append(("free", None, r.displacement_m))
            else:
                modes.append(("", r.force_N, r.displacement_m))
            for mode, f, d in modes:
                t = float(step + 1)
                cond: dict[str, Any] = {"protocol": r.protocol, "layers": r.layers, "voltage_V": r.voltage_V,
                                        "sag_m": r.sag_m, "repetition": r.repetition, "direction": "up",
                                        "source_line": r.line}
                if r.design is not None:
                    cond["design"] = r.design
                if mode:
                    cond["mode"] = mode
                rec.write_event(t, "step", step, f"{csv_path.name} line {r.line}", **cond)
                data = {}
                if f is not None:
                    data["force_N"] = f
                    rec.write_scalar("/force", t, force_N=f)
                if d is not None:
                    data["displacement_m"] = d
                    rec.write_scalar("/camera/displacement", t, displacement_m=d, x_px=math.nan, y_px=math.nan)
                rec.write_event(t, "measurement", step, "", **data)
                step += 1
        rec.write_event(float(step + 1), "run_end", 0, "imported", exit_status="success")
    except BaseException:
        rec.close("failed", "import failed")
        raise
    rec.close("success", "")
    return step


# ----------------------------------------------------------------------------------------------- trace
def read_trace(path: Path) -> dict[str, np.ndarray]:
    path = Path(path)
    header, rows = _read(path, TRACE_COLUMNS)
    col = {name: header.index(name) for name in TRACE_COLUMNS}
    data = {name: np.full(len(rows), np.nan) for name in TRACE_COLUMNS}
    last_t = -math.inf
    for i, (line, row) in enumerate(rows):
        for name in TRACE_COLUMNS:
            v = _number(path, line, name, row[col[name]], blank_ok=name != "time_s")
            data[name][i] = math.nan if v is None else v
        t = data["time_s"][i]
        if t <= last_t:
            raise ConfigError(f"{path}:{line}: column time_s: {t!r} does not increase (previous {last_t!r})")
        last_t = t
    if np.all(np.isnan(data["force_N"])) and np.all(np.isnan(data["displacement_m"])):
        raise ConfigError(f"{path}: columns force_N and displacement_m are blank on every row (nothing measured)")
    return data


def _hold(x: np.ndarray) -> np.ndarray:
    """Blank cells of a slowly read channel take the last value read (sample-and-hold)."""
    out = x.copy()
    valid = np.isfinite(out)
    if not valid.any():
        return out
    idx = np.where(valid, np.arange(out.size), 0)
    np.maximum.accumulate(idx, out=idx)
    out = out[idx]
    first = np.argmax(valid)
    out[:first] = out[first]
    return out


def _steps_driven(t: np.ndarray, v: np.ndarray, stage: np.ndarray) -> list[tuple[int, int, float, float]]:
    """(start, stop, peak_V, stage_m) per step: consecutive drive bursts with the same peak and stage position.

    A burst is a run of samples above 1 % of the file's peak voltage; the step's samples run from the ground
    plateau before its first burst to the ground plateau after its last."""
    vmax = np.nanmax(v) if np.isfinite(v).any() else 0.0
    if not vmax > 0:
        return []
    above = np.nan_to_num(v, nan=0.0) > 0.01 * vmax
    d = np.diff(np.r_[0, above.astype(np.int8), 0])
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    bursts = [(a, b, float(np.nanmax(v[a:b])), float(np.nanmedian(stage[a:b])) if np.isfinite(stage[a:b]).any()
               else math.nan) for a, b in zip(starts, stops)]
    steps: list[list] = []
    for a, b, peak, pos in bursts:
        both_known = bool(steps) and math.isfinite(pos) and math.isfinite(steps[-1][3])
        same = (bool(steps) and abs(steps[-1][2] - peak) <= 0.02 * peak
                and (not both_known or abs(steps[-1][3] - pos) <= STAGE_TOLERANCE_M))
        if same:
            steps[-1][1] = b
        else:
            steps.append([a, b, peak, pos])
    out = []
    for k, (a, b, peak, pos) in enumerate(steps):
        # extend to the low plateaus on both sides (halfway to the neighbouring steps)
        lo = 0 if k == 0 else (steps[k - 1][1] + a) // 2
        hi = t.size if k == len(steps) - 1 else (b + steps[k + 1][0]) // 2
        out.append((lo, hi, peak, pos))
    return out


def _steps_static(t: np.ndarray, stage: np.ndarray) -> list[tuple[int, int, float]]:
    """(start, stop, stage_m) per stage plateau at least MIN_STATIC_PLATEAU_S long."""
    out = []
    a = 0
    for i in range(1, t.size + 1):
        if i == t.size or abs(stage[i] - stage[a]) > STAGE_TOLERANCE_M:
            if t[i - 1] - t[a] >= MIN_STATIC_PLATEAU_S:
                out.append((a, i, float(np.median(stage[a:i]))))
            a = i
    return out


def import_trace(csv_path: Path, out_path: Path, protocol: str, design: int | None = None, layers: int = 2,
                 zero_sag_m: float | None = None, overwrite: bool = False, toward_leg_sign: float = 1.0) -> int:
    """Write one time series as a recording of `protocol`; returns the number of steps found.

    Sag = (stage position - zero_sag_m) x toward_leg_sign; zero_sag_m defaults to the stage position of the first
    step (the paper's protocols start at zero sag). The actuator protocol's mode is taken from the data: a step with
    a displacement reading and no force is 'free', otherwise 'blocked'."""
    from hamr_bench.recording import Recorder

    if protocol not in PROTOCOLS:
        raise ConfigError(f"--protocol {protocol!r}: expected one of {', '.join(PROTOCOLS)}")
    if protocol != "actuator" and design is None:
        raise ConfigError(f"--design is required for the leg protocol {protocol}")
    csv_path, out_path = Path(csv_path), Path(out_path)
    data = read_trace(csv_path)
    t = data["time_s"]
    v = _hold(data["voltage_V"])
    stage = _hold(data["stage_position_m"])
    if protocol == "static":
        found = [(a, b, 0.0, pos) for a, b, pos in _steps_static(t, np.nan_to_num(stage, nan=0.0))]
    else:
        found = _steps_driven(t, v, stage)
    if not found:
        raise ConfigError(f"{csv_path}: no {'stage plateaus' if protocol == 'static' else 'drive cycles'} found "
                          f"(column {'stage_position_m' if protocol == 'static' else 'voltage_V'})")
    zero = zero_sag_m if zero_sag_m is not None else (found[0][3] if math.isfinite(found[0][3]) else 0.0)
    rec = Recorder(out_path, overwrite=overwrite, start_time_ns=0)
    try:
        _metadata(rec, protocol, design if protocol != "actuator" else None, layers, "import-trace", csv_path,
                  {"hold_s": None} if protocol == "static" else {})
        rec.write_event(float(t[0]), "run_start", 0, f"imported from {csv_path.name}")
        for name, topic, field in (("voltage_V", "/amplifier/drive/monitor", "voltage_V"),
                                   ("stage_position_m", "/stage/position", "position_m"),
                                   ("force_N", "/force", "force_N")):
            ok = np.isfinite(data[name])
            for ti, xi in zip(t[ok], data[name][ok]):
                rec.write_scalar(topic, float(ti), **{field: float(xi)})
        ok = np.isfinite(data["displacement_m"])
        for ti, xi in zip(t[ok], data["displacement_m"][ok]):
            rec.write_scalar("/camera/displacement", float(ti), displacement_m=float(xi), x_px=math.nan, y_px=math.nan)
        counts: dict[tuple, int] = {}
        prev_v = None
        for k, (a, b, peak, pos) in enumerate(found):
            sag = (pos - zero) * toward_leg_sign if math.isfinite(pos) else 0.0
            has_disp = np.isfinite(data["displacement_m"][a:b]).any()
            has_force = np.isfinite(data["force_N"][a:b]).any()
            cond: dict[str, Any] = {"voltage_V": round(peak, 6), "sag_m": sag}
            if protocol == "actuator":
                cond["mode"] = "free" if has_disp and not has_force else "blocked"
            key = (cond.get("mode", ""), round(peak, 3), round(sag, 7))
            cond["repetition"] = counts.get(key, 0)
            counts[key] = cond["repetition"] + 1
            cond["direction"] = "down" if prev_v is not None and peak < prev_v - 1e-9 else "up"
            prev_v = peak
            rec.write_event(float(t[a]), "step", k, f"{csv_path.name} rows {a + 1}-{b}", **cond)
            if protocol != "static":
                n = b - a
                rate = (n - 1) / (t[b - 1] - t[a]) if n > 1 and t[b - 1] > t[a] else 0.0
                rec.write_event(float(t[a]), "drive_start", k, "", sample_rate_Hz=rate, n_samples=int(n),
                                peak_V=peak, track=protocol == "free-displacement" or cond.get("mode") == "free")
                rec.write_event(float(t[b - 1]), "drive_end", k, "")
        rec.write_event(float(t[-1]), "run_end", 0, "imported", exit_status="success")
    except BaseException:
        rec.close("failed", "import failed")
        raise
    rec.close("success", "")
    return len(found)
