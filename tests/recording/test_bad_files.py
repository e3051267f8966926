"""Truncated and corrupted recordings give a clear RecordingError or a partial read with a RecordingWarning, never
a hang, a bare traceback or a silent wrong answer; `recover` makes a valid file out of any truncation."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest

from hamr_bench.errors import RecordingError
from hamr_bench.recording import Recorder, RecordingReader, RecordingWarning
from hamr_bench.recording.recover import recover
import contextlib


@pytest.fixture(scope="module")
def small_recording(tmp_path_factory):
    """A small file with several chunks, metadata between them, and every message kind."""
    path = tmp_path_factory.mktemp("bad") / "small.mcap"
    with Recorder(path, start_time_ns=10**18) as rec:
        rec.add_metadata("rig", {"path": "r.toml"})
        for chunk in range(3):
            for k in range(15):
                t = chunk * 0.1 + k * 1e-3
                rec.write_scalar("/force", t, force_N=float(chunk * 15 + k))
            rec.write_event(chunk * 0.1, "step_start", chunk)
            rec.write_bytes("/traffic/stage", chunk * 0.1, "tx", b"1TS\r\n")
            rec.flush()  # a chunk boundary
        rec.write_image("/camera/image", 0.35, np.arange(64, dtype=np.uint8).reshape(8, 8))
    data = path.read_bytes()
    return path, data


def _read(path, validate_crcs=True):
    """Outcome of opening a file: ('error', msg) | ('partial', reader, warnings) | ('ok', reader)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            reader = RecordingReader(path, validate_crcs=validate_crcs)
        except RecordingError as exc:
            assert "\n" not in str(exc)
            return ("error", str(exc))
    # another test's leftover (an unclosed event loop) warns from its finalizer whenever GC runs, here too: not
    # the reader's
    caught = [w for w in caught
              if not (issubclass(w.category, ResourceWarning) and str(w.message).startswith("unclosed event loop"))]
    ours = [w for w in caught if issubclass(w.category, RecordingWarning)]
    assert len(ours) == len(caught), [str(w.message) for w in caught]
    if reader.partial:
        assert len(ours) == 1
        return ("partial", reader)
    assert not ours
    return ("ok", reader)


def test_every_truncation_point_reads_a_prefix_or_fails_clearly(small_recording, tmp_path):
    path, data = small_recording
    full = RecordingReader(path).scalars("/force")["force_N"]
    target = tmp_path / "cut.mcap"
    target.write_bytes(data)
    outcomes = {"error": 0, "partial": 0}
    for cut in range(len(data) - 1, -1, -1):  # every truncation point, shortening one file in place
        os.truncate(target, cut)
        outcome = _read(target)
        assert outcome[0] != "ok", f"truncated at {cut} of {len(data)} bytes but read as complete"
        outcomes[outcome[0]] += 1
        if outcome[0] == "partial":
            reader = outcome[1]
            got = reader.scalars("/force")["force_N"] if "/force" in reader.topics() else np.array([])
            np.testing.assert_array_equal(got, full[: len(got)])
            if reader.exit_status is not None:
                # run_end is the last record of the data section: seeing it means no sample is missing.
                assert len(got) == len(full)
    assert outcomes["partial"] > outcomes["error"] > 0  # only cuts inside the magic are unreadable


