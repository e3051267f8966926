"""Recordings -> phase-resolved observations for the gap diagnosis.

The fit's dataset (`analysis.dataset`) keeps one number per step (the high-plateau mean). The gap diagnosis needs
more: hysteresis shows as rise vs fall, creep as early vs late in a dwell, drift in the low dwell where the foot is
lifted. So each driven step is cut, per trapezoid cycle, into windows named by `hamr_bench.protocols.drive.
phase_labels`' phases:

    low_late   last half of the low dwell          rise   second half of the up ramp
    high_early first 30 % of the high dwell        high_late last half of the high dwell
    fall       first half of the down ramp

and an undriven step (the leg's static test, the actuator's stiffness sweep) into one `hold` window. A row is
the mean of the sensor over its window, averaged over the step's cycles; its standard error comes from the
cycle-to-cycle scatter pooled over the run's steps of that phase (pure error). Camera rows are relative to the same cycle's low_late window (the camera has no absolute zero).

For the model, each row carries `eval_times_s` (a few points in each of its windows; the prediction is their mean)
and the run carries the command timelines (bias, drive, stage targets), the contact and tare times, so any
candidate effect, including memory and stage effects, can be evaluated on exactly what the rig was told to do.
"""

from __future__ import annotations

import json
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from hamr_bench.errors import ConfigError, RecordingError

PHASES = ("low_late", "rise", "high_early", "high_late", "fall")


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


@dataclass
class GapData:
    runs: list[RunTrace]
    rows: list[Row]

    def arrays(self) -> dict[str, np.ndarray]:
        keys = ("run", "protocol", "quantity", "mode", "voltage_V", "sag_m", "repetition", "direction", "phase",
                "value", "se", "n")
        return {k: np.array([getattr(r, k) for r in self.rows]) for k in keys}


def _sorted_stream(reader: Any, topic: str, name: str) -> tuple[np.ndarray, np.ndarray]:
    topics = reader.topics()
    if topic not in topics or not topics[topic].message_count:
        return np.empty(0), np.empty(0)
    s = reader.scalars(topic)
    order = np.argsort(s["time_s"], kind="stable")
    return np.asarray(s["time_s"])[order], np.asarray(s[name], float)[order]


def _samples_in(t: np.ndarray, a: float, b: float) -> np.ndarray:
    """The sensor's own sample times inside [a, b]: the model is evaluated exactly where the sensor was read."""
    return t[np.searchsorted(t, a, "left"):np.searchsorted(t, b, "right")]


def _mean_in(t: np.ndarray, y: np.ndarray, a: float, b: float) -> float:
    i0, i1 = np.searchsorted(t, a, "left"), np.searchsorted(t, b, "right")
    return float(np.mean(y[i0:i1])) if i1 > i0 else math.nan


def _windows(dl: float, r: float, dh: float) -> dict[str, tuple[float, float]]:
    """Window bounds relative to a cycle's start (the cycle begins with its low dwell)."""
    hs = dl + r
    fs = hs + dh
    return {"low_late": (0.5 * dl, dl), "rise": (dl + 0.5 * r, dl + r), "high_early": (hs, hs + 0.3 * dh),
            "high_late": (hs + 0.5 * dh, fs), "fall": (fs, fs + 0.5 * r)}


