"""The MCAP byte layout as the recorder writes it: records, chunks, message indexes, and the summary section.

Why not `mcap.writer.Writer`: it builds every record field by field through a stream object (about ten Python calls
a message), which made the writer thread ~28 % of a simulated run's CPU. Here a message record is one
`struct.pack`, the message index of a chunk is one `numpy` array turned to bytes, and each chunk chooses its own
compression when it closes (a chunk that is mostly camera-frame bytes the caller marked `stored` is written
uncompressed, any other is compressed) instead of through a private attribute of another library's class. The
recorder and `recover` write with it; the tests read what it writes with the `mcap` package, an independent
implementation, as well as with `scan.py`.

Layout (MCAP v0, https://mcap.dev/spec): magic, Header, then the data section: Schema and Channel records as they
are registered (outside chunks, so a truncated file still describes its channels), Chunks each followed by one
MessageIndex per channel (one chunk is open at a time, so messages reach the file in the order they are added: a
caller that adds them in log-time order, as the recorder does, gets a file whose log times never decrease in file
order), Metadata records between chunks; DataEnd with the
CRC of the data section; the summary section: Schemas, Channels, Statistics, ChunkIndexes, MetadataIndexes,
SummaryOffsets; Footer with the summary CRC; magic. All CRCs are written (chunk, data section, summary).
"""

from __future__ import annotations

import struct
import zlib
from typing import BinaryIO

import numpy as np

MAGIC = b"\x89MCAP0\r\n"

OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06
OP_MESSAGE_INDEX, OP_CHUNK_INDEX, OP_STATISTICS, OP_METADATA = 0x07, 0x08, 0x0B, 0x0C
OP_METADATA_INDEX, OP_SUMMARY_OFFSET, OP_DATA_END = 0x0D, 0x0E, 0x0F

_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<BQHIQQ")  # opcode, length, channel id, sequence, log time, publish time
_MESSAGE_FIXED = 2 + 4 + 8 + 8
COMPRESSIONS = ("lz4", "zstd", "")


def _string(text: str) -> bytes:
    raw = text.encode("utf-8")
    return struct.pack("<I", len(raw)) + raw