@pytest.mark.parametrize("fraction", [0.0, 0.1, 0.3, 0.5, 0.7, 0.9, 0.97, 0.999])
def test_recover_turns_any_truncation_into_a_valid_file(small_recording, tmp_path, fraction):
    path, data = small_recording
    cut = max(int(len(data) * fraction), 0)
    src = tmp_path / "cut.mcap"
    src.write_bytes(data[:cut])
    if cut < 8:
        with pytest.raises(RecordingError, match="empty|not an MCAP"):
            recover(src, tmp_path / "out.mcap")
        assert not (tmp_path / "out.mcap").exists()
        return
    source_outcome = _read(src)
    source_kind, source = source_outcome[0], source_outcome[1]
    report = recover(src, tmp_path / "out.mcap")
    kind, reader = _read(tmp_path / "out.mcap")
    assert kind == "ok"
    if source_kind != "error":
        # every topic the cut file still describes is kept, even one whose messages were all lost
        assert set(reader.topics()) == set(source.topics())
    assert reader.metadata()["run_end"]["recovered"] == "true"
    if source_kind == "partial" and source.exit_status is not None:
        # Cut inside the summary: the run had ended and said how; recover keeps that.
        assert reader.exit_status == "success" and report.messages_by_topic["/force"] == 45
    else:
        assert reader.exit_status == "failed" and reader.exit_reason == "recovered: writer did not finish"
    n = report.messages_by_topic.get("/force", 0)
    if n:
        np.testing.assert_array_equal(reader.scalars("/force")["force_N"], np.arange(n, dtype=float))


def test_every_flipped_byte_is_detected(small_recording, tmp_path):
    """With CRC validation on, no single flipped byte anywhere goes unnoticed."""
    path, data = small_recording
    target = tmp_path / "flipped.mcap"
    target.write_bytes(data)
    fd = os.open(target, os.O_RDWR)
    try:
        for pos in range(len(data)):  # flip each byte in place, read, put it back
            os.pwrite(fd, bytes([data[pos] ^ 0x5A]), pos)
            outcome = _read(target)
            os.pwrite(fd, data[pos : pos + 1], pos)
            assert outcome[0] != "ok", f"byte {pos} of {len(data)} flipped but the file read as intact"
    finally:
        os.close(fd)


def test_flipped_byte_in_a_chunk_is_a_crc_error_and_recover_skips_that_chunk(small_recording, tmp_path):
    path, data = small_recording
    reader = RecordingReader(path)
    assert reader.status.chunks >= 3
    # Find the second chunk record and damage the middle of its compressed records.
    from hamr_bench.recording.scan import OP_CHUNK, ScanStatus, scan

    records = scan(path, "strict", ScanStatus())
    offsets = sorted({rec.chunk_offset for rec in records if hasattr(rec, "chunk_offset")})
    assert len(offsets) >= 3
    start, end = offsets[1], offsets[2]
    assert data[start] == OP_CHUNK
    damaged = bytearray(data)
    damaged[(start + end) // 2] ^= 0xFF
    target = tmp_path / "crc.mcap"
    target.write_bytes(bytes(damaged))
    with pytest.raises(RecordingError, match="chunk"):
        RecordingReader(target)
    report = recover(target, tmp_path / "saved.mcap")
    assert report.chunks_skipped == 1
    saved = RecordingReader(tmp_path / "saved.mcap")
    assert not saved.partial
    assert 0 < report.messages_recovered < sum(t.message_count for t in reader.topics().values())


def test_garbage_and_empty_files_are_clear_errors(tmp_path):
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(RecordingError, match="is empty"):
        RecordingReader(empty)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(np.random.default_rng(1).bytes(5000))
    with pytest.raises(RecordingError, match="not an MCAP recording"):
        RecordingReader(junk)
    with pytest.raises(RecordingError, match="cannot open"):
        RecordingReader(tmp_path / "missing.mcap")


def test_random_bytes_after_a_valid_header_never_crash(small_recording, tmp_path):
    path, data = small_recording
    rng = np.random.default_rng(7)
    target = tmp_path / "noise.mcap"
    for _trial in range(200):
        keep = int(rng.integers(8, len(data)))
        target.write_bytes(data[:keep] + rng.bytes(int(rng.integers(1, 300))))
        for validate in (True, False):
            _read(target, validate_crcs=validate)  # any outcome but an unexpected exception
        with contextlib.suppress(RecordingError):
            recover(target, tmp_path / "noise-out.mcap", overwrite=True)
