"""A bounds-checked, single-pass scanner of an MCAP file's data section, shared by the reader and `recover`.

It reads records in file order and yields schemas, channels, metadata and messages (chunks are decompressed and
split). It never trusts a length field beyond the bytes actually present, so a truncated or corrupted file ends the
scan with a `problem` string instead of a hang, a huge allocation or a bare traceback. Three policies:

- `strict`: any CRC mismatch (chunk, data section, summary) or a damaged record in a file that has a footer raises
  RecordingError; a file without a footer (killed writer) is read up to its last complete record.
- `lenient`: no CRC checks; reads as far as the records make sense.
- `salvage` (recover): a chunk with a bad CRC or undecodable data is skipped and counted; scanning goes on.

`scan` yields one record per message. `_scan` takes an optional `split` that may hand a whole chunk on as one record
together with the MessageIndex records that follow it (`index_scan.py`, used by the reader); it returns None when it
cannot, and the chunk is then split record by record here. CRCs and file-level checks are the same either way.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, NamedTuple

from hamr_bench.errors import RecordingError

MAGIC = b"\x89MCAP0\r\n"
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 0x01, 0x02, 0x03, 0x04, 0x05
OP_CHUNK, OP_MESSAGE_INDEX, OP_METADATA, OP_DATA_END = 0x06, 0x07, 0x0C, 0x0F
_OP_NAMES = {
    0x01: "header", 0x02: "footer", 0x03: "schema", 0x04: "channel", 0x05: "message", 0x06: "chunk",
    0x07: "message index", 0x08: "chunk index", 0x09: "attachment", 0x0A: "attachment index",
    0x0B: "statistics", 0x0C: "metadata", 0x0D: "metadata index", 0x0E: "summary offset", 0x0F: "data end",
}
_FOOTER_RECORD_SIZE = 1 + 8 + 20
_RECORD_HEAD = struct.Struct("<BQ")
_MESSAGE_HEAD = struct.Struct("<HIQQ")
# A chunk claiming to inflate more than this is treated as corrupted rather than allocated.
_MAX_UNCOMPRESSED_CHUNK = 1 << 30

Policy = Literal["strict", "lenient", "salvage"]


class _Corrupt(Exception):
    """A record's bytes do not parse (internal; becomes a `problem` or a RecordingError)."""


@dataclass(frozen=True)
class SchemaRecord:
    id: int
    name: str
    encoding: str
    data: bytes


@dataclass(frozen=True)
class ChannelRecord:
    id: int
    schema_id: int
    topic: str
    message_encoding: str
    metadata: dict[str, str]


class MessageRecord(NamedTuple):
    """One message (a named tuple, not a dataclass: a camera run holds ~10^5 of them and a frozen dataclass costs
    several times as much to build)."""

    channel_id: int
    sequence: int
    log_time: int
    publish_time: int
    data: bytes
    chunk_offset: int  # file offset of the chunk record holding it (-1 outside chunks)


@dataclass(frozen=True)
class MetadataRecord:
    name: str
    values: dict[str, str]


@dataclass
class ScanStatus:
    """What the scan found about the file as a whole (filled while iterating)."""

    file_size: int = 0
    library: str = ""
    chunks: int = 0
    chunks_crc_checked: int = 0
    chunks_skipped: int = 0
    data_end_seen: bool = False
    data_crc: str = "not checked"  # ok | mismatch | absent | not checked
    summary_crc: str = "not checked"
    has_footer: bool = False
    bytes_read: int = 0  # offset just past the last record that parsed
    problem: str | None = None  # why the scan stopped before the data end, if it did
    skipped: list[str] = field(default_factory=list)

    @property
    def complete(self) -> bool:
        return self.has_footer and self.data_end_seen and self.problem is None


class _Cursor:
    __slots__ = ("buf", "pos", "end")

    def __init__(self, buf: bytes, pos: int = 0, end: int | None = None) -> None:
        self.buf = buf
        self.pos = pos
        self.end = len(buf) if end is None else end

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > self.end:
            raise _Corrupt(f"field of {n} bytes runs past its record")
        out = self.buf[self.pos : self.pos + n]
        self.pos += n
        return out

    def u16(self) -> int:
        return int.from_bytes(self.take(2), "little")

    def u32(self) -> int:
        return int.from_bytes(self.take(4), "little")

    def u64(self) -> int:
        return int.from_bytes(self.take(8), "little")

    def string(self) -> str:
        try:
            return self.take(self.u32()).decode("utf-8")
        except UnicodeDecodeError:
            raise _Corrupt("string is not UTF-8") from None

    def string_map(self) -> dict[str, str]:
        length = self.u32()
        end = self.pos + length
        if end > self.end:
            raise _Corrupt("map runs past its record")
        out: dict[str, str] = {}
        while self.pos < end:
            key = self.string()
            out[key] = self.string()
        if self.pos != end:
            raise _Corrupt("map length does not match its entries")
        return out


