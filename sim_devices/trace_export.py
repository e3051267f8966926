"""Simulated actuator runs written as another lab would hand them over: CSV files in the trace format of
docs/log-format.md ("Trace"), one file per test (blocked force / free displacement) x layer count x V_bias, with
several specimens per file (the `specimen` column), so a self-check can go through `hamr-bench import trace FILE
--protocol actuator --layers N` exactly as outside data does.

Each specimen is one run of the actuator protocol on a bench holding the scenario's effects and that specimen's
parameters. A file takes, for every specimen in turn, the windows of that run's steps of its test and voltage
(all repetitions, in time order), with the specimen's time from its own run start:

- `time_s`: the union of the drive command's samples and the sensor's samples in those windows;
- `voltage_V`: the commanded drive held at each row (a lab's logger records what its DAQ wrote);
- `stage_position_m`: the stage's reading where one was taken (blank cells hold the last value);
- `force_N` (blocked) or `displacement_m` (free): the sensor's reading where one was taken, blank elsewhere.

The undriven stiffness sweep has no trace form (the importer finds actuator steps from drive cycles) and is not
written.
"""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.recording import RecordingReader
from hamr_bench.recording.contract import EventKind, Topic
from sim_devices.scenarios import Scenario

TESTS = {"blocked": ("force_N", Topic.FORCE, "force_N"),
         "free": ("displacement_m", Topic.CAMERA_DISPLACEMENT, "displacement_m")}
COLUMNS = ("time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m", "specimen")


def record_specimens(scenario: Scenario, out_dir: Path, set_options: list[str] | None = None,
                     seed: int = 0) -> list[Path]:
    """One actuator-protocol recording per specimen of the scenario (run through the real drivers)."""
    from hamr_bench.protocols.session import RunRequest, run_protocol

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for k, specimen in enumerate(scenario.specimens):
        rig = scenario.rig_file(out_dir / f"rig-specimen{specimen.label}.toml", specimen=k)
        path = out_dir / f"actuator-specimen{specimen.label}.mcap"
        result = run_protocol(RunRequest(protocol="actuator", out=path, rig_path=rig, layers=specimen.layers,
                                         design=scenario.design, seed=seed * 1000 + k, overwrite=True,
                                         set_options=list(set_options or []), specimen=specimen.label))
        if not result.ok:
            raise RuntimeError(f"specimen {specimen.label}: the simulated run ended {result.exit_status} "
                               f"({result.reason})")
        paths.append(path)
    return paths


def _windows(reader: RecordingReader) -> list[tuple[dict[str, Any], float, float]]:
    events = reader.events()
    steps = [e for e in events if e.kind == EventKind.STEP]
    end = next((e.time_s for e in events if e.kind == EventKind.RUN_END), events[-1].time_s)
    return [(s.data, s.time_s, steps[i + 1].time_s if i + 1 < len(steps) else end) for i, s in enumerate(steps)]


def _held(times: np.ndarray, t_src: np.ndarray, v_src: np.ndarray) -> np.ndarray:
    """The value in force at each time (zero-order hold; nan before the first)."""
    idx = np.searchsorted(t_src, times, side="right") - 1
    return np.where(idx >= 0, v_src[np.maximum(idx, 0)], np.nan)


def specimen_rows(reader: RecordingReader, test: str, voltage_V: float, t_origin_s: float) -> list[list[Any]]:
    """The rows of one specimen's run for one test at one V_bias."""
    column, topic, field = TESTS[test]
    command = reader.scalars(Topic.DRIVE_COMMAND)
    sensor = reader.scalars(topic)
    stage = reader.scalars(Topic.STAGE_POSITION)
    rows: list[list[Any]] = []
    for condition, start, end in _windows(reader):
        if condition.get("mode") != test or abs(float(condition.get("voltage_V", -1.0)) - voltage_V) > 1e-6:
            continue
        sel_c = (command["time_s"] >= start) & (command["time_s"] < end)
        sel_s = (sensor["time_s"] >= start) & (sensor["time_s"] < end)
        times = np.union1d(command["time_s"][sel_c], sensor["time_s"][sel_s])
        volts = _held(times, command["time_s"], command["voltage_V"])
        reading = dict(zip(sensor["time_s"][sel_s].tolist(), sensor[field][sel_s].tolist(), strict=True))
        stage_at = dict(zip(stage["time_s"].tolist(), stage["position_m"].tolist(), strict=True))
        first_stage = _held(np.array([start]), stage["time_s"], stage["position_m"])[0]
        for i, t in enumerate(times.tolist()):
            position = stage_at.get(t, first_stage if i == 0 else None)
            value = reading.get(t)
            rows.append([t - t_origin_s, volts[i], position, value if column == "force_N" else None,
                         value if column == "displacement_m" else None])
    return rows


def export_actuator_traces(scenario: Scenario, out_dir: Path, recordings: list[Path] | None = None,
                           set_options: list[str] | None = None, seed: int = 0) -> list[Path]:
    """Write the CSV files (recording the specimens first unless their recordings are given, in specimen order),
    one per test x layer count x V_bias. Returns the files written, named `actuator-<test>-<layers>x-<V>V.csv`
    (`exported_layers` reads the layer count back)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = recordings or record_specimens(scenario, out_dir / "runs", set_options, seed)
    readers = [RecordingReader(p) for p in paths]
    voltages = sorted({float(c["voltage_V"]) for r in readers for c, _, _ in _windows(r)
                       if c.get("mode") in TESTS})
    written = []
    for test in TESTS:
        for layers in scenario.layer_counts:
            for v in voltages:
                target = out_dir / f"actuator-{test}-{layers}x-{v:g}V.csv"
                with target.open("w", newline="", encoding="utf-8") as fh:
                    writer = csv.writer(fh)
                    writer.writerow(COLUMNS)
                    count = 0
                    for specimen, reader in zip(scenario.specimens, readers, strict=True):
                        if specimen.layers != layers:
                            continue
                        origin = reader.events()[0].time_s
                        for row in specimen_rows(reader, test, v, origin):
                            writer.writerow([_cell(x) for x in row] + [specimen.label])
                            count += 1
                if count:
                    written.append(target)
                else:
                    target.unlink()
    return written


def exported_layers(path: Path) -> int:
    """The layer count of a file `export_actuator_traces` wrote (from its name)."""
    match = re.fullmatch(r"actuator-\w+-(\d+)x-.*", Path(path).stem)
    if match is None:
        raise ValueError(f"{path}: not a file export_actuator_traces writes")
    return int(match.group(1))


def _cell(value: Any) -> str:
    if value is None or (isinstance(value, float) and not np.isfinite(value)):
        return ""
    return repr(float(value))
