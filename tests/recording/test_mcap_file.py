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
        # every tenth message is a "frame", marked for stored chunks as the recorder marks frames kept whole
        channel = f if i % 10 == 0 else a if i % 3 else b
        data = bytes([i % 256]) * (1 + i % 7 + (600 if channel == f else 0))
        w.add_message(channel, 1000 + i, data, 1000 + i, stored=channel == f)
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
    # a chunk mostly of frame bytes is stored, the others compressed
    assert {c.compression for c in summary.chunk_indexes} == ({compression, ""} if compression else {""})
    # One chunk is open at a time: file order is the order sent, which is log-time order.
    assert [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=True)] == sent
    assert [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=False)] == sent
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


def test_chunk_compression_follows_what_the_chunk_holds():
    """A chunk at least half made of bytes marked `stored` (frames) is written uncompressed; one of scalars with
    a few small marked messages (regions of interest are not marked, but a stray one must not matter) is
    compressed."""
    buf = io.BytesIO()
    w = McapFileWriter(buf, chunk_size=4096, compression="lz4")
    w.start()
    schema = w.register_schema("s", "protobuf", b"")
    scalar, frames = w.register_channel("/force", "protobuf", schema), w.register_channel("/image", "protobuf", schema)
    for i in range(400):
        w.add_message(scalar, i, b"x" * 18)
        if i % 160 == 0:
            w.add_message(frames, i, b"f" * 5000, stored=True)  # closes its chunk: mostly frame bytes
        elif i % 40 == 0:
            w.add_message(frames, i, b"f" * 10, stored=True)
    w.finish()
    summary = make_reader(io.BytesIO(buf.getvalue())).get_summary()
    by_compression = {c.compression: 0 for c in summary.chunk_indexes}
    for c in summary.chunk_indexes:
        by_compression[c.compression] += 1
        assert (c.compression == "") == (c.uncompressed_size > 5000)
    assert by_compression[""] == 3 and by_compression["lz4"] >= 3  # scalars fill chunks of their own between