def _parse_schema(c: _Cursor) -> SchemaRecord:
    schema_id = c.u16()
    name = c.string()
    encoding = c.string()
    return SchemaRecord(schema_id, name, encoding, c.take(c.u32()))


def _parse_channel(c: _Cursor) -> ChannelRecord:
    channel_id = c.u16()
    schema_id = c.u16()
    topic = c.string()
    encoding = c.string()
    return ChannelRecord(channel_id, schema_id, topic, encoding, c.string_map())


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if size > _MAX_UNCOMPRESSED_CHUNK:
        raise _Corrupt(f"chunk claims {size} uncompressed bytes")
    try:
        if compression == "":
            out = data
        elif compression == "lz4":
            import lz4.frame

            out = lz4.frame.decompress(data)
        elif compression == "zstd":
            import zstandard

            out = zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        else:
            raise _Corrupt(f"unknown chunk compression {compression!r}")
    except _Corrupt:
        raise
    except Exception as exc:  # lz4 raises RuntimeError, zstandard ZstdError: both mean "not decodable"
        raise _Corrupt(f"{compression} data does not decompress ({exc})") from None
    if len(out) != size:
        raise _Corrupt(f"chunk inflates to {len(out)} bytes, header says {size}")
    return out


_CHUNK_HEAD = struct.Struct("<QQQII")  # start time, end time, uncompressed size, CRC, compression name length
_KNOWN_COMPRESSIONS = {b"": "", b"lz4": "lz4", b"zstd": "zstd"}


def _chunk_data(body: bytes, validate_crc: bool) -> bytes:
    """The records of a chunk, decompressed and (if asked) checked against the chunk's CRC."""
    fields = _split_chunk_body(body)
    if fields is None:  # something is off: the field-by-field parse says what, as it always did
        c = _Cursor(body)
        c.u64()  # message start time
        c.u64()  # message end time
        size = c.u64()
        crc = c.u32()
        compression = c.string()
        stored = c.take(c.u64())
    else:
        size, crc, compression, stored = fields
    data = _decompress(compression, stored, size)
    if validate_crc and crc != 0 and zlib.crc32(data) != crc:
        raise _Corrupt("chunk CRC mismatch")
    return data


def _split_chunk_body(body: bytes) -> tuple[int, int, str, bytes] | None:
    """(uncompressed size, CRC, compression, stored records) of a well-formed chunk body, in one unpack (a field at a
    time costs ~10 us a chunk); None if any length does not fit."""
    if len(body) < _CHUNK_HEAD.size:
        return None
    _start, _end, size, crc, name_length = _CHUNK_HEAD.unpack_from(body)
    at = _CHUNK_HEAD.size + name_length
    compression = _KNOWN_COMPRESSIONS.get(body[_CHUNK_HEAD.size : at])
    if compression is None or at + 8 > len(body):
        return None
    stored_length = int.from_bytes(body[at : at + 8], "little")
    if at + 8 + stored_length > len(body):
        return None
    return size, crc, compression, body[at + 8 : at + 8 + stored_length]


def _chunk_records(
    body: bytes, chunk_offset: int, validate_crc: bool
) -> Iterator[SchemaRecord | ChannelRecord | MessageRecord]:
    return _inner_records(_chunk_data(body, validate_crc), chunk_offset)


def _inner_records(
    data: bytes, chunk_offset: int, pos: int = 0, n: int | None = None
) -> Iterator[SchemaRecord | ChannelRecord | MessageRecord]:
    """The records in data[pos:n] (the whole chunk by default); one running past `n` is damage."""
    n = len(data) if n is None else n
    unpack_head = _RECORD_HEAD.unpack_from
    unpack_msg = _MESSAGE_HEAD.unpack_from
    while pos < n:
        if pos + 9 > n:
            raise _Corrupt("record header runs past the chunk")
        opcode, length = unpack_head(data, pos)
        pos += 9
        end = pos + length
        if end > n:
            raise _Corrupt("record runs past the chunk")
        if opcode == OP_MESSAGE:
            if length < 22:
                raise _Corrupt("message record too short")
            channel_id, sequence, log_time, publish_time = unpack_msg(data, pos)
            yield MessageRecord(channel_id, sequence, log_time, publish_time, data[pos + 22 : end], chunk_offset)
        elif opcode == OP_SCHEMA:
            yield _parse_schema(_Cursor(data, pos, end))
        elif opcode == OP_CHANNEL:
            yield _parse_channel(_Cursor(data, pos, end))
        pos = end


