"""Every kind of message written by `Recorder` reads back (with CRC validation) through `RecordingReader` and, as an
independent check, through the reference `mcap` reader with the protobuf decoder built from the stored schemas."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory

from hamr_bench.errors import RecordingError
from hamr_bench.recording import Recorder, RecordingReader, schemas

START_NS = 1_700_000_000_123_456_789


def _frame(seed: int, dtype=np.uint8) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.integers(0, np.iinfo(dtype).max, size=(48, 64), dtype=dtype)


@pytest.fixture()
def full_recording(tmp_path):
    path = tmp_path / "run.mcap"
    force_t = np.arange(2000) / 10_000.0
    force = 0.05 * np.sin(2 * np.pi * 50 * force_t)
    frames = [_frame(k) for k in range(3)]
    jpeg_source = np.tile(np.linspace(0, 255, 64, dtype=np.uint8), (48, 1))
    with Recorder(path, start_time_ns=START_NS) as rec:
        rec.add_metadata("rig", {"path": "rigs/sim.toml", "text": "[stage]\nkind = 'sim'\n"})
        rec.add_metadata("protocol", {"name": "blocked-force", "parameters": json.dumps({"repetitions": 5})})
        for t, f in zip(force_t.tolist(), force.tolist()):
            rec.write_scalar("/force", t, force_N=f)
        for k in range(20):
            t = k * 1e-3
            rec.write_scalar("/stage/position", t, position_m=1e-4 * k)
            rec.write_scalar("/stage/command", t, target_m=2e-3)
            for name in ("bias", "drive"):
                rec.write_scalar(f"/amplifier/{name}/command", t, voltage_V=100.0 + k)
                rec.write_scalar(f"/amplifier/{name}/monitor", t, voltage_V=99.5 + k)
            rec.write_scalar("/camera/displacement", t, displacement_m=1e-6 * k, x_px=10.0 + k, y_px=-3.5)
        rec.write_scalar("/custom/temperature", 0.5, temperature_K=296.15, humidity=0.4)
        for k, frame in enumerate(frames):
            rec.write_image("/camera/image", 0.01 * k, frame)
            rec.write_image("/camera/png", 0.01 * k, frame, format="png")
        rec.write_image("/camera/image", 0.05, _frame(9, np.uint16))
        rec.write_image("/camera/colour", 0.05, np.stack([_frame(k) for k in (4, 5, 6)], axis=-1))
        rec.write_image("/camera/jpeg", 0.06, jpeg_source, format="jpeg")
        rec.write_image("/camera/raw_bytes", 0.07, b"\x89PNG-not-really", format="png", frame_id="cam2")
        rec.write_event(
            0.0, "protocol_start", 0, "blocked-force", repetitions=np.int64(5), voltages_V=np.array([100.0, 150.0])
        )
        rec.write_event(0.1, "step_start", 1, "bias 100 V")
        rec.write_bytes("/traffic/stage", 0.02, "tx", b"1PA0.5\r\n")
        rec.write_bytes("/traffic/stage", 0.03, "rx", bytes(range(256)))
        stats = rec.close("success", "all steps done")
    return {
        "path": path, "force_t": force_t, "force": force, "frames": frames, "jpeg_source": jpeg_source,
        "stats": stats,
    }


def test_scalars_events_images_traffic_metadata_round_trip(full_recording):
    r = RecordingReader(full_recording["path"], validate_crcs=True)
    assert not r.partial
    assert r.status.data_crc == "ok" and r.status.summary_crc == "ok"
    assert r.status.chunks_crc_checked >= 1
    assert r.exit_status == "success" and r.exit_reason == "all steps done"
    force = r.scalars("/force")
    np.testing.assert_array_equal(force["time_s"], full_recording["force_t"])
    np.testing.assert_array_equal(force["force_N"], full_recording["force"])
    stage = r.scalars("/stage/position")
    np.testing.assert_array_equal(stage["position_m"], 1e-4 * np.arange(20))
    assert set(r.scalars("/camera/displacement")) == {"time_s", "displacement_m", "x_px", "y_px"}
    np.testing.assert_array_equal(r.scalars("/camera/displacement")["x_px"], 10.0 + np.arange(20))
    np.testing.assert_array_equal(r.scalars("/amplifier/drive/monitor")["voltage_V"], 99.5 + np.arange(20))
    custom = r.scalars("/custom/temperature")
    assert custom["temperature_K"].tolist() == [296.15] and custom["humidity"].tolist() == [0.4]

    images = list(r.images("/camera/image"))
    assert [im.time_s for im in images] == [0.0, 0.01, 0.02, 0.05]
    for image, frame in zip(images, full_recording["frames"]):
        assert image.format == "raw" and image.encoding == "mono8" and image.frame_id == "camera"
        np.testing.assert_array_equal(image.pixels(), frame)
    assert images[3].encoding == "mono16"
    np.testing.assert_array_equal(images[3].pixels(), _frame(9, np.uint16))
    (colour,) = r.images("/camera/colour")
    assert colour.encoding == "bgr8"
    np.testing.assert_array_equal(colour.pixels(), np.stack([_frame(k) for k in (4, 5, 6)], axis=-1))
    pngs = list(r.images("/camera/png"))
    for image, frame in zip(pngs, full_recording["frames"], strict=True):
        assert image.format == "png"
        np.testing.assert_array_equal(image.pixels(), frame)  # lossless
    (jpeg,) = r.images("/camera/jpeg")
    assert jpeg.format == "jpeg"
    assert np.abs(jpeg.pixels().astype(int) - full_recording["jpeg_source"]).max() <= 8  # lossy, but close
    (raw,) = r.images("/camera/raw_bytes")
    assert raw.data == b"\x89PNG-not-really" and raw.frame_id == "cam2"

    events = r.events()
    assert [(e.kind, e.step, e.message) for e in events] == [
        ("protocol_start", 0, "blocked-force"), ("step_start", 1, "bias 100 V"),
    ]
    assert events[0].data == {"repetitions": 5, "voltages_V": [100.0, 150.0]}
    traffic = r.traffic("/traffic/stage")
    assert [(t.direction, t.data) for t in traffic] == [("tx", b"1PA0.5\r\n"), ("rx", bytes(range(256)))]

    meta = r.metadata()
    assert meta["rig"]["text"] == "[stage]\nkind = 'sim'\n"
    assert json.loads(meta["protocol"]["parameters"]) == {"repetitions": 5}
    assert meta["recording"]["start_time_ns"] == str(START_NS)
    assert meta["run_end"]["dropped_total"] == "0"
    topics = r.topics()
    assert topics["/force"].message_count == 2000
    assert topics["/force"].rate_Hz == pytest.approx(10_000.0)
    assert full_recording["stats"].written["/force"] == 2000


def test_reference_reader_decodes_every_message_with_log_time_equal_start_plus_time(full_recording):
    """The hand-laid-out scalar bytes must be ordinary protobuf: decode them with the generic decoder."""
    counts: dict[str, int] = {}
    with open(full_recording["path"], "rb") as f:
        reader = make_reader(f, validate_crcs=True, decoder_factories=[DecoderFactory()])
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
            assert channel.message_encoding == "protobuf" and schema.encoding == "protobuf"
            if schema.name.startswith("foxglove."):  # images, /log: their own timestamp
                stamp = decoded.timestamp.seconds * 10**9 + decoded.timestamp.nanos
                assert stamp == message.log_time
            else:
                assert message.log_time == START_NS + round(decoded.time_s * 1e9)
            if channel.topic == "/camera/image" and counts[channel.topic] <= 3:
                assert schema.name == "foxglove.RawImage" and decoded.encoding == "mono8"
                frame = full_recording["frames"][counts[channel.topic] - 1]
                assert (decoded.width, decoded.height, decoded.step) == (64, 48, 64)
                assert decoded.data == frame.tobytes()
            if channel.topic == "/force":
                assert schema.name == "hamr_bench.Force"
                i = counts["/force"] - 1
                assert decoded.force_N == full_recording["force"][i]
    assert counts["/force"] == 2000 and counts["/camera/image"] == 4 and counts["/events"] == 2


def test_out_of_order_and_nan_times_keep_the_field_but_not_break_log_time(tmp_path):
    path = tmp_path / "ooo.mcap"
    times = [0.1, 0.2, 0.15, math.nan, 0.3]
    with Recorder(path, start_time_ns=START_NS) as rec:
        for k, t in enumerate(times):
            rec.write_scalar("/force", t, force_N=float(k))
    r = RecordingReader(path)
    got = r.scalars("/force")
    np.testing.assert_array_equal(got["force_N"], np.arange(5.0))
    assert got["time_s"][:3].tolist() == [0.1, 0.2, 0.15] and math.isnan(got["time_s"][3])
    log_s = r.log_times_s("/force")
    assert np.all(np.diff(log_s) >= 0)
    assert log_s.tolist() == pytest.approx([0.1, 0.2, 0.2, 0.2, 0.3], abs=1e-9)
    assert json.loads(r.metadata()["run_end"]["out_of_order_by_topic"]) == {"/force": 2}


def test_refuses_to_overwrite_unless_asked(tmp_path):
    path = tmp_path / "existing.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(RecordingError, match="existing.mcap.*--force"):
        Recorder(path)
    assert path.read_bytes() == b"precious"
    with Recorder(path, overwrite=True) as rec:
        rec.write_scalar("/force", 0.0, force_N=1.0)
    assert RecordingReader(path).scalars("/force")["force_N"].tolist() == [1.0]


def test_missing_directory_is_a_one_line_error(tmp_path):
    with pytest.raises(RecordingError, match="cannot create recording"):
        Recorder(tmp_path / "no" / "such" / "dir.mcap")


def test_context_manager_closes_failed_with_the_exception_text(tmp_path):
    path = tmp_path / "boom.mcap"
    with pytest.raises(ValueError), Recorder(path) as rec:
        rec.write_scalar("/force", 0.0, force_N=1.0)
        raise ValueError("stage fault: E7\nsecond line")
    r = RecordingReader(path)
    assert r.exit_status == "failed" and r.exit_reason == "ValueError: stage fault: E7"
    assert r.scalars("/force")["force_N"].tolist() == [1.0]


def test_context_manager_ctrl_c_is_aborted_and_close_is_idempotent(tmp_path):
    path = tmp_path / "ctrlc.mcap"
    with pytest.raises(KeyboardInterrupt), Recorder(path) as rec:
        raise KeyboardInterrupt
    assert RecordingReader(path).exit_status == "aborted"
    assert rec.close("success") == rec.stats()  # already closed: no second run_end
    assert RecordingReader(path).exit_status == "aborted"
    with pytest.raises(RecordingError, match="closed"):
        rec.write_scalar("/force", 1.0, force_N=0.0)


def test_full_queue_drops_are_counted_never_silent(tmp_path):
    path = tmp_path / "drops.mcap"
    rec = Recorder(path, max_queue_messages=0, max_queue_bytes=0)
    for k in range(50):
        rec.write_scalar("/force", k * 1e-4, force_N=0.0)
    rec.write_image("/camera/image", 0.0, np.zeros((8, 8), np.uint8))
    stats = rec.close("success")
    assert stats.dropped == {"/force": 50, "/camera/image": 1} and stats.dropped_total == 51
    run_end = RecordingReader(path).metadata()["run_end"]
    assert run_end["dropped_total"] == "51"
    assert json.loads(run_end["dropped_by_topic"]) == {"/force": 50, "/camera/image": 1}


def test_block_mode_waits_for_room_instead_of_dropping(tmp_path):
    path = tmp_path / "offline.mcap"
    frame = np.arange(64, dtype=np.uint8).reshape(8, 8)
    with Recorder(path, max_queue_messages=1, max_queue_bytes=1, when_full="block") as rec:
        for k in range(3000):
            rec.write_scalar("/force", k * 1e-4, force_N=float(k))
            if k % 100 == 0:
                rec.write_image("/camera/image", k * 1e-4, frame)  # larger than the whole byte budget
    stats = rec.stats()
    assert stats.dropped_total == 0
    r = RecordingReader(path)
    np.testing.assert_array_equal(r.scalars("/force")["force_N"], np.arange(3000.0))
    assert r.topics()["/camera/image"].message_count == 30


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda r: r.write_scalar("/force", 0.0, force=1.0), "takes fields force_N"),
        (lambda r: r.write_scalar("/force", 0.0, force_N="heavy"), "expected time_s and a number"),
        (lambda r: r.write_scalar("/weird topic", 0.0, x=1.0), "not a valid topic"),
        (lambda r: r.write_scalar("/events", 0.0, x=1.0), "reserved"),
        (lambda r: r.write_scalar("/custom", 0.0), "at least one field"),
        (lambda r: r.add_metadata("rig", {"path": 3}), "must both be strings"),
        (lambda r: r.write_bytes("/traffic/stage", 0.0, "both", b""), "direction"),
        (lambda r: r.write_bytes("/stage", 0.0, "tx", b""), "must start with /traffic/"),
        (lambda r: r.write_image("/camera/image", 0.0, np.zeros((4, 4), np.float32)), "dtype"),
        (lambda r: r.write_image("/camera/image", 0.0, np.zeros((4, 4, 2), np.uint8)), "shape"),
        (lambda r: r.write_image("/camera/image", 0.0, b"\x89PNG"), "needs a numpy array"),
        (lambda r: (r.write_image("/cam", 0.0, np.zeros((4, 4), np.uint8)),
                    r.write_image("/cam", 0.1, np.zeros((4, 4), np.uint8), format="png")), "one schema per topic"),
        (lambda r: r.write_event(0.0, "x", 1, bad=object()), "not JSON serialisable"),
    ],
)
def test_bad_calls_raise_one_line_recording_errors(tmp_path, call, match):
    with Recorder(tmp_path / "bad.mcap") as rec:
        with pytest.raises(RecordingError, match=match) as info:
            call(rec)
        assert "\n" not in str(info.value)


@settings(max_examples=200, deadline=None)
@given(
    st.floats(allow_nan=False).filter(lambda x: x != 0.0),
    st.lists(st.floats(allow_nan=False).filter(lambda x: x != 0.0), min_size=3, max_size=3),
)
def test_fixed_layout_scalar_bytes_are_what_protobuf_itself_serialises(time_s, values):
    """The struct-packed payload equals the protobuf library's serialisation (nonzero values: proto3 omits zeros)."""
    schema = schemas.CAMERA_DISPLACEMENT
    fields = dict(zip(schema.fields, values))
    cls = schemas.message_class(schema.name, schema.descriptor_set())
    assert schema.packer()(time_s, fields) == cls(time_s=time_s, **fields).SerializeToString()


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_failing_disk_becomes_a_recording_error_for_the_caller(tmp_path):
    with pytest.raises(RecordingError, match="No space left on device"):
        Recorder("/dev/full", overwrite=True)  # the first metadata record cannot be written

    rec = Recorder(tmp_path / "disk-fills-up.mcap")
    rec.write_scalar("/force", 0.0, force_N=1.0)
    full = os.open("/dev/full", os.O_WRONLY)
    os.dup2(full, rec._file.fileno())  # from now on every write to the recording fails with ENOSPC
    os.close(full)
    with pytest.raises(RecordingError, match="No space left on device"):
        for k in range(1, 100):  # the failure reaches the caller at the next flush
            rec.write_scalar("/force", k * 1e-3, force_N=1.0)
            rec.flush()
    with pytest.raises(RecordingError, match="No space left on device"):
        rec.close("success")


def test_a_program_that_exits_without_closing_still_leaves_a_finished_file(tmp_path):
    path = tmp_path / "forgot.mcap"
    code = (
        "import sys\n"
        "from hamr_bench.recording import Recorder\n"
        "rec = Recorder(sys.argv[1])\n"
        "rec.write_scalar('/force', 0.0, force_N=2.0)\n"
    )
    subprocess.run([sys.executable, "-c", code, str(path)], check=True, timeout=60)
    r = RecordingReader(path)
    assert not r.partial
    assert r.exit_status == "failed" and r.exit_reason == "recorder not closed before the program exited"
    assert r.scalars("/force")["force_N"].tolist() == [2.0]
