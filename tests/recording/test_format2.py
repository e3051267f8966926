"""Format 2 as another reader sees it (the `mcap` package): log times never decrease in FILE order across all
channels, a message later than the reorder window is logged late and counted (its own time kept), units in the
channel metadata, every event also a `foxglove.Log` line, step conditions as typed fields."""

from __future__ import annotations

import math

import numpy as np
import pytest
from mcap.reader import make_reader

from hamr_bench.recording import Recorder, RecordingReader, schemas


def file_order(path):
    """(topic, log_time, schema name, payload) of every message, in the order they sit in the file."""
    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        return [(c.topic, m.log_time, s.name, bytes(m.data))
                for s, c, m in reader.iter_messages(log_time_order=False)]


def test_batches_delivered_late_still_land_in_log_time_order(tmp_path):
    """Producers as the runner's: the force stream drained in batches after the slower streams were sampled at
    "now", frames written after their exposure ended, a burst of drive samples ahead of time."""
    path = tmp_path / "r.mcap"
    rng = np.random.default_rng(0)
    with Recorder(path, start_time_ns=10**18) as rec:
        t = 0.0
        for _ in range(300):
            now = t + 0.02
            rec.write_scalar("/stage/position", now, position_m=1e-3)
            rec.write_scalar("/amplifier/drive/monitor", now, voltage_V=1.0)
            for k in range(20):  # the force batch of the pass: times up to now, arriving after "now" samples
                rec.write_scalar("/force", t + k * 1e-3, force_N=float(k))
            if rng.random() < 0.5:
                frame = rng.integers(0, 255, size=(48, 64), dtype=np.uint8)
                rec.write_image("/camera/image", now - 0.015, frame)
            t = now
        rec.write_event(t, "step", 1, "done", voltage_V=10.0)
    messages = file_order(path)
    times = [log for _, log, _, _ in messages]
    assert all(b >= a for a, b in zip(times, times[1:], strict=False))
    r = RecordingReader(path)
    assert r.metadata()["run_end"]["late_by_topic"] == "{}"
    assert r.metadata()["recording"]["format_version"] == "2"
    force = r.scalars("/force")
    np.testing.assert_array_equal(force["force_N"], np.tile(np.arange(20.0), 300))


def test_a_message_later_than_the_window_is_logged_late_counted_and_keeps_its_time(tmp_path):
    path = tmp_path / "late.mcap"
    with Recorder(path, reorder_window_s=0.5) as rec:
        for i in range(200):
            rec.write_scalar("/a", 5.0 + i * 0.01, x_m=float(i))  # up to 6.99 s
        rec.flush()  # everything so far is in the file
        rec.write_scalar("/b", 4.0, y_m=1.0)  # 3 s behind what the file holds
        rec.write_scalar("/b", 7.5, y_m=2.0)  # after everything: in order
    times = [log for _, log, _, _ in file_order(path)]
    assert all(b >= a for a, b in zip(times, times[1:], strict=False))
    r = RecordingReader(path)
    assert r.metadata()["run_end"]["late_by_topic"] == '{"/b": 1}'
    b = r.scalars("/b")
    np.testing.assert_array_equal(b["time_s"], [4.0, 7.5])  # its own time, in its field
    assert r.log_times_s("/b")[0] > 6.0  # logged where the file had got to


def test_units_are_in_the_channel_metadata(tmp_path):
    path = tmp_path / "u.mcap"
    with Recorder(path) as rec:
        rec.write_scalar("/force", 0.0, force_N=1.0)
        rec.write_scalar("/camera/displacement", 0.0, displacement_m=1e-6, x_px=1.0, y_px=2.0)
        rec.write_scalar("/custom/thing", 0.0, count=3.0, speed_m=0.1)
    with open(path, "rb") as f:
        channels = {c.topic: c.metadata for c in make_reader(f).get_summary().channels.values()}
    assert channels["/force"] == {"unit.time_s": "s", "unit.force_N": "N"}
    assert channels["/camera/displacement"] == {"unit.time_s": "s", "unit.displacement_m": "m", "unit.x_px": "px",
                                                "unit.y_px": "px"}
    assert channels["/custom/thing"] == {"unit.time_s": "s", "unit.speed_m": "m"}  # `count` names no unit


