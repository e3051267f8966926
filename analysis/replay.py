"""A recording -> the plan that re-executes it (a replay), and a fit's JSON -> the model overrides of the twin.

Reads only the recording (docs/log-format.md), never the protocol's defaults, so a run with hand-edited
parameters, an aborted run or an imported trace replays as it was. Where each operation comes from:

- stage set-points: `/stage/command` {target_m}, each at its recorded time; in a recording with no command stream
  at all (an imported trace) the measured `/stage/position`, a new set-point wherever it moves by more than
  STAGE_TOLERANCE_M;
- bias/drive set-points: `set_voltages` events {bias_V, drive_V} (the ramp to a target);
- drive waveforms: the `/amplifier/drive/command` samples between `drive_start` {sample_rate_Hz, n_samples} and
  `drive_end` (without that stream: `/amplifier/drive/monitor`, resampled onto the event's rate), played from the
  first sample's recorded time; the samples the runner writes when it makes the rig safe are not commands;
- `home`, `tare`, `step` (with its condition, so the twin has the same steps) and `contact_found` events.

Timing: an operation the runner records before doing it (stage command, set_voltages, home) waits until its
recorded time; one it records only after some device traffic (tare; a step, after a stage check; a drive, whose
first sample time is known) is started TARE_LEAD_S / STEP_LEAD_S / DRIVE_LEAD_S before its recorded time, or as
soon as the previous operation ends if that is later.
A wait reads what the source read in the same gap (every stream at the source's dwell passes, which show in the
amplifier monitors recorded once per pass; the force stream alone where the source's force stream ran with no
monitors, the contact search; nothing during a device query); see hamr_bench/protocols/replay_plan.py for why.

A source without `home` / `tare` events (an imported trace) gets both at its start, and a step without
`set_voltages` events sets the bias to the step condition's `voltage_V` (the protocols drive 0 V -> bias).
"""

from __future__ import annotations

import hashlib
import json
import math
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.errors import ConfigError, RecordingError
from hamr_bench.protocols.plan import FindContact, Home, SetVoltages, Step, Tare
from hamr_bench.protocols.replay_plan import Note, ReplayDrive, StageCommand, WaitUntil
from hamr_bench.protocols.runner import FORCE_WINDOW_S
from hamr_bench.recording.contract import EventKind, Topic

STAGE_TOLERANCE_M = 1e-6
TARE_LEAD_S = 3.0       # longer than a tare takes (leg rig ~0.4 s: stream stop + drain + restart; Nano17 ~1 s)
DRIVE_LEAD_S = 0.01     # longer than an amplifier takes to arm a waveform after a set-point (<= 1 sample period)
STEP_LEAD_S = 0.05      # longer than the stage check the runner makes before it records a step (~10 ms)
MAX_RESAMPLED_RATE_HZ = 1000.0  # an imported trace's drive is resampled to at most this rate
DRIVE_REST_V = 0.5      # an imported drive below this is at rest (a monitor's noise is ~0.1 V)
CONTACT_STEP_S = 0.1    # more than a stage step takes on the rigs (allowance for an imported trace's search)
HOME_ALLOWANCE_S = 10.0  # more than homing takes from the actuator's contact (a few mm at the stage's speed)
MONITOR_TOPICS = (Topic.BIAS_MONITOR, Topic.DRIVE_MONITOR)
CAMERA_TOPICS = (Topic.CAMERA_DISPLACEMENT, Topic.CAMERA_IMAGE)


@dataclass
class ReplaySource:
    """What a recording says was done, as a replay plan, plus the facts the twin's metadata repeats."""

    path: Path
    kind: str                   # sim | real | imported
    protocol: str
    protocol_params_json: str
    design: int | None
    layers: int
    fixture: str
    seed: int | None
    effects: dict[str, float]
    exit_status: str
    exit_reason: str
    start_s: float
    end_s: float
    items: list[Any] = field(default_factory=list)
    steps: int = 0

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


def _int_or_none(text: str | None) -> int | None:
    try:
        return int(text) if text not in (None, "") else None
    except ValueError:
        return None