def read_chunk_messages(path: Path, chunk_offset: int, validate_crc: bool) -> Iterator[MessageRecord]:
    """Messages of the chunk record at `chunk_offset` (used to fetch images lazily)."""
    with open(path, "rb") as f:
        f.seek(chunk_offset)
        head = f.read(9)
        if len(head) < 9:
            raise RecordingError(f"{path}: chunk at byte {chunk_offset} is gone (file changed while reading?)")
        opcode, length = _RECORD_HEAD.unpack(head)
        body = f.read(length)
    if opcode != OP_CHUNK or len(body) != length:
        raise RecordingError(f"{path}: no chunk at byte {chunk_offset} (file changed while reading?)")
    try:
        return iter([r for r in _chunk_records(body, chunk_offset, validate_crc) if isinstance(r, MessageRecord)])
    except _Corrupt as exc:
        raise RecordingError(f"{path}: chunk at byte {chunk_offset}: {exc}") from None


Record = SchemaRecord | ChannelRecord | MessageRecord | MetadataRecord


# split(chunk records, chunk's file offset, bodies of the MessageIndex records after it) -> records, or None to have
# the chunk split record by record. It must never raise on bad input: doubt means None.
ChunkSplitter = Callable[[bytes, int, list[bytes]], "list[Any] | None"]


def scan(path: Path, policy: Policy, status: ScanStatus) -> Iterator[Record]:
    """Yield the records of the data section in file order; fill `status` as it goes (final once exhausted)."""
    return _scan(path, policy, status, None)


def _scan(path: Path, policy: Policy, status: ScanStatus, split: ChunkSplitter | None) -> Iterator[Any]:
    validate = policy != "lenient"
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"cannot open recording {path}: {exc.strerror or exc}") from None
    with f:
        size = status.file_size = _file_size(f)
        magic = f.read(8)
        if magic != MAGIC:
            what = "is empty" if size == 0 else "is not an MCAP recording (bad magic bytes at the start)"
            raise RecordingError(f"{path} {what}")
        status.has_footer = _has_footer(f, size)
        data_crc = zlib.crc32(magic)
        pos = 8
        status.bytes_read = pos
        while True:
            head = f.read(9)
            if len(head) < 9:
                status.problem = f"file ends at byte {size} without a data-end record"
                break
            opcode, length = _RECORD_HEAD.unpack(head)
            name = _OP_NAMES.get(opcode, f"opcode 0x{opcode:02x}")
            if length > size - pos - 9:
                status.problem = f"{name} record at byte {pos} runs past the end of the file"
                break
            if opcode == OP_DATA_END:
                status.data_end_seen = True
                body = f.read(length)
                stored = int.from_bytes(body[:4], "little") if len(body) >= 4 else 0
                if stored == 0:
                    status.data_crc = "absent"
                elif validate:
                    status.data_crc = "ok" if stored == data_crc else "mismatch"
                    if status.data_crc == "mismatch" and policy == "strict":
                        raise RecordingError(f"{path}: data section CRC mismatch (the file is corrupted)")
                status.bytes_read = pos + 9 + length
                if status.has_footer and status.bytes_read != _summary_start(f, size):
                    status.problem = f"data-end record at byte {pos} does not end where the footer's summary starts"
                break
            body = f.read(length)
            if validate:
                data_crc = zlib.crc32(body, zlib.crc32(head, data_crc))
            indexes: list[tuple[bytes, bytes]] = []
            try:
                if opcode == OP_CHUNK:
                    status.chunks += 1
                    try:
                        if split is not None:
                            data = _chunk_data(body, validate)
                            indexes = _peek_message_indexes(f, pos + 9 + length, size)
                            records = split(data, pos, [index_body for _, index_body in indexes])
                            if records is None:
                                records = list(_inner_records(data, pos))
                        else:
                            records = list(_chunk_records(body, pos, validate))
                    except _Corrupt as exc:
                        if policy == "salvage":
                            status.chunks_skipped += 1
                            status.skipped.append(f"chunk at byte {pos}: {exc}")
                            records = []
                        else:
                            raise
                    else:
                        if validate:
                            status.chunks_crc_checked += 1
                    yield from records
                    if indexes:
                        # The message indexes just peeked at: account for them as the loop below would.
                        pos += 9 + length
                        for index_head, index_body in indexes[:-1]:
                            if validate:
                                data_crc = zlib.crc32(index_body, zlib.crc32(index_head, data_crc))
                            pos += 9 + len(index_body)
                        head, body = indexes[-1]
                        length = len(body)
                        if validate:
                            data_crc = zlib.crc32(body, zlib.crc32(head, data_crc))
                elif opcode == OP_METADATA:
                    c = _Cursor(body)
                    name_ = c.string()
                    yield MetadataRecord(name_, c.string_map())
                elif opcode == OP_SCHEMA:
                    yield _parse_schema(_Cursor(body))
                elif opcode == OP_CHANNEL:
                    yield _parse_channel(_Cursor(body))
                elif opcode == OP_MESSAGE:
                    yield from _inner_records(head + body, -1)
                elif opcode == OP_HEADER:
                    c = _Cursor(body)
                    c.string()  # profile
                    status.library = c.string()
                elif opcode == OP_FOOTER:
                    status.problem = f"footer at byte {pos} before any data-end record"
                    break
            except _Corrupt as exc:
                # Truncation cannot get here (lengths were checked against the file size): this is damage.
                status.problem = f"{name} record at byte {pos} is damaged ({exc})"
                if policy == "strict":
                    raise RecordingError(f"{path}: {status.problem}") from None
                break
            pos += 9 + length
            status.bytes_read = pos
        if status.problem is not None and status.has_footer and policy == "strict":
            raise RecordingError(f"{path}: {status.problem}, although the file has a footer (corrupted)")
        if status.has_footer and status.data_end_seen and validate:
            status.summary_crc = _check_summary_crc(f, size)
            if status.summary_crc == "mismatch" and policy == "strict":
                raise RecordingError(
                    f"{path}: summary section CRC mismatch (its index is corrupted; "
                    "`hamr-bench recover` rebuilds it)"
                )