def load_run(path: Path | str, index: int) -> RunTrace:
    from hamr_bench.recording import RecordingReader, RecordingWarning

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)
        reader = RecordingReader(path)
    meta = reader.metadata()
    proto_md, design_md = meta.get("protocol", {}), meta.get("design", {})
    protocol = proto_md.get("name", "")
    if not protocol:
        raise RecordingError(f"{path}: metadata 'protocol' has no 'name' (not a hamr-bench run recording?)")
    try:
        params = json.loads(proto_md.get("params") or "{}")
        model_params = json.loads(design_md.get("model_params") or "{}")
    except ValueError:
        raise RecordingError(f"{path}: metadata protocol.params or design.model_params is not JSON") from None
    fixture = design_md.get("fixture") or ("actuator" if protocol == "actuator" else "leg")
    design_text = design_md.get("design", "")
    design = int(design_text) if design_text.strip().isdigit() else None
    layers = int(design_md.get("layers", "2") or 2)
    events = sorted(reader.events(), key=lambda e: e.time_s)
    contact = [e.time_s for e in events if e.kind == "contact_found"]
    tare = [e.time_s for e in events if e.kind == "tare"]
    tf, force = _sorted_stream(reader, "/force", "force_N")
    tc, disp = _sorted_stream(reader, "/camera/displacement", "displacement_m")
    run = RunTrace(
        index=index, path=str(path), protocol=protocol, fixture=fixture, design=design, layers=layers,
        params_set=design_md.get("params_set", "effective") or "effective", model_params=model_params,
        bias_cmd=_sorted_stream(reader, "/amplifier/bias/command", "voltage_V"),
        drive_cmd=_sorted_stream(reader, "/amplifier/drive/command", "voltage_V"),
        stage_cmd=_sorted_stream(reader, "/stage/command", "target_m"),
        t_contact_s=contact[0] if contact else None, t_tare_s=tare[0] if tare else 0.0,
        t_end_s=float(events[-1].time_s) if events else 0.0)
    drive = params.get("drive", {}) or {}
    dl, r, dh = (float(drive.get(k, d)) for k, d in (("dwell_low_s", 0.4), ("ramp_s", 0.05), ("dwell_high_s", 0.4)))
    period = dl + 2 * r + dh
    rel = _windows(dl, r, dh)
    hold_s = params.get("hold_s")
    stiff_hold_s = (params.get("stiffness") or {}).get("hold_s")
    steps = [i for i, e in enumerate(events) if e.kind == "step"]
    for n, i in enumerate(steps):
        ev = events[i]
        t_next = events[steps[n + 1]].time_s if n + 1 < len(steps) else math.inf
        inside = [e for e in events[i + 1:] if e.time_s <= t_next and e.kind != "step"]
        cond = ev.data
        mode = str(cond.get("mode", ""))
        base = dict(run=index, protocol=protocol, mode=mode, voltage_V=float(cond.get("voltage_V", 0.0) or 0.0),
                    sag_m=float(cond.get("sag_m", 0.0) or 0.0), repetition=int(cond.get("repetition", 0) or 0),
                    direction=str(cond.get("direction", "up")), step=int(ev.step if hasattr(ev, "step") else n))
        starts = [e for e in inside if e.kind == "drive_start"]
        if starts:
            st = starts[0]
            n_samples = int(st.data.get("n_samples", 0) or 0)
            rate = float(st.data.get("sample_rate_Hz", 1000.0) or 1000.0)
            td = run.drive_cmd[0]
            j = np.searchsorted(td, st.time_s - 0.5, "left")
            seg = td[j:np.searchsorted(td, st.time_s + n_samples / rate + 1.0, "right")]
            # the waveform's first sample: the first command at or after drive_start minus a small tolerance
            k = np.searchsorted(seg, st.time_s - 1e-3, "left")
            if k >= seg.size:
                continue
            t0 = float(seg[k])
            n_cycles = max(1, int(round((n_samples - 1) / rate / period))) if n_samples else int(drive.get("cycles", 1))
            tracked = bool(st.data.get("track", False)) or protocol == "free-displacement" or mode == "free"
            t_s, y_s, quantity = (tc, disp, "displacement_m") if tracked else (tf, force, "force_N")
            if t_s.size == 0:
                continue
            per_phase: dict[str, list[float]] = {p: [] for p in PHASES}
            pts: dict[str, list[np.ndarray]] = {p: [] for p in PHASES}
            for c in range(n_cycles):
                c0 = t0 + c * period
                ref = _mean_in(t_s, y_s, c0 + rel["low_late"][0], c0 + rel["low_late"][1]) if tracked else 0.0
                for p in PHASES:
                    a, b = rel[p]
                    per_phase[p].append(_mean_in(t_s, y_s, c0 + a, c0 + b) - ref)
                    pts[p].append(_samples_in(t_s, c0 + a, c0 + b))
            for p in PHASES:
                if tracked and p == "low_late":
                    continue
                vals = np.asarray(per_phase[p])
                vals = vals[np.isfinite(vals)]
                if vals.size == 0:
                    continue
                refs = None
                if tracked:
                    refs = [_samples_in(t_s, t0 + c * period + rel["low_late"][0], t0 + c * period + rel["low_late"][1])
                            for c in range(n_cycles)]
                keep = [c for c in range(n_cycles) if pts[p][c].size and (refs is None or refs[c].size)]
                if not keep:
                    continue
                row = Row(quantity=quantity, phase=p, value=float(vals.mean()), n=int(vals.size),
                          eval_times_s=np.concatenate([pts[p][c] for c in keep]),
                          eval_cycle=np.concatenate([np.full(pts[p][c].size, c) for c in keep]),
                          ref_times_s=None if refs is None else np.concatenate([refs[c] for c in keep]),
                          ref_cycle=None if refs is None else np.concatenate([np.full(refs[c].size, c) for c in keep]),
                          **base)
                row._cycle_values = vals  # type: ignore[attr-defined]
                run.rows.append(row)
        elif tf.size and (protocol == "static" or mode == "stiffness"):
            # undriven hold: the leg's static test, or the actuator's stiffness sweep (its own hold time)
            h_rec = stiff_hold_s if mode == "stiffness" else hold_s
            h = float(h_rec) if h_rec else 0.5
            a, b = ev.time_s, min(ev.time_s + h, t_next)
            i0, i1 = np.searchsorted(tf, a, "left"), np.searchsorted(tf, b, "right")
            if i1 - i0 < 2:
                continue
            seg = force[i0:i1]
            row = Row(quantity="force_N", phase="hold", value=float(seg.mean()), n=int(seg.size),
                      eval_times_s=tf[i0:i1], eval_cycle=np.zeros(i1 - i0, int), **base)
            # white-noise standard error of the hold mean; pooled below like the cycles
            row._cycle_values = seg  # type: ignore[attr-defined]
            run.rows.append(row)
    _pool_standard_errors(run)
    return run