def _scalars(reader: Any, topic: str, field_name: str) -> tuple[np.ndarray, np.ndarray] | None:
    if topic not in reader.topics():
        return None
    data = reader.scalars(topic)
    if field_name not in data:
        raise RecordingError(f"{reader.path}: topic {topic} has no field {field_name}")
    return data["time_s"], data[field_name]


def _times(reader: Any, topics: tuple[str, ...]) -> np.ndarray:
    out = []
    for topic in topics:
        if topic in reader.topics():
            out.append(reader.log_times_s(topic) if topic.endswith("image") else reader.scalars(topic)["time_s"])
    return np.sort(np.concatenate(out)) if out else np.zeros(0)


def _any_between(times: np.ndarray, lo: float, hi: float) -> bool:
    i = np.searchsorted(times, lo, side="right")
    return bool(i < times.size and times[i] < hi)


def read_replay_source(path: Path | str) -> ReplaySource:
    """Read `path` and build its replay plan; raises RecordingError/ConfigError naming what is missing."""
    from hamr_bench.recording import RecordingReader

    path = Path(path)
    reader = RecordingReader(path)
    md = reader.metadata()
    proto = md.get("protocol", {})
    design_md = md.get("design", {})
    run_md = md.get("run", {})
    rig_md = md.get("rig", {})
    if not proto.get("name"):
        raise RecordingError(f"{path}: metadata protocol.name is missing (not a hamr-bench recording?)")
    try:
        effects = {k: float(v) for k, v in json.loads(run_md.get("effects") or "{}").items()}
    except (ValueError, AttributeError, TypeError):
        raise RecordingError(f"{path}: metadata run.effects={run_md.get('effects')!r} is not a JSON object") from None
    events = reader.events()
    topics = reader.topics()
    all_times = [t.first_time_s for t in topics.values() if t.first_time_s is not None]
    all_ends = [t.last_time_s for t in topics.values() if t.last_time_s is not None]
    start_s = min(all_times + [e.time_s for e in events]) if (all_times or events) else 0.0
    end_s = max(all_ends + [e.time_s for e in events]) if (all_ends or events) else 0.0
    run_end = [e for e in events if e.kind == EventKind.RUN_END]
    exit_status = reader.exit_status or (run_end[-1].data.get("exit_status") if run_end else None) or "unknown"
    source = ReplaySource(
        path=path, kind=rig_md.get("kind", "real") or "real", protocol=proto["name"],
        protocol_params_json=proto.get("params") or "{}", design=_int_or_none(design_md.get("design")),
        layers=_int_or_none(design_md.get("layers")) or 2, fixture=design_md.get("fixture") or "leg",
        seed=_int_or_none(run_md.get("seed")), effects=effects, exit_status=exit_status,
        exit_reason=reader.exit_reason or (run_end[-1].message if run_end else "") or "",
        start_s=start_s, end_s=end_s)
    source.items = _build_items(reader, events, source.fixture)
    source.steps = sum(1 for e in events if e.kind == EventKind.STEP)
    return source


def _contact_moves(reader: Any, events: list[Any], fixture: str) -> list[tuple[float, Any, float]]:
    """(time, operation, allowance_s): how the twin puts its sensor where an imported actuator trace's steps had
    it, when the trace has no stage positions: the lab's sensor touched the tip in blocked (and stiffness) steps and
    was clear of it in free ones. The twin finds contact with the actuator protocol's own search before the first
    touching step (and again after a free step), and homes (clear) before a free step after touching ones. Each is
    given an allowance (a worst-case duration: the steps after it are replayed that much later, so the search never
    makes the twin skip drive samples); `compare` aligns steps by their starts, so the shift does not matter there."""
    if fixture != "actuator" or any(t in reader.topics() for t in (Topic.STAGE_COMMAND, Topic.STAGE_POSITION)):
        return []
    from hamr_bench.protocols.actuator import Params

    c = Params().contact
    n_steps = c.max_travel_m / c.coarse_step_m + 2 * (c.clearance_m + 2 * c.coarse_step_m) / c.fine_step_m
    search_s = n_steps * (FORCE_WINDOW_S + CONTACT_STEP_S)
    search = FindContact(c.threshold_N, c.coarse_step_m, c.fine_step_m, c.max_travel_m, clearance_m=c.clearance_m)
    out: list[tuple[float, FindContact | Home, float]] = []
    touching = False
    for e in events:
        if e.kind != EventKind.STEP:
            continue
        mode = e.data.get("mode", "")
        if mode in ("blocked", "stiffness") and not touching:
            out.append((e.time_s - STEP_LEAD_S - DRIVE_LEAD_S, search, search_s))
            touching = True
        elif mode == "free" and touching:
            out.append((e.time_s - STEP_LEAD_S - DRIVE_LEAD_S, Home(), HOME_ALLOWANCE_S))
            touching = False
    return out


