"""The reader's indexed fast path (chunks read through their MessageIndex records, `index_scan.py`) gives exactly
what the per-record path gives: every reader API compared on the same file, for files from our writer, from the
`mcap` package's writer (with and without message indexes), truncated files, and files with a damaged chunk or a
damaged message index. The reference is `RecordingReader(..., use_message_indexes=False)`, the plain scan."""

from __future__ import annotations

import os
import struct
import zlib
import warnings

import numpy as np
import pytest
from mcap.writer import CompressionType, IndexType, Writer

from hamr_bench.errors import RecordingError
from hamr_bench.recording import Recorder, RecordingReader, RecordingWarning
from hamr_bench.recording.scan import OP_CHUNK, OP_MESSAGE_INDEX, ChannelRecord, MessageRecord, MetadataRecord
from hamr_bench.recording.scan import SchemaRecord, ScanStatus, scan


def _facts(reader: RecordingReader) -> dict:
    """Everything a caller can get from a reader, as plain comparable values."""
    topics = reader.topics()
    out: dict = {
        "topics": topics, "metadata": reader.metadata(), "exit": (reader.exit_status, reader.exit_reason),
        "partial": reader.partial, "orphans": reader.orphan_messages, "start_ns": reader.start_time_ns,
    }
    status = dict(vars(reader.status))
    out["status"] = status
    for topic, _info in topics.items():
        out[f"log_times {topic}"] = reader.log_times_s(topic).tolist()
        for name, call in (("scalars", reader.scalars), ("traffic", reader.traffic), ("images", reader.images)):
            try:
                value = call(topic)
                value = {k: v.tolist() for k, v in value.items()} if name == "scalars" else list(value)
            except (RecordingError, AttributeError) as exc:
                value = ("error", type(exc).__name__, str(exc))
            out[f"{name} {topic}"] = value
    try:
        out["events"] = reader.events()
    except RecordingError as exc:
        out["events"] = ("error", str(exc))
    return out


def _outcome(path, validate_crcs: bool = True, use_message_indexes: bool = True):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            reader = RecordingReader(path, validate_crcs=validate_crcs, use_message_indexes=use_message_indexes)
        except RecordingError as exc:
            return ("error", str(exc)), None
    said = [str(w.message) for w in caught if issubclass(w.category, RecordingWarning)]
    return ("read", _facts(reader), said), reader


def _assert_same(path, validate_crcs: bool = True) -> RecordingReader | None:
    fast, reader = _outcome(path, validate_crcs)
    plain, _ = _outcome(path, validate_crcs, use_message_indexes=False)
    assert fast == plain
    return reader