def _pool_standard_errors(run: RunTrace) -> None:
    """Standard error per row from the pure error pooled over the run's rows of the same phase and quantity."""
    groups: dict[tuple[str, str], list[Row]] = {}
    for r in run.rows:
        groups.setdefault((r.quantity, r.phase), []).append(r)
    for rows in groups.values():
        ss = sum(float(np.sum((r._cycle_values - r._cycle_values.mean()) ** 2)) for r in rows)  # type: ignore
        dof = sum(r._cycle_values.size - 1 for r in rows)  # type: ignore[attr-defined]
        var = ss / dof if dof > 0 else math.nan
        for r in rows:
            r.se = math.sqrt(var / r.n) if np.isfinite(var) else math.nan


def _load_run_task(args: tuple[Path, int]) -> Any:
    return load_run(*args)


def load_gap_data(paths: Iterable[Path | str], jobs: int | None = 1, scheduler: Any = None) -> GapData:
    """Read recordings (files, or directories searched for *.mcap); `jobs` local processes or a Dask `scheduler`
    read them in parallel (analysis.parallel; jobs=1 reads in this process)."""
    files: list[Path] = []
    for p in paths:
        p = Path(p)
        files.extend(sorted(p.glob("*.mcap")) if p.is_dir() else [p])
    if not files:
        raise ConfigError("no recordings given (expected .mcap files or directories holding them)")
    if jobs == 1 and scheduler is None:
        runs = [load_run(f, i) for i, f in enumerate(files)]
    else:
        from analysis.parallel import parallel_map

        runs = parallel_map(_load_run_task, [(f, i) for i, f in enumerate(files)], jobs=jobs, scheduler=scheduler)
    rows = [r for run in runs for r in run.rows]
    if not rows:
        raise RecordingError(f"{files[0]}: no driven or static steps to compare with the model")
    return GapData(runs, rows)