def _build_items(reader: Any, events: list[Any], fixture: str = "leg") -> list[Any]:
    timed: list[tuple[float, int, int, Any]] = []  # (anchor time, order key, sequence, item-with-wait)
    seq = 0

    def add(anchor_s: float, priority: int, kind: str, item: Any, lead_s: float = 0.0) -> None:
        nonlocal seq
        timed.append((anchor_s, priority, seq, (kind, item, anchor_s - lead_s)))
        seq += 1

    kinds = {e.kind for e in events}
    # --- events -> operations
    for e in events:
        if e.kind == EventKind.HOME:
            add(e.time_s, 0, "pre", Home())
        elif e.kind == EventKind.TARE:
            add(e.time_s, 0, "post", Tare(), TARE_LEAD_S)
        elif e.kind == EventKind.STEP:
            add(e.time_s, 0, "post", Step(int(e.step), e.message, dict(e.data)), STEP_LEAD_S)
        elif e.kind == EventKind.SET_VOLTAGES:
            add(e.time_s, 0, "pre", SetVoltages(float(e.data.get("bias_V", 0.0)), float(e.data.get("drive_V", 0.0))))
        elif e.kind == EventKind.CONTACT_FOUND:
            add(e.time_s, 0, "note", Note(e.kind, e.message, dict(e.data)))
    # --- stage set-points
    stage = _scalars(reader, Topic.STAGE_COMMAND, "target_m")
    commanded_anything = any(t in reader.topics() for t in (Topic.STAGE_COMMAND, Topic.BIAS_COMMAND,
                                                            Topic.DRIVE_COMMAND))
    if stage is None and not commanded_anything:  # a trace of measurements only (imported)
        measured = _scalars(reader, Topic.STAGE_POSITION, "position_m")
        if measured is not None:
            stage = _setpoints_from_positions(*measured)
    if stage is not None:
        for t, target in zip(*stage, strict=True):
            if math.isfinite(target):
                add(float(t), 1, "pre", StageCommand(float(target)))
    # --- drives
    for t0, rate, samples, track in _drives(reader, events):
        add(t0, 2, "post", ReplayDrive(tuple(samples), rate, t0, track), DRIVE_LEAD_S)
    # --- a source without set_voltages (imported trace): bias each step to its condition's voltage
    if EventKind.SET_VOLTAGES not in kinds:
        for e in events:
            if e.kind == EventKind.STEP and isinstance(e.data.get("voltage_V"), (int, float)):
                add(e.time_s, 0, "note_after", SetVoltages(float(e.data["voltage_V"]), 0.0))
    moves = _contact_moves(reader, events, fixture)
    for t, item, _allowance in moves:
        add(t, -1, "chain", item)
    timed.sort(key=lambda x: (x[0], x[1], x[2]))
    if EventKind.HOME not in kinds:  # an imported trace: reference the stage and zero the sensor first
        timed.insert(0, (-math.inf, -1, -2, ("chain", Home(), -math.inf)))
        if EventKind.TARE not in kinds:
            timed.insert(1, (-math.inf, -1, -1, ("chain", Tare(), -math.inf)))
    # The runner records the amplifier monitors once per pass of a dwell, so they show when its passes were;
    # its force averaging during the contact search shows as force samples with no dwell passes around.
    runner_made = any(t in reader.topics() for t in (Topic.STAGE_COMMAND, Topic.BIAS_COMMAND,
                                                     Topic.DRIVE_COMMAND))
    monitors = np.unique(_times(reader, MONITOR_TOPICS)) if runner_made else np.zeros(0)
    # A dwell pass records the stage position and the monitors at the same time; the force averaging's periodic
    # checks record monitors alone, so they do not mark a dwell.
    stage_times = _times(reader, (Topic.STAGE_POSITION,))
    monitors = monitors[np.isin(monitors, stage_times)]
    force = _times(reader, (Topic.FORCE,))
    camera = _times(reader, CAMERA_TOPICS)
    items: list[Any] = []
    previous_s = -math.inf

    def shift(t: float) -> float:
        """Source time -> twin time: later by the allowances of the contact moves before it."""
        return t + sum(allowance for at, _item, allowance in moves if at <= t)

    for anchor_s, _prio, _seq, (kind, item, wait_to) in timed:
        if isinstance(item, ReplayDrive) and moves:
            item = replace(item, start_s=shift(item.start_s))
        if kind in ("pre", "post") and math.isfinite(wait_to):
            lo = int(np.searchsorted(monitors, previous_s, side="left"))
            hi = int(np.searchsorted(monitors, anchor_s - 1e-12, side="left"))
            passes = tuple(float(x) for x in monitors[lo:hi])
            items.append(WaitUntil(
                shift(wait_to), pass_times_s=passes,
                poll_force=runner_made and not passes and _any_between(force, previous_s, anchor_s),
                after_query=bool(items) and isinstance(items[-1], Tare),
                dwell=not runner_made, track=_any_between(camera, previous_s, anchor_s)))
        items.append(item)
        if math.isfinite(anchor_s):
            previous_s = anchor_s
    return items


