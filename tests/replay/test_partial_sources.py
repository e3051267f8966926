"""Sources that are not a complete run of this software: a run that ended on a device fault part-way, and a
time series imported from CSV (no command streams at all) both replay, with the source's steps and timeline."""

from __future__ import annotations

import csv

import numpy as np

from analysis.compare import compare_recordings
from analysis.importer import import_trace
from analysis.replay import read_replay_source, replay_recording
from hamr_bench.recording import RecordingReader
from tests.reliability.harness import IN_TRANSIT_S
from tests.replay.conftest import SOURCE_EFFECTS, record


def test_aborted_recording_replays_what_it_holds(source_run, tmp_path):
    # The force sensor drops out during the second step (timed from the same run without the fault, so the test
    # follows the model's geometry): the run fails there.
    second_step_s = [e.time_s for e in RecordingReader(source_run).events() if e.kind == "step"][1]
    fault_s = round(second_step_s + 0.55, 3)
    src = record(tmp_path / "aborted.mcap", faults=[f"force_sensor:disconnect@{fault_s}"])
    reader = RecordingReader(src)
    assert reader.exit_status == "failed"
    steps = [e for e in reader.events() if e.kind == "step"]
    assert 1 <= len(steps) < 4
    twin = tmp_path / "twin.mcap"
    result, source = replay_recording(src, twin)
    assert result.ok and source.exit_status == "failed"
    assert RecordingReader(twin).metadata()["replay"]["source_exit_status"] == "failed"
    twin_reader = RecordingReader(twin)
    assert [e.data for e in twin_reader.events() if e.kind == "step"] == [e.data for e in steps]
    # up to the fault the twin is the source (same seed and effects): compare every stream before it, less the
    # force lines still on their way when the link went (the source lost them with the port; the twin has them)
    cut_s = fault_s - IN_TRANSIT_S
    for topic in ("/force", "/stage/position", "/amplifier/drive/command", "/amplifier/bias/monitor"):
        a, b = reader.scalars(topic), twin_reader.scalars(topic)
        ka, kb = a["time_s"] < cut_s, b["time_s"] < cut_s
        np.testing.assert_allclose(b["time_s"][kb], a["time_s"][ka], atol=1e-9, err_msg=topic)
        for field in a:
            np.testing.assert_allclose(b[field][kb], a[field][ka], rtol=1e-12, atol=1e-9, err_msg=topic)


def write_trace_csv(src, path):
    """The source run as a lab's data logger would export it: one row per force sample, drive voltage and stage
    position as measured (held between their own samples)."""
    reader = RecordingReader(src)
    f, m, p = (reader.scalars(t) for t in ("/force", "/amplifier/drive/monitor", "/stage/position"))
    t = f["time_s"]
    volts = np.where(t >= m["time_s"][0], np.interp(t, m["time_s"], m["voltage_V"]), 0.0)
    held = p["position_m"][np.clip(np.searchsorted(p["time_s"], t, side="right") - 1, 0, None)]
    with open(path, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m"])
        for row in zip(t, volts, held, f["force_N"]):
            out.writerow([*(repr(float(x)) for x in row), ""])


def test_imported_trace_replays_on_its_timeline(source_run, tmp_path):
    csv_path = tmp_path / "trace.csv"
    write_trace_csv(source_run, csv_path)
    imported = tmp_path / "imported.mcap"
    import_trace(csv_path, imported, "blocked-force", design=4)
    source = read_replay_source(imported)
    assert source.kind == "imported"
    twin = tmp_path / "twin.mcap"
    result, _ = replay_recording(imported, twin, effects=SOURCE_EFFECTS)
    assert result.ok
    a, b = RecordingReader(imported), RecordingReader(twin)
    assert [e.data for e in b.events() if e.kind == "step"] == [e.data for e in a.events() if e.kind == "step"]
    comparison = compare_recordings(imported, twin)
    # The drive plays at its recorded times: the twin's drive monitor follows the imported voltage within noise.
    assert comparison["channels"]["drive_monitor_V"]["steps_compared"] >= 2
    assert not comparison["channels"]["drive_monitor_V"]["exceeds_noise"]
    # The stage ends where the trace's did, and the blocked force of the last step is the source's within 15 %
    # (the same model; timing within a poll interval at the drive's edges is all that differs).
    pos_a, pos_b = a.scalars("/stage/position")["position_m"], b.scalars("/stage/position")["position_m"]
    assert abs(pos_b[-1] - pos_a[-1]) < 2e-6
    last = [s for s in comparison["steps"] if s["index"] >= 0][-1]
    start = [e.time_s for e in a.events() if e.kind == "step"][-1]
    fa, fb = a.scalars("/force"), b.scalars("/force")
    peak_a = fa["force_N"][fa["time_s"] >= start].max()
    peak_b = fb["force_N"][fb["time_s"] >= start].max()
    assert last["channels"]["force_N"]["n"] > 10
    assert abs(peak_b - peak_a) < 0.15 * peak_a
