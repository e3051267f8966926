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

The force the contact search left on the sensor (`preload_N`: mean force over the last 0.1 s before
`contact_found`) is kept per run, because the observation model needs it (zero sag is where the force dropped
below the release threshold, not where it is exactly zero).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Sequence

import numpy as np

from hamr_bench.errors import ConfigError, HamrBenchError, RecordingError

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


@dataclass
class Run:
    info: RunInfo
    observations: list[Observation] = field(default_factory=list)

    def reader(self):
        from hamr_bench.recording import RecordingReader

        return RecordingReader(self.info.path)

    def trace(self, topic: str) -> dict[str, np.ndarray]:
        """Raw stream of one topic (`{'time_s': ..., field: ...}`); empty dict if the topic is absent."""
        reader = self.reader()
        if topic not in reader.topics():
            return {}
        return reader.scalars(topic)


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
                if isinstance(v, (tuple, list, set)):
                    ok = have in v
                else:
                    ok = have == v
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
def _json(value: str | None, where: str) -> Any:
    if not value:
        return {}
    try:
        return json.loads(value)
    except ValueError:
        raise RecordingError(f"{where} is not JSON") from None


def run_info(path: Path, reader: Any, preload_N: float = 0.0, preload_sd_N: float = 0.0) -> RunInfo:
    meta = reader.metadata()
    design_md = meta.get("design", {})
    protocol_md = meta.get("protocol", {})
    run_md = meta.get("run", {})
    protocol = protocol_md.get("name", "")
    if not protocol:
        raise RecordingError(f"{path}: metadata 'protocol' has no 'name' (not a hamr-bench run recording?)")
    fixture = design_md.get("fixture") or ("actuator" if protocol == "actuator" else "leg")
    design_text = design_md.get("design", "")
    try:
        design = int(design_text) if design_text not in ("", "mixed") else None
        layers = int(design_md.get("layers", "2") or 2)
    except ValueError:
        raise RecordingError(f"{path}: metadata design/layers are not integers ({design_text!r}, "
                             f"{design_md.get('layers')!r})") from None
    return RunInfo(
        path=str(path), protocol=protocol, fixture=fixture, design=design, layers=layers,
        params_set=design_md.get("params_set", "effective") or "effective",
        model_params=_json(design_md.get("model_params") or design_md.get("params"), f"{path}: design.model_params"),
        protocol_params=_json(protocol_md.get("params") or protocol_md.get("parameters"), f"{path}: protocol.params"),
        seed=run_md.get("seed", ""), effects=_json(run_md.get("effects"), f"{path}: run.effects"),
        exit_status=reader.exit_status, source=run_md.get("source", "recorded") or "recorded",
        preload_N=float(preload_N), preload_sd_N=float(preload_sd_N))