def _peek_message_indexes(f, at: int, size: int) -> list[tuple[bytes, bytes]]:  # noqa: ANN001
    """(head, body) of the complete MessageIndex records starting at `at` (just after a chunk); the file is left
    just past the last of them (the caller accounts for them once the chunk has been taken)."""
    bodies: list[tuple[bytes, bytes]] = []
    pos = at
    while True:
        head = f.read(9)
        if len(head) < 9:
            break
        opcode, length = _RECORD_HEAD.unpack(head)
        if opcode != OP_MESSAGE_INDEX or length > size - pos - 9:
            break
        body = f.read(length)
        if len(body) < length:
            break
        bodies.append((head, body))
        pos += 9 + length
    f.seek(pos)
    return bodies


def _file_size(f) -> int:  # noqa: ANN001
    import os

    return os.fstat(f.fileno()).st_size


def _has_footer(f, size: int) -> bool:  # noqa: ANN001
    if size < 8 + _FOOTER_RECORD_SIZE + 8:
        return False
    f.seek(size - 8 - _FOOTER_RECORD_SIZE)
    tail = f.read(_FOOTER_RECORD_SIZE + 8)
    f.seek(8)
    return tail[-8:] == MAGIC and tail[0] == OP_FOOTER and int.from_bytes(tail[1:9], "little") == 20


def _summary_start(f, size: int) -> int:  # noqa: ANN001
    """Where the footer says the summary section starts (the footer itself if there is no summary)."""
    footer_at = size - 8 - _FOOTER_RECORD_SIZE
    here = f.tell()
    f.seek(footer_at + 9)
    summary_start = int.from_bytes(f.read(8), "little")
    f.seek(here)
    return summary_start or footer_at


def _check_summary_crc(f, size: int) -> str:  # noqa: ANN001
    footer_at = size - 8 - _FOOTER_RECORD_SIZE
    f.seek(footer_at + 9)
    summary_start, _summary_offset_start, stored = struct.unpack("<QQI", f.read(20))
    if stored == 0:
        return "absent"
    start = summary_start if summary_start else footer_at
    if not 8 <= start <= footer_at:
        return "mismatch"
    f.seek(start)
    crc = zlib.crc32(f.read(footer_at + 25 - start))
    return "ok" if crc == stored else "mismatch"
