"""The recorder's own MCAP writer, read back by the `mcap` package (an independent implementation of the spec)."""

from __future__ import annotations

import io

import pytest
from mcap.reader import make_reader

from hamr_bench.recording.mcap_file import McapFileWriter


@pytest.mark.parametrize("compression", ["lz4", "zstd", ""])
def test_official_reader_reads_back_every_record(compression):
    buf = io.BytesIO()
    w = McapFileWriter(buf, chunk_size=300, compression=compression)
    w.start(profile="", library="test")
    schema = w.register_schema("s", "protobuf", b"\x01\x02")
    a = w.register_channel("/a", "protobuf", schema)
    b = w.register_channel("/b", "protobuf", schema, {"k": "v"})
    f = w.register_channel("/frames", "protobuf", schema)
    sent = []
    for i in range(200):
        # every tenth message is a "frame", stored uncompressed as the recorder does with frames
        channel = f if i % 10 == 0 else a if i % 3 else b
        data = bytes([i % 256]) * (1 + i % 7)
        w.add_message(channel, 1000 + i, data, 1000 + i, compression="" if channel == f else None)
        sent.append((channel, 1000 + i, data))
        if i == 100:
            w.add_metadata("middle", {"x": "1"})
    w.add_metadata("end", {"y": "2"})
    w.finish()

    reader = make_reader(io.BytesIO(buf.getvalue()), validate_crcs=True)
    summary = reader.get_summary()
    assert summary.statistics.message_count == 200
    assert summary.statistics.channel_message_counts == {c: sum(c == s for s, _, _ in sent) for c in (a, b, f)}
    assert (summary.statistics.message_start_time, summary.statistics.message_end_time) == (1000, 1199)
    assert summary.channels[b].metadata == {"k": "v"} and summary.channels[a].topic == "/a"
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 20
    assert {c.compression for c in summary.chunk_indexes} == ({compression, ""} if compression else {""})
    # Stored and compressed chunks are open side by side, so file order interleaves them; log-time order is the
    # order sent, and within a channel file order is too.
    assert [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=True)] == sent
    in_file_order = [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=False)]
    for channel in (a, b, f):
        assert [m for m in in_file_order if m[0] == channel] == [m for m in sent if m[0] == channel]
    assert {m.name: m.metadata for m in reader.iter_metadata()} == {"middle": {"x": "1"}, "end": {"y": "2"}}
    # the same file streamed without its summary (as a reader of a file cut short would)
    from mcap.stream_reader import StreamReader
    records = list(StreamReader(io.BytesIO(buf.getvalue()), skip_magic=False, emit_chunks=False).records)
    kinds = [type(r).__name__ for r in records]
    assert kinds.count("Message") == 200
    # in the data section, every channel (and its schema) is defined before the first message
    data_section = kinds[:kinds.index("DataEnd")]
    assert data_section.index("Schema") < data_section.index("Channel")
    assert max(i for i, k in enumerate(data_section) if k == "Channel") < data_section.index("Message")


def test_a_frame_does_not_cut_the_scalar_chunk_short():
    """Frames go in stored chunks of their own while scalars keep filling one compressed chunk: the scalars take
    as many chunks as their bytes need, not one per frame."""
    buf = io.BytesIO()
    w = McapFileWriter(buf, chunk_size=4096, compression="lz4")
    w.start()
    schema = w.register_schema("s", "protobuf", b"")
    scalar, frames = w.register_channel("/force", "protobuf", schema), w.register_channel("/image", "protobuf", schema)
    scalar_bytes = 0
    for i in range(400):
        w.add_message(scalar, i, b"x" * 18)
        scalar_bytes += 31 + 18  # message record header + payload
        if i % 8 == 0:
            w.add_message(frames, i, b"f" * 1000, compression="")
    w.finish()
    summary = make_reader(io.BytesIO(buf.getvalue())).get_summary()
    scalar_chunks = sum(c.compression == "lz4" for c in summary.chunk_indexes)
    assert scalar_chunks <= scalar_bytes // 4096 + 1  # 50 frames; one chunk at a time made ~50 scalar chunks
