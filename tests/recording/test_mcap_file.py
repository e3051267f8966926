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
    sent = []
    for i in range(200):
        channel = a if i % 3 else b
        data = bytes([i % 256]) * (1 + i % 7)
        # every tenth message is stored uncompressed in a chunk of its own, as the recorder does with frames
        w.add_message(channel, 1000 + i, data, 1000 + i, compression="" if i % 10 == 0 else None)
        sent.append((channel, 1000 + i, data))
        if i == 100:
            w.add_metadata("middle", {"x": "1"})
    w.add_metadata("end", {"y": "2"})
    w.finish()

    reader = make_reader(io.BytesIO(buf.getvalue()), validate_crcs=True)
    summary = reader.get_summary()
    assert summary.statistics.message_count == 200
    assert summary.statistics.channel_message_counts == {a: sum(c == a for c, _, _ in sent),
                                                         b: sum(c == b for c, _, _ in sent)}
    assert (summary.statistics.message_start_time, summary.statistics.message_end_time) == (1000, 1199)
    assert summary.channels[b].metadata == {"k": "v"} and summary.channels[a].topic == "/a"
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 20
    assert {c.compression for c in summary.chunk_indexes} == ({compression, ""} if compression else {""})
    got = [(m.channel_id, m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=False)]
    assert got == sent
    assert {m.name: m.metadata for m in reader.iter_metadata()} == {"middle": {"x": "1"}, "end": {"y": "2"}}
    # the same file streamed without its summary (as a reader of a file cut short would)
    from mcap.stream_reader import StreamReader
    records = list(StreamReader(io.BytesIO(buf.getvalue()), skip_magic=False, emit_chunks=False).records)
    assert sum(type(r).__name__ == "Message" for r in records) == 200