def _setpoints_from_positions(t: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out_t, out_x = [], []
    last = None
    for ti, xi in zip(t, x, strict=True):
        if not math.isfinite(xi):
            continue
        if last is None or abs(xi - last) > STAGE_TOLERANCE_M:
            out_t.append(ti)
            out_x.append(xi)
            last = xi
    return np.asarray(out_t), np.asarray(out_x)


def _drives(reader: Any, events: list[Any]) -> list[tuple[float, float, np.ndarray, bool]]:
    """(first sample time, rate, samples, track) per drive_start event."""
    starts = [i for i, e in enumerate(events) if e.kind == EventKind.DRIVE_START]
    if not starts:
        return []
    commanded = _scalars(reader, Topic.DRIVE_COMMAND, "voltage_V")
    end_of_file = max([e.time_s for e in events] + [math.inf])
    out = []
    if commanded is not None:
        t, v = commanded
        claimed = np.zeros(t.size, dtype=bool)
        # set_voltages writes one drive record at or after its event; making the rig safe writes the last one.
        for e in events:
            if e.kind == EventKind.SET_VOLTAGES:
                idx = np.flatnonzero((t >= e.time_s - 1e-12) & ~claimed)
                if idx.size:
                    claimed[idx[0]] = True
        if any(e.kind == EventKind.SAFE_STATE for e in events) and t.size:
            claimed[-1] = True
        for i in starts:
            e = events[i]
            rate = float(e.data.get("sample_rate_Hz", 0.0))
            n = int(e.data.get("n_samples", 0))
            if not rate > 0:
                raise RecordingError(f"{reader.path}: drive_start at {e.time_s:.3f} s has sample_rate_Hz={rate!r}")
            end = next((x.time_s for x in events[i + 1:]
                        if x.kind in (EventKind.DRIVE_END, EventKind.DRIVE_START)), end_of_file)
            window = np.flatnonzero(~claimed & (t >= e.time_s - 1.0) & (t <= end + 1e-9))
            # the waveform is the run of records on the grid t0 + k / rate that starts nearest before the event
            before = window[t[window] <= e.time_s + 1e-9]
            if before.size == 0:
                continue
            first = before[0]
            for j in before[::-1]:
                if j == before[0] or not _on_grid(t[j] - t[j - 1], rate) or claimed[j - 1]:
                    first = j
                    break
            candidates = window[window >= first]
            k = (t[candidates] - t[first]) * rate
            on_grid = np.abs(k - np.round(k)) < 1e-6
            candidates, k = candidates[on_grid], np.round(k[on_grid]).astype(np.int64)
            # consecutive sample numbers 0, 1, 2, ... (the waveform ends at the first gap or after n samples)
            breaks = np.flatnonzero(k != np.arange(k.size))
            chosen = candidates[:breaks[0] if breaks.size else k.size]
            if n > 0:
                chosen = chosen[:n]
            claimed[chosen] = True
            out.append((float(t[first]), rate, v[chosen], bool(e.data.get("track", False))))
        return out
    monitored = _scalars(reader, Topic.DRIVE_MONITOR, "voltage_V")
    if monitored is None:
        raise RecordingError(f"{reader.path}: drive_start events but neither {Topic.DRIVE_COMMAND} nor "
                             f"{Topic.DRIVE_MONITOR} to replay the waveform from")
    # The drive as the recording contract infers it from the monitor (each cycle's corners and level): the
    # waveform the monitor measured, without its noise and overshoot, which the twin's amplifier would otherwise
    # be told to reproduce. Where no cycle is found, the monitor itself.
    from hamr_bench.recording.steps import parse_run

    timelines = parse_run(reader).timelines
    if timelines.sources.get("drive") == "inferred" and timelines.drive[0].size:
        knots_t, knots_v = timelines.drive
        t = monitored[0]
        v = np.interp(t, knots_t, knots_v, left=0.0, right=0.0)
    else:
        t, v = monitored
    for i in starts:
        e = events[i]
        rate = float(e.data.get("sample_rate_Hz", 0.0))
        end = next((x.time_s for x in events[i + 1:]
                    if x.kind in (EventKind.DRIVE_END, EventKind.DRIVE_START)), end_of_file)
        sel = (t >= e.time_s - 1e-9) & (t <= end + 1e-9) & np.isfinite(v)
        if sel.sum() < 2 or not rate > 0:
            continue
        ts, vs = t[sel], v[sel]
        # An importer's step may span more than the drive (the contact search before it): play only from the
        # last sample at rest before the drive moves, so stage moves recorded meanwhile are not held up.
        moving = np.flatnonzero(np.abs(vs) > DRIVE_REST_V)
        if moving.size == 0:
            continue
        first = max(int(moving[0]) - 1, 0)
        ts, vs = ts[first:], vs[first:]
        if ts.size < 2:
            continue
        rate = min(rate, MAX_RESAMPLED_RATE_HZ)
        grid = ts[0] + np.arange(int(math.floor((ts[-1] - ts[0]) * rate + 1e-9)) + 1) / rate
        out.append((float(ts[0]), rate, np.clip(np.interp(grid, ts, vs), 0.0, None),
                    bool(e.data.get("track", False))))
    return out


def _on_grid(dt: float, rate: float) -> bool:
    return abs(dt * rate - 1.0) < 1e-6


# ---------------------------------------------------------------------------------------------- fit parameters
ACTUATOR_FIT_FIELDS = {"E_p": "pzt_modulus_Pa", "d31": "d31_m_per_V", "t_p": "pzt_thickness_m",
                       "length": "length_m", "width": "width_nom_m"}
DESIGN_FIT_FIELDS = {"k_ser": "k_ser_N_per_m", "bias": "bias_m"}


def _value(entry: Any, where: str) -> float:
    value: Any = entry.get("value") if isinstance(entry, dict) else entry
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected a number or {{\"value\": number}}, got {entry!r}") from None
    if not math.isfinite(number):
        raise ConfigError(f"{where}: value {number!r} is not finite")
    return number


def model_overrides_from_fit(fit_path: Path | str, design: int | None, layers: int,
                             fixture: str = "leg") -> dict[str, dict[str, Any]]:
    """The fit JSON (`hamr-bench fit --json`) -> {"actuator": {...}, "design": {...}} for the twin's bench: the
    actuator of `layers` layers and the design `design`, each only where the fit has them."""
    from hamr_bench.model import design_preset

    fit_path = Path(fit_path)
    try:
        doc = json.loads(fit_path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(f"--params {fit_path}: cannot read ({exc.strerror})") from None
    except ValueError as exc:
        raise ConfigError(f"--params {fit_path}: not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ConfigError(f"--params {fit_path}: expected an object with 'actuators' and/or 'designs'")
    out: dict[str, dict[str, Any]] = {}
    actuator = (doc.get("actuators") or {}).get(str(layers))
    if isinstance(actuator, dict):
        values = {field_name: _value(actuator[key], f"{fit_path}: actuators.{layers}.{key}")
                  for key, field_name in ACTUATOR_FIT_FIELDS.items() if key in actuator}
        if values:
            out["actuator"] = values
    group = (doc.get("designs") or {}).get(str(design)) if design is not None and fixture == "leg" else None
    if isinstance(group, dict) and design is not None:
        design_values: dict[str, Any] = {
            field_name: _value(group[key], f"{fit_path}: designs.{design}.{key}")
            for key, field_name in DESIGN_FIT_FIELDS.items() if key in group}
        kappas = [f"kappa_{i}" for i in (1, 2, 3)]
        if any(k in group for k in kappas):
            preset = design_preset(design).kappa_N_m_per_rad
            design_values["kappa_N_m_per_rad"] = [
                _value(group[k], f"{fit_path}: designs.{design}.{k}") if k in group else float(preset[i])
                for i, k in enumerate(kappas)]
        if design_values:
            out["design"] = design_values
    if not out:
        raise ConfigError(f"--params {fit_path}: has no actuators.{layers}"
                          + (f" or designs.{design}" if design is not None and fixture == "leg" else "")
                          + " entry for this recording")
    return out


# ---------------------------------------------------------------------------------------------- running a replay
def _sha256_of_file(path: Path) -> str:
    """Hex SHA-256 of `path`, streamed (a camera run is hundreds of MB, no need to hold it in memory)."""
    with open(path, "rb") as f:
        return hashlib.file_digest(f, "sha256").hexdigest()


def replay_recording(source_path: Path | str, out: Path | str, *, params_path: Path | str | None = None,
                     effects: dict[str, float] | None = None, seed: int | None = None,
                     rig_path: Path | str | None = None, overwrite: bool = False, quiet: bool = True,
                     record_traffic: bool = False, serve_traffic: bool = False, camera_storage: Any = None,
                     live: Any = None) -> tuple[Any, ReplaySource]:
    """Re-execute `source_path` on the simulated bench into `out`. Seed and effects default to the source's
    (a simulated source) or to 0 / none; model parameters are the bench's nominal ones unless `params_path` names
    a fit's JSON. `serve_traffic` serves the serial devices from the source's recorded traffic instead of the
    emulators (driver-change testing). `camera_storage` and `live` (a LiveView) as for a run
    (hamr_bench.protocols.session.RunRequest). Returns (RunResult, ReplaySource)."""
    from hamr_bench.protocols.replay_plan import ReplayRequest, run_replay

    # The digest is computed on a thread while the source is read: both stream the whole file (hundreds of MB for a
    # camera run) and hashlib and file reads release the GIL, so on two cores the hash costs no wall time.
    with ThreadPoolExecutor(max_workers=1) as pool:
        digest_future = pool.submit(_sha256_of_file, Path(source_path))
        source = read_replay_source(source_path)
        digest = digest_future.result()
    overrides = model_overrides_from_fit(params_path, source.design, source.layers, source.fixture) \
        if params_path else {}
    use_seed = seed if seed is not None else (source.seed if source.seed is not None else 0)
    use_effects = dict(effects) if effects is not None else (dict(source.effects) if source.kind == "sim" else {})
    replay_md = {
        "source": str(Path(source_path).resolve()), "source_sha256": digest, "source_kind": source.kind,
        "source_exit_status": source.exit_status, "source_reason": source.exit_reason,
        "source_duration_s": repr(source.duration_s),
        "model_params": "fit" if params_path else "nominal",
        "params_file": str(Path(params_path).resolve()) if params_path else "",
        "model_overrides": json.dumps(overrides), "seed": str(use_seed), "effects": json.dumps(use_effects),
        "operations": str(len(source.items)),
        "serial_devices": "recorded traffic" if serve_traffic else "emulators",
    }
    design = source.design if source.design is not None else 4
    result = run_replay(ReplayRequest(
        items=source.items, out=Path(out), protocol=source.protocol,
        protocol_params_json=source.protocol_params_json, design=design, layers=source.layers,
        fixture=source.fixture, seed=use_seed, effects=use_effects, replay_metadata=replay_md,
        model_overrides=overrides, rig_path=Path(rig_path) if rig_path else None, overwrite=overwrite,
        record_traffic=record_traffic, step_count=source.steps, quiet=quiet,
        traffic_from=Path(source_path) if serve_traffic else None, camera_storage=camera_storage, live=live))
    return result, source