# ----------------------------------------------------------------------------------------------- traces -> cycles
def _segments(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index runs where mask is true."""
    if mask.size == 0:
        return []
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    starts = np.flatnonzero(d == 1)
    stops = np.flatnonzero(d == -1)
    return list(zip(starts.tolist(), stops.tolist()))


def plateau_windows(time_s: np.ndarray, volts: np.ndarray, settle_s: float | None
                    ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """Per trapezoid cycle, the averaging windows ((low_a, low_b), (high_a, high_b)) from the drive waveform.

    A plateau is a run of samples within 1 % of the peak (high) or of ground (low); a cycle is a low plateau
    followed by a high one (the drive starts with its low dwell). Each window is the plateau minus its first
    `settle_s` (or minus half of it when `settle_s` is None or longer than half the plateau)."""
    if time_s.size < 3:
        return []
    peak = float(np.max(volts))
    if not peak > 0:
        return []
    tol = 0.01 * peak
    high = _segments(volts >= peak - tol)
    low = _segments(np.abs(volts) <= tol)

    def window(seg: tuple[int, int]) -> tuple[float, float]:
        a, b = float(time_s[seg[0]]), float(time_s[seg[1] - 1])
        span = b - a
        s = DEFAULT_SETTLE_FRACTION * span if settle_s is None else min(settle_s, DEFAULT_SETTLE_FRACTION * span)
        return a + s, b

    cycles = []
    for h in high:
        before = [seg for seg in low if seg[1] <= h[0]]
        if not before:
            continue
        lo_seg = before[-1]
        if lo_seg[1] - lo_seg[0] < 2 or h[1] - h[0] < 2:
            continue
        if cycles and cycles[-1][0] == window(lo_seg):
            continue
        cycles.append((window(lo_seg), window(h)))
    return cycles


def _mean_in(t: np.ndarray, y: np.ndarray, a: float, b: float) -> float:
    i0, i1 = np.searchsorted(t, a, "left"), np.searchsorted(t, b, "right")
    if i1 <= i0:
        return math.nan
    return float(np.mean(y[i0:i1]))


def _sorted(stream: dict[str, np.ndarray], name: str) -> tuple[np.ndarray, np.ndarray]:
    if not stream:
        return np.empty(0), np.empty(0)
    t = stream["time_s"]
    order = np.argsort(t, kind="stable")
    return t[order], stream[name][order]


def _stats(values: Sequence[float]) -> tuple[float, float, int]:
    v = np.asarray([x for x in values if np.isfinite(x)], dtype=float)
    if v.size == 0:
        return math.nan, math.nan, 0
    return float(v.mean()), (float(v.std(ddof=1)) if v.size > 1 else math.nan), int(v.size)


def _cond_float(cond: dict, key: str, default: float) -> float:
    v = cond.get(key, default)
    try:
        return float(v)
    except (TypeError, ValueError):
        return default


# ----------------------------------------------------------------------------------------------- one recording
def load_run(path: Path | str, index: int = 0) -> Run:
    """Read one recording into a Run with its observations. Raises RecordingError naming the file."""
    import warnings

    from hamr_bench.recording import RecordingReader, RecordingWarning

    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such recording")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RecordingWarning)   # a partial file still yields its finished steps
        reader = RecordingReader(path)
    topics = reader.topics()

    def stream(topic: str) -> dict[str, np.ndarray]:
        return reader.scalars(topic) if topic in topics and topics[topic].message_count else {}

    events = sorted(reader.events(), key=lambda e: e.time_s)
    tf, force = _sorted(stream("/force"), "force_N")
    tc, disp = _sorted(stream("/camera/displacement"), "displacement_m")
    wave = stream("/amplifier/drive/command") or stream("/amplifier/drive/monitor")
    tw, volts = _sorted(wave, "voltage_V")

    preload, preload_sd = 0.0, 0.0
    contact = [e for e in events if e.kind == "contact_found"]
    if contact and tf.size:
        i0 = np.searchsorted(tf, contact[0].time_s - FORCE_WINDOW_S, "left")
        i1 = np.searchsorted(tf, contact[0].time_s + 1e-9, "right")
        if i1 > i0:
            window = force[i0:i1]
            preload = float(window.mean())
            preload_sd = float(window.std(ddof=1) / math.sqrt(window.size)) if window.size > 1 else 0.0
    info = run_info(path, reader, preload, preload_sd)
    run = Run(info)
    drive_p = info.protocol_params.get("drive", {}) if isinstance(info.protocol_params, dict) else {}
    settle_s = drive_p.get("settle_s")
    hold_s = info.protocol_params.get("hold_s") if isinstance(info.protocol_params, dict) else None
    stiffness_p = info.protocol_params.get("stiffness", {}) if isinstance(info.protocol_params, dict) else {}
    stiffness_hold_s = stiffness_p.get("hold_s") if isinstance(stiffness_p, dict) else None

    steps = [i for i, e in enumerate(events) if e.kind == "step"]
    end_time = events[-1].time_s + 1.0 if events else math.inf
    for n, i in enumerate(steps):
        ev = events[i]
        nxt = events[steps[n + 1]].time_s if n + 1 < len(steps) else end_time
        inside = events[i + 1: steps[n + 1]] if n + 1 < len(steps) else events[i + 1:]
        cond = dict(ev.data)
        protocol = str(cond.get("protocol", info.protocol))
        fixture = "actuator" if protocol == "actuator" else "leg"
        design = cond.get("design", info.design)
        design = int(design) if design not in (None, "") else None
        layers = int(cond.get("layers", info.layers))
        mode = str(cond.get("mode", ""))
        base = dict(run=index, protocol=protocol, fixture=fixture, design=design, layers=layers, mode=mode,
                    voltage_V=_cond_float(cond, "voltage_V", 0.0), sag_m=_cond_float(cond, "sag_m", 0.0),
                    repetition=int(_cond_float(cond, "repetition", 0)), direction=str(cond.get("direction", "up")),
                    step=int(ev.step), preload_N=preload)
        measured = [e for e in inside if e.kind == "measurement"]
        if measured:
            for q in ("force_N", "displacement_m"):
                v = measured[0].data.get(q)
                if v is not None and np.isfinite(float(v)):
                    run.observations.append(Observation(quantity=q, value=float(v), spread=math.nan, n_cycles=1,
                                                        **base))
            continue
        starts = [e for e in inside if e.kind == "drive_start"]
        ends = [e for e in inside if e.kind == "drive_end"]
        if starts:
            t_end = ends[0].time_s + 1e-6 if ends else nxt
            n_samples = int(starts[0].data.get("n_samples", 0) or 0)
            j0, j1 = np.searchsorted(tw, ev.time_s, "left"), np.searchsorted(tw, t_end, "right")
            seg_t, seg_v = tw[j0:j1], volts[j0:j1]
            if n_samples and seg_t.size > n_samples:   # keep the waveform itself, not the set_voltages sample
                seg_t, seg_v = seg_t[-n_samples:], seg_v[-n_samples:]
            cycles = plateau_windows(seg_t, seg_v, None if settle_s is None else float(settle_s))
            if not cycles:
                continue
            tracked = bool(starts[0].data.get("track", False)) or protocol == "free-displacement" or mode == "free"
            if tracked and tc.size:
                strokes = [_mean_in(tc, disp, *hi) - _mean_in(tc, disp, *lo) for lo, hi in cycles]
                mean, spread, k = _stats(strokes)
                if k:
                    run.observations.append(Observation(quantity="displacement_m", value=mean, spread=spread,
                                                        n_cycles=k, **base))
            if not tracked or mode == "blocked":
                if tf.size:
                    mean, spread, k = _stats([_mean_in(tf, force, *hi) for _lo, hi in cycles])
                    if k:
                        run.observations.append(Observation(quantity="force_N", value=mean, spread=spread,
                                                            n_cycles=k, **base))
        elif tf.size:
            # Undriven step (static leg, or the actuator's stiffness sweep): the force over the hold that follows
            # the step event.
            h = stiffness_hold_s if mode == "stiffness" else hold_s
            if h is not None:
                a, b = ev.time_s, min(ev.time_s + float(h), nxt)
            else:   # no hold time recorded (imported trace): the second half of the plateau, after settling
                end = min(nxt, float(tf[-1]))
                a, b = ev.time_s + DEFAULT_SETTLE_FRACTION * (end - ev.time_s), end
            i0, i1 = np.searchsorted(tf, a, "left"), np.searchsorted(tf, b, "right")
            if i1 > i0:
                seg = force[i0:i1]
                run.observations.append(Observation(
                    quantity="force_N", value=float(seg.mean()),
                    spread=float(seg.std(ddof=1)) if seg.size > 1 else math.nan, n_cycles=1, **base))
    # Stroke magnitude: the camera's sign convention is a rig setting, not physics.
    flipped = []
    for o in run.observations:
        if o.quantity == "displacement_m" and o.value < 0:
            o = Observation(**{**o.__dict__, "value": -o.value})
        flipped.append(o)
    run.observations = flipped
    return run


def load_dataset(paths: Iterable[Path | str], skip_failed: bool = False) -> Dataset:
    """Read recordings (files, or directories searched for *.mcap) into one Dataset."""
    files: list[Path] = []
    for p in paths:
        p = Path(p)
        if p.is_dir():
            files.extend(sorted(p.glob("*.mcap")))
        else:
            files.append(p)
    if not files:
        raise ConfigError("no recordings given (expected .mcap files or directories holding them)")
    runs: list[Run] = []
    for f in files:
        try:
            run = load_run(f, len(runs))
        except HamrBenchError:
            if skip_failed:
                continue
            raise
        runs.append(run)
    obs = [o for r in runs for o in r.observations]
    return Dataset(runs, obs)