def _string_map(values: dict[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in values.items())
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return _RECORD_HEAD.pack(opcode, len(body)) + body


def _compress(data: bytes, compression: str) -> bytes:
    if compression == "lz4":
        import lz4.frame  # a dependency of the mcap package

        return lz4.frame.compress(data)
    if compression == "zstd":
        import zstandard  # a dependency of the mcap package

        return zstandard.compress(data)
    return data


class _Chunk:
    """The chunk in progress: its records, and per channel the (log time, offset) of each message."""

    __slots__ = ("parts", "size", "messages", "start_ns", "end_ns", "index", "stored_bytes")

    def __init__(self) -> None:
        self.parts: list[bytes] = []
        self.size = 0
        self.messages = 0
        self.start_ns = 0
        self.end_ns = 0
        self.index: dict[int, list[int]] = {}  # channel id -> [log time, offset, log time, offset, ...]
        self.stored_bytes = 0  # bytes of messages that would rather be stored than compressed (camera frames)


class McapFileWriter:
    """Writes one MCAP file to an open binary stream; the caller owns the stream (and fsync)."""

    def __init__(self, stream: BinaryIO, chunk_size: int = 256 * 1024, compression: str = "lz4") -> None:
        if compression not in COMPRESSIONS:
            raise ValueError(f"compression {compression!r}: expected one of {COMPRESSIONS}")
        self._out = stream
        self._chunk_size = int(chunk_size)
        self.compression = compression
        self._pos = 0
        self._data_crc = 0
        self._chunk: _Chunk | None = None  # the chunk in progress
        self._schemas: list[bytes] = []  # their records, for the summary
        self._channels: list[bytes] = []
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._channel_counts: dict[int, int] = {}
        self._chunk_spans: list[tuple[int, int]] = []  # (first, last log time) per chunk: the file's span
        self._metadata_count = 0
        self._finished = False

    # ------------------------------------------------------------------ writing bytes
    def _write(self, data: bytes) -> None:
        self._out.write(data)
        self._data_crc = zlib.crc32(data, self._data_crc)
        self._pos += len(data)

    def start(self, profile: str = "", library: str = "") -> None:
        self._write(MAGIC)
        self._write(_record(OP_HEADER, _string(profile) + _string(library)))

    # ------------------------------------------------------------------ registration
    # Schema and Channel records go straight into the data section, outside any chunk: written at once, a definition
    # precedes every message of its channel, so a truncated file still describes its channels.
    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        schema_id = len(self._schemas) + 1
        record = _record(OP_SCHEMA, struct.pack("<H", schema_id) + _string(name) + _string(encoding)
                         + struct.pack("<I", len(data)) + bytes(data))
        self._schemas.append(record)
        self._write(record)
        return schema_id

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: dict[str, str] | None = None) -> int:
        channel_id = len(self._channels) + 1
        record = _record(OP_CHANNEL, struct.pack("<HH", channel_id, schema_id) + _string(topic)
                         + _string(message_encoding) + _string_map(metadata or {}))
        self._channels.append(record)
        self._channel_counts[channel_id] = 0
        self._write(record)
        return channel_id

    # ------------------------------------------------------------------ messages
    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int | None = None,
                    sequence: int = 0, stored: bool = False) -> None:
        """One message into the open chunk. `stored=True` marks bytes that compress badly for their cost (camera
        frames: sensor noise): a chunk at least half made of them is written uncompressed, any other with the
        file's compression. One chunk is open at a time, so file order is the order of the calls."""
        chunk = self._chunk
        if chunk is None:
            chunk = self._chunk = _Chunk()
        head = _MESSAGE_HEAD.pack(OP_MESSAGE, _MESSAGE_FIXED + len(data), channel_id, sequence, log_time,
                                  log_time if publish_time is None else publish_time)
        entries = chunk.index.get(channel_id)
        if entries is None:
            entries = chunk.index[channel_id] = []
        entries.append(log_time)
        entries.append(chunk.size)
        chunk.parts.append(head)
        chunk.parts.append(data)
        chunk.size += len(head) + len(data)
        if stored:
            chunk.stored_bytes += len(data)
        if chunk.messages:
            if log_time < chunk.start_ns:
                chunk.start_ns = log_time
            if log_time > chunk.end_ns:
                chunk.end_ns = log_time
        else:
            chunk.start_ns = chunk.end_ns = log_time
        chunk.messages += 1
        self._channel_counts[channel_id] += 1
        if chunk.size > self._chunk_size:
            self.close_chunk()

    def close_chunk(self) -> None:
        """Write the open chunk (if any) and its message indexes."""
        chunk = self._chunk
        if chunk is None:
            return
        self._chunk = None
        compression = "" if 2 * chunk.stored_bytes >= chunk.size else self.compression
        data = b"".join(chunk.parts)
        stored = _compress(data, compression)
        body = (struct.pack("<QQQI", chunk.start_ns, chunk.end_ns, len(data), zlib.crc32(data))
                + _string(compression) + struct.pack("<Q", len(stored)))
        chunk_start = self._pos
        self._write(_RECORD_HEAD.pack(OP_CHUNK, len(body) + len(stored)) + body)
        self._write(stored)
        chunk_length = self._pos - chunk_start
        index_start = self._pos
        offsets = []
        for channel_id in sorted(chunk.index):
            entries = np.asarray(chunk.index[channel_id], dtype="<u8").tobytes()
            offsets.append(struct.pack("<HQ", channel_id, self._pos))
            self._write(_record(OP_MESSAGE_INDEX, struct.pack("<HI", channel_id, len(entries)) + entries))
        offsets_map = b"".join(offsets)
        self._chunk_spans.append((chunk.start_ns, chunk.end_ns))
        self._chunk_indexes.append(_record(OP_CHUNK_INDEX, struct.pack(
            "<QQQQI", chunk.start_ns, chunk.end_ns, chunk_start, chunk_length, len(offsets_map)) + offsets_map
            + struct.pack("<Q", self._pos - index_start) + _string(compression)
            + struct.pack("<QQ", len(stored), len(data))))

    def flush(self) -> None:
        """Close the chunk in progress and push everything to the stream (no fsync: the caller's)."""
        self.close_chunk()
        self._out.flush()

    # ------------------------------------------------------------------ metadata and the end
    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        self.close_chunk()
        offset = self._pos
        record = _record(OP_METADATA, _string(name) + _string_map(values))
        self._write(record)
        self._metadata_count += 1
        self._metadata_indexes.append(_record(OP_METADATA_INDEX, struct.pack("<QQ", offset, len(record))
                                              + _string(name)))

    def finish(self) -> None:
        """Data end, summary, footer, magic. The stream is left open (and not fsynced)."""
        if self._finished:
            return
        self.close_chunk()
        data_end = _record(OP_DATA_END, struct.pack("<I", self._data_crc))
        self._write(data_end)
        summary_start = self._pos
        groups: list[tuple[int, bytes]] = []
        counts = b"".join(struct.pack("<HQ", c, n) for c, n in self._channel_counts.items())
        start_ns = min((a for a, _ in self._chunk_spans), default=0)
        end_ns = max((b for _, b in self._chunk_spans), default=0)
        statistics = _record(OP_STATISTICS, struct.pack(
            "<QHIIIIQQI", sum(self._channel_counts.values()), len(self._schemas), len(self._channels), 0,
            self._metadata_count, len(self._chunk_indexes), start_ns, end_ns, len(counts)) + counts)
        for opcode, records in ((OP_SCHEMA, self._schemas), (OP_CHANNEL, self._channels),
                                (OP_STATISTICS, [statistics]), (OP_CHUNK_INDEX, self._chunk_indexes),
                                (OP_METADATA_INDEX, self._metadata_indexes)):
            if records:
                groups.append((opcode, b"".join(records)))
        summary = bytearray()
        offsets = bytearray()
        for opcode, group in groups:
            offsets += _record(OP_SUMMARY_OFFSET, struct.pack("<BQQ", opcode, summary_start + len(summary),
                                                              len(group)))
            summary += group
        summary_offset_start = summary_start + len(summary)
        summary += offsets
        footer_head = struct.pack("<BQQQ", OP_FOOTER, 8 + 8 + 4, summary_start, summary_offset_start)
        summary_crc = zlib.crc32(footer_head, zlib.crc32(bytes(summary)))
        self._out.write(bytes(summary))
        self._out.write(footer_head + struct.pack("<I", summary_crc))
        self._out.write(MAGIC)
        self._finished = True