def _frame(seed: int) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 255, size=(24, 32), dtype=np.uint8)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A run with every kind of message: scalar streams over many chunks, camera frames each in its own stored chunk
    between compressed scalar chunks (as the recorder writes them), a topic first written mid-run, events with
    different sizes, traffic, metadata between chunks."""
    path = tmp_path_factory.mktemp("fast") / "run.mcap"
    with Recorder(path, start_time_ns=10**18, chunk_size=4096) as rec:
        rec.add_metadata("rig", {"path": "r.toml"})
        for k in range(1500):
            t = k * 1e-3
            rec.write_scalar("/force", t, force_N=np.sin(k / 10.0))
            rec.write_scalar("/amplifier/drive/command", t, voltage_V=100.0 + k)
            if k % 7 == 0:
                rec.write_scalar("/camera/displacement", t, displacement_m=1e-6 * k, x_px=k, y_px=-1.0)
            if k % 100 == 0:
                rec.write_image("/camera/image", t, _frame(k))
                rec.write_event(t, "step_start", k // 100, "step" + "!" * (k // 100), level=k)
            if k == 700:  # a topic that first appears mid-run: registered inside a chunk
                rec.add_metadata("middle", {"k": str(k)})
            if k >= 700 and k % 3 == 0:
                rec.write_scalar("/stage/position", t, position_m=1e-5 * k)
            if k % 250 == 0:
                rec.write_bytes("/traffic/stage", t, "tx", b"1PA" + str(k).encode() + b"\r\n")
    return path


def test_our_writer_files_take_the_fast_path_and_read_the_same(recorded):
    reader = _assert_same(recorded)
    assert reader is not None and not reader.partial
    assert reader.status.chunks > 30
    assert reader.chunks_indexed > 0.9 * reader.status.chunks  # the fast path was taken, not just the fallback
    assert reader.topics()["/force"].message_count == 1500
    # And without CRC checks (lenient scan).
    _assert_same(recorded, validate_crcs=False)


def _copy_with_mcap_writer(source, target, **writer_options) -> int:
    """The same records written by the `mcap` package's Writer (another chunk layout and index writer)."""
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    messages = 0
    with open(target, "wb") as f:
        writer = Writer(f, **writer_options)
        writer.start(profile="", library="mcap-package-test")
        for record in scan(source, "strict", ScanStatus()):
            if isinstance(record, SchemaRecord):
                schema_ids[record.id] = writer.register_schema(record.name, record.encoding, record.data)
            elif isinstance(record, ChannelRecord):
                channel_ids[record.id] = writer.register_channel(
                    record.topic, record.message_encoding, schema_ids[record.schema_id], record.metadata)
            elif isinstance(record, MessageRecord):
                writer.add_message(channel_ids[record.channel_id], record.log_time, record.data, record.publish_time,
                                   record.sequence)
                messages += 1
            elif isinstance(record, MetadataRecord):
                writer.add_metadata(record.name, record.values)
        writer.finish()
    return messages


@pytest.mark.parametrize("options", [
    {"chunk_size": 2000, "compression": CompressionType.ZSTD},
    {"chunk_size": 5000, "compression": CompressionType.LZ4},
    {"chunk_size": 3000, "compression": CompressionType.NONE, "index_types": IndexType.NONE},
], ids=["zstd", "lz4", "no-indexes"])
def test_files_from_the_mcap_package_read_the_same(recorded, tmp_path, options):
    target = tmp_path / "mcap-package.mcap"
    messages = _copy_with_mcap_writer(recorded, target, **options)
    reader = _assert_same(target)
    assert reader is not None
    assert sum(t.message_count for t in reader.topics().values()) == messages
    if options.get("index_types") == IndexType.NONE:
        assert reader.chunks_indexed == 0
    else:
        assert reader.chunks_indexed > 0


