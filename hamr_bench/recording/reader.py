"""Reading a hamr-bench recording back: metadata, topics, scalar streams as numpy arrays, events, images, traffic.

The whole data section is scanned once when the reader opens (validating every chunk CRC, the data-section CRC and
the summary CRC unless `validate_crcs=False`). Scalars, events and traffic are kept in memory (tens of MB for an
hour at 10 kHz); images stay on disk and are fetched chunk by chunk when iterated. A file without a footer (a
killed writer) is read up to its last complete record with a `RecordingWarning`; a damaged file raises
`RecordingError` naming the file and the byte at fault.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.errors import RecordingError
from hamr_bench.recording import schemas
from hamr_bench.recording.scan import (
    ChannelRecord,
    MessageRecord,
    MetadataRecord,
    SchemaRecord,
    ScanStatus,
    read_chunk_messages,
    scan,
)

_LAZY_SCHEMAS = set(schemas.IMAGE_SCHEMAS)


class RecordingWarning(UserWarning):
    """A recording was readable only in part (no footer: its writer did not finish)."""


@dataclass(frozen=True)
class TopicInfo:
    topic: str
    schema_name: str
    message_count: int
    first_time_s: float | None
    last_time_s: float | None

    @property
    def rate_Hz(self) -> float | None:
        if self.message_count < 2 or self.first_time_s is None or self.last_time_s is None:
            return None
        span_s = self.last_time_s - self.first_time_s
        return (self.message_count - 1) / span_s if span_s > 0 else None


@dataclass(frozen=True)
class Event:
    time_s: float
    step: int
    kind: str
    message: str
    data: dict[str, Any]


@dataclass(frozen=True)
class Image:
    """One camera frame: `format` is "raw" (a `foxglove.RawImage`: `width`, `height`, `encoding`, `step` say how
    to read `data`) or the `foxglove.CompressedImage` format ("png", "jpeg")."""

    time_s: float
    format: str
    frame_id: str
    data: bytes
    width: int = 0
    height: int = 0
    encoding: str = ""
    step: int = 0

    def pixels(self) -> np.ndarray:
        from hamr_bench.recording.images import decode_image, decode_raw_image

        if self.format == "raw":
            return decode_raw_image(self.data, self.width, self.height, self.encoding, self.step)
        return decode_image(self.data)


@dataclass(frozen=True)
class Traffic:
    time_s: float
    direction: str
    data: bytes


class _Stream:
    __slots__ = ("log_times", "payloads", "chunk_offsets", "count")

    def __init__(self) -> None:
        self.log_times: list[int] = []
        self.payloads: list[bytes] = []
        self.chunk_offsets: list[int] = []
        self.count = 0


class RecordingReader:
    """Opens and scans `path` at once; raises RecordingError if it cannot be read."""

    def __init__(self, path: Path | str, validate_crcs: bool = True) -> None:
        self.path = Path(path)
        self.validate_crcs = validate_crcs
        self.status = ScanStatus()
        self._schemas: dict[int, SchemaRecord] = {}
        self._channels: dict[int, ChannelRecord] = {}
        self._metadata: dict[str, dict[str, str]] = {}
        self._streams: dict[int, _Stream] = {}
        self.orphan_messages = 0  # messages whose channel record was lost
        lazy: dict[int, bool] = {}
        for record in scan(self.path, "strict" if validate_crcs else "lenient", self.status):
            if isinstance(record, MessageRecord):
                stream = self._streams.get(record.channel_id)
                if stream is None:
                    if record.channel_id not in self._channels:
                        self.orphan_messages += 1
                        continue
                    stream = self._streams[record.channel_id] = _Stream()
                    lazy[record.channel_id] = self._schema_name(record.channel_id) in _LAZY_SCHEMAS
                stream.log_times.append(record.log_time)
                stream.count += 1
                if lazy[record.channel_id]:
                    if not stream.chunk_offsets or stream.chunk_offsets[-1] != record.chunk_offset:
                        stream.chunk_offsets.append(record.chunk_offset)
                else:
                    stream.payloads.append(record.data)
            elif isinstance(record, ChannelRecord):
                self._channels[record.id] = record
            elif isinstance(record, SchemaRecord):
                self._schemas[record.id] = record
            elif isinstance(record, MetadataRecord):
                self._metadata[record.name] = record.values
        self._by_topic = {c.topic: c for c in self._channels.values()}
        self.start_time_ns = self._start_time_ns()
        if self.partial:
            n = sum(s.count for s in self._streams.values())
            warnings.warn(
                f"{self.path}: {self.status.problem}; read {n} messages from the first {self.status.bytes_read} "
                f"of {self.status.file_size} bytes (the writer did not finish; `hamr-bench recover` makes a "
                "complete copy)",
                RecordingWarning,
                stacklevel=2,
            )

    # ------------------------------------------------------------------ whole-file facts

    @property
    def partial(self) -> bool:
        """True if the file had no valid footer/summary and was read up to its last complete record."""
        return not self.status.complete

    def metadata(self) -> dict[str, dict[str, str]]:
        return {name: dict(values) for name, values in self._metadata.items()}

    @property
    def exit_status(self) -> str | None:
        """'success' | 'aborted' | 'failed', or None if the run never recorded its end (killed writer)."""
        return self._metadata.get("run_end", {}).get("exit_status")

    @property
    def exit_reason(self) -> str | None:
        return self._metadata.get("run_end", {}).get("reason")

    def topics(self) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        for channel_id, channel in sorted(self._channels.items()):
            stream = self._streams.get(channel_id)
            count = stream.count if stream else 0
            first = last = None
            if stream and stream.log_times:
                first = self._to_time_s(min(stream.log_times))
                last = self._to_time_s(max(stream.log_times))
            out[channel.topic] = TopicInfo(channel.topic, self._schema_name(channel_id), count, first, last)
        return out

    def log_times_s(self, topic: str) -> np.ndarray:
        """MCAP log_time of each message on `topic`, as seconds since the run start."""
        stream = self._stream(topic)
        return (np.asarray(stream.log_times, dtype=np.int64) - self.start_time_ns) / 1e9

    # ------------------------------------------------------------------ streams

    def scalars(self, topic: str) -> dict[str, np.ndarray]:
        """{'time_s': ..., '<field>': ...} as float64 arrays, in file order, for a scalar topic."""
        channel = self._channel(topic)
        schema = self._schemas.get(channel.schema_id)
        fields = (
            schemas.scalar_fields_from_descriptor(schema.name, schema.data)
            if schema is not None and schema.encoding == "protobuf"
            else None
        )
        if fields is None:
            raise RecordingError(
                f"{self.path}: topic {topic} is not a scalar stream (schema {self._schema_name(channel.id)})"
            )
        payloads = self._streams[channel.id].payloads if channel.id in self._streams else []
        names = ("time_s", *fields)
        spec = schemas.ScalarSchema("", tuple(fields))
        # The fixed wire layout of a flat all-double message: tag byte then 8-byte double, per field.
        dtype = np.dtype([item for i, name in enumerate(names) for item in ((f"_tag{i}", "u1"), (name, "<f8"))])
        if all(len(p) == dtype.itemsize for p in payloads):
            packed = np.frombuffer(b"".join(payloads), dtype=dtype)
            tags_ok = all(np.all(packed[f"_tag{i}"] == tag) for i, tag in enumerate(spec.tags))
            if tags_ok:
                return {name: packed[name].astype(np.float64) for name in names}
        # Another writer may omit zero fields or order them differently: decode properly.
        cls = schemas.message_class(schema.name, schema.data)
        columns: dict[str, list[float]] = {name: [] for name in names}
        for payload in payloads:
            msg = self._parse(cls, payload, topic)
            for name in names:
                columns[name].append(getattr(msg, name))
        return {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}

    def events(self) -> list[Event]:
        if schemas.EVENTS_TOPIC not in self._by_topic:
            return []
        cls = self._message_class(schemas.EVENTS_TOPIC)
        out = []
        for payload in self._stream(schemas.EVENTS_TOPIC).payloads:
            msg = self._parse(cls, payload, schemas.EVENTS_TOPIC)
            try:
                data = json.loads(msg.data) if msg.data else {}
            except ValueError:
                raise RecordingError(
                    f"{self.path}: event {msg.kind!r} at step {msg.step} has data that is not JSON"
                ) from None
            out.append(Event(msg.time_s, int(msg.step), msg.kind, msg.message, data))
        return out

    def traffic(self, topic: str) -> list[Traffic]:
        cls = self._message_class(topic)
        return [
            Traffic(m.time_s, m.direction, bytes(m.data))
            for m in (self._parse(cls, p, topic) for p in self._stream(topic).payloads)
        ]

    def images(self, topic: str = "/camera/image") -> Iterator[Image]:
        """Frames in file order, read from disk chunk by chunk."""
        channel = self._channel(topic)
        schema_name = self._schema_name(channel.id)
        if schema_name not in schemas.IMAGE_SCHEMAS:
            raise RecordingError(
                f"{self.path}: topic {topic} is not an image stream ({' or '.join(schemas.IMAGE_SCHEMAS)}) but "
                f"{schema_name}"
            )
        raw = schema_name == schemas.RAW_IMAGE_SCHEMA
        cls = self._message_class(topic)
        stream = self._streams.get(channel.id)
        if stream is None:
            return
        for offset in stream.chunk_offsets:
            for record in read_chunk_messages(self.path, offset, self.validate_crcs):
                if record.channel_id != channel.id:
                    continue
                msg = self._parse(cls, record.data, topic)
                stamp_ns = msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos
                if raw:
                    yield Image(self._to_time_s(stamp_ns), "raw", msg.frame_id, bytes(msg.data), msg.width,
                                msg.height, msg.encoding, msg.step)
                else:
                    yield Image(self._to_time_s(stamp_ns), msg.format, msg.frame_id, bytes(msg.data))

    # ------------------------------------------------------------------ helpers

    def _start_time_ns(self) -> int:
        value = self._metadata.get("recording", {}).get("start_time_ns")
        if value is not None:
            try:
                return int(value)
            except ValueError:
                raise RecordingError(
                    f"{self.path}: metadata recording.start_time_ns={value!r} is not an integer"
                ) from None
        firsts = [min(s.log_times) for s in self._streams.values() if s.log_times]
        return min(firsts) if firsts else 0

    def _to_time_s(self, log_ns: int) -> float:
        return (log_ns - self.start_time_ns) / 1e9

    def _schema_name(self, channel_id: int) -> str:
        channel = self._channels.get(channel_id)
        schema = self._schemas.get(channel.schema_id) if channel else None
        return schema.name if schema else ""

    def _channel(self, topic: str) -> ChannelRecord:
        channel = self._by_topic.get(topic)
        if channel is None:
            known = ", ".join(sorted(self._by_topic)) or "none"
            raise RecordingError(f"{self.path} has no topic {topic} (topics: {known})")
        return channel

    def _stream(self, topic: str) -> _Stream:
        return self._streams.get(self._channel(topic).id) or _Stream()

    def _message_class(self, topic: str) -> Any:
        channel = self._channel(topic)
        schema = self._schemas.get(channel.schema_id)
        if schema is None or schema.encoding != "protobuf":
            raise RecordingError(f"{self.path}: topic {topic} has no protobuf schema")
        return schemas.message_class(schema.name, schema.data)

    def _parse(self, cls: Any, payload: bytes, topic: str) -> Any:
        try:
            return cls.FromString(payload)
        except Exception:  # protobuf's DecodeError and friends
            raise RecordingError(
                f"{self.path}: a message on {topic} does not decode as {cls.DESCRIPTOR.full_name}"
            ) from None