def test_events_become_log_lines_and_step_conditions_typed_fields(tmp_path):
    path = tmp_path / "e.mcap"
    with Recorder(path, start_time_ns=10**18) as rec:
        rec.write_event(0.5, "step", 3, "150 V, sag 0.1 mm", voltage_V=150.0, sag_m=1e-4, repetition=1,
                        direction="down", mode="blocked")
        rec.write_event(0.7, "drive_start", 3, "", peak_V=150.0)
        rec.write_event(0.9, "step", 4, "stiffness", sag_m=2e-4, mode="stiffness")
        rec.write_event(1.0, "run_end", 4, "interrupted", exit_status="aborted")
    logs = [(topic, log, payload) for topic, log, name, payload in file_order(path) if name == schemas.LOG_SCHEMA]
    cls = schemas.message_class(schemas.LOG_SCHEMA, schemas.log_descriptor_set())
    decoded = [cls.FromString(p) for _, _, p in logs]
    assert [t for t, _, _ in logs] == ["/log"] * 4
    assert decoded[0].message == "step 3 | step: 150 V, sag 0.1 mm | direction=down mode=blocked repetition=1 " \
                                 "sag_m=0.0001 voltage_V=150"
    assert decoded[0].timestamp.ToNanoseconds() == 10**18 + 500_000_000 and decoded[0].name == "hamr_bench"
    assert [d.level for d in decoded] == [2, 2, 2, 3]  # INFO, INFO, INFO, WARNING (an aborted run)
    steps = [schemas.message_class(schemas.STEP_SCHEMA, schemas.step_descriptor_set()).FromString(p)
             for topic, _, _, p in file_order(path) if topic == "/step"]
    assert [(s.step, s.voltage_V, s.sag_m, s.repetition, s.direction, s.mode) for s in steps[:1]] == [
        (3, 150.0, 1e-4, 1, "down", "blocked")]
    assert steps[1].step == 4 and math.isnan(steps[1].voltage_V) and steps[1].mode == "stiffness"
    assert [e.kind for e in RecordingReader(path).events()] == ["step", "drive_start", "step", "run_end"]


def test_the_reorder_stage_holds_a_window_and_clamps_what_comes_later():
    from hamr_bench.recording.reorder import ReorderStage

    out = []
    stage = ReorderStage(lambda i, t, p: out.append((i, t, p)), lambda: 3, window_ns=100, idle_release_s=1e6,
                         max_bytes=10**6)
    for t, i in [(1000, 0), (990, 1), (1050, 0), (1120, 0)]:
        stage.push(t, i, b"x")
        stage.release()
    assert out == [(1, 990, b"x"), (0, 1000, b"x")]  # 1050 and 1120 are within 100 ns of the newest: held
    stage.push(1010, 2, b"y")  # behind what already left (1000)? no: 1010 > 1000, still in time
    stage.push(995, 1, b"z")  # behind 1000, which has left: logged at 1000, counted
    stage.drain()
    assert out[2:] == [(1, 1000, b"z"), (2, 1010, b"y"), (0, 1050, b"x"), (0, 1120, b"x")]
    assert stage.late == [0, 1, 0]


@pytest.mark.parametrize("window_s", [-0.1, 1.5, float("nan")])
def test_a_reorder_window_outside_the_crash_bound_is_refused(tmp_path, window_s):
    from hamr_bench.errors import RecordingError

    with pytest.raises(RecordingError, match="reorder_window_s"):
        Recorder(tmp_path / "x.mcap", reorder_window_s=window_s)