def test_truncated_files_read_the_same_prefix_or_fail_the_same(recorded, tmp_path):
    data = recorded.read_bytes()
    target = tmp_path / "cut.mcap"
    rng = np.random.default_rng(3)
    cuts = sorted({*rng.integers(8, len(data), 40).tolist(), len(data) - 1, len(data) // 2, 9, 100})
    for cut in cuts:
        target.write_bytes(data[:cut])
        _assert_same(target)
        _assert_same(target, validate_crcs=False)


def _chunk_and_index_offsets(data: bytes) -> tuple[list[int], list[int]]:
    """File offsets of the chunk and MessageIndex records, walking the data section's record heads."""
    chunks, indexes = [], []
    pos = 8 + 9 + int.from_bytes(data[9:17], "little")  # past the magic and the header record
    while pos + 9 <= len(data) and data[pos] != 0x0F:
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        (chunks if data[pos] == OP_CHUNK else indexes if data[pos] == OP_MESSAGE_INDEX else []).append(pos)
        pos += 9 + length
    return chunks, indexes


def test_a_damaged_chunk_fails_or_reads_the_same(recorded, tmp_path):
    data = recorded.read_bytes()
    chunks, _ = _chunk_and_index_offsets(data)
    target = tmp_path / "damaged.mcap"
    for chunk in (chunks[1], chunks[len(chunks) // 2], chunks[-1]):
        for delta in (40, 60, 300):  # in the chunk header, at its first records, further in
            damaged = bytearray(data)
            damaged[chunk + delta] ^= 0x5A
            target.write_bytes(bytes(damaged))
            fast, _ = _outcome(target)
            assert fast[0] == "error"
            assert (fast, None) == _outcome(target, use_message_indexes=False)
            _assert_same(target, validate_crcs=False)  # no CRC checks: read as far as the records make sense


def test_a_message_index_that_disagrees_is_not_trusted(recorded, tmp_path):
    """Without CRC checks a damaged index goes unnoticed by the scan: the fast path must see that it disagrees with
    its chunk and take that chunk record by record, never return other data."""
    data = recorded.read_bytes()
    _, indexes = _chunk_and_index_offsets(data)
    plain_reader = RecordingReader(recorded, validate_crcs=False)
    target = tmp_path / "bad-index.mcap"
    fell_back = 0
    for index in indexes[5:200:13]:
        for delta in (9, 15, 15 + 8, 15 + 12):  # channel id, first log time, first offset, its high bytes
            damaged = bytearray(data)
            damaged[index + delta] ^= 0x21
            target.write_bytes(bytes(damaged))
            reader = _assert_same(target, validate_crcs=False)
            assert reader is not None
            fell_back += reader.chunks_indexed < plain_reader.chunks_indexed
            with pytest.raises(RecordingError, match="data section CRC mismatch"):
                RecordingReader(target)  # with CRC checks the damage is an error, as before
    assert fell_back > 0


def test_orphan_messages_are_counted_the_same(recorded, tmp_path):
    """A file whose first chunk (holding the channel records) is unreadable: later messages are orphans."""
    data = recorded.read_bytes()
    chunks, _ = _chunk_and_index_offsets(data)
    damaged = bytearray(data)
    damaged[chunks[0] + 50] ^= 0xFF
    target = tmp_path / "orphans.mcap"
    target.write_bytes(bytes(damaged))
    reader = _assert_same(target, validate_crcs=False)
    if reader is not None:
        assert reader.orphan_messages >= 0
    os.truncate(target, len(data) // 3)
    _assert_same(target, validate_crcs=False)


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


def _text(value: str) -> bytes:
    return struct.pack("<I", len(value)) + value.encode()


def test_an_index_claiming_a_message_in_a_chunk_too_short_for_one_is_not_trusted(tmp_path):
    """A chunk shorter than a message header, whose index claims a message, at the end of a batch (found by a fuzzing
    review: the header look-up ran past the batch's bytes and raised IndexError). Read as the plain scan reads it."""
    from hamr_bench.recording import schemas

    force = schemas.FORCE
    records = [_record(0x03, struct.pack("<H", 1) + _text(force.name) + _text("protobuf")
                       + struct.pack("<I", len(force.descriptor_set())) + force.descriptor_set()),
               _record(0x04, struct.pack("<HH", 1, 1) + _text("/force") + _text("protobuf") + struct.pack("<I", 0))]
    for log_time, inner, entries in ((10, True, [(10, 0)]), (11, True, [(11, 0)]), (11, False, [(11, 0)])):
        data = _record(0x05, struct.pack("<HIQQ", 1, 0, log_time, log_time)
                       + force.packer()(log_time * 1e-9, {"force_N": 1.0})) if inner else b""
        records.append(_record(OP_CHUNK, struct.pack("<QQQI", log_time, log_time, len(data), zlib.crc32(data))
                               + _text("") + struct.pack("<Q", len(data)) + data))
        index = b"".join(struct.pack("<QQ", t, offset) for t, offset in entries)
        records.append(_record(OP_MESSAGE_INDEX, struct.pack("<HI", 1, len(index)) + index))
    body = b"\x89MCAP0\r\n" + _record(0x01, _text("") + _text("test")) + b"".join(records)
    body += _record(0x0F, struct.pack("<I", zlib.crc32(body)))
    path = tmp_path / "tiny-chunk.mcap"
    path.write_bytes(body + struct.pack("<BQQQI", 0x02, 20, 0, 0, 0) + b"\x89MCAP0\r\n")
    reader = _assert_same(path)
    assert reader is not None and reader.scalars("/force")["force_N"].tolist() == [1.0, 1.0]
