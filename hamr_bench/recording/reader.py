"""Reading a hamr-bench recording back: metadata, topics, scalar streams as numpy arrays, events, images, traffic.

The whole data section is scanned once when the reader opens (validating every chunk CRC, the data-section CRC and
the summary CRC unless `validate_crcs=False`). Chunks whose message indexes check out are taken in per-channel
numpy blocks (`index_scan.py`), the others record by record; a `ChannelStream` keeps both kinds of block in file
order and joins them when asked, so both ways give the same answers. Scalars, events and traffic are kept in memory
(tens of MB for an hour at 10 kHz); images stay on disk and are fetched chunk by chunk when iterated. A file
without a footer (a killed writer) is read up to its last complete record with a `RecordingWarning`; a damaged
file raises `RecordingError` naming the file and the byte at fault.
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
from hamr_bench.recording.contract import MetadataName, Topic
from hamr_bench.recording.index_scan import (
    SMALL_CHUNK,
    BATCH_BYTES,
    ChunkCandidate,
    ChunkMessages,
    IndexBatch,
    check_small,
    scan_indexed,
    split_chunk,
    walk_chunk,
)
from hamr_bench.recording.channel_stream import ChannelStream
from hamr_bench.recording.scan import (
    ChannelRecord,
    MessageRecord,
    MetadataRecord,
    Policy,
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
    to read `data`) or the `foxglove.CompressedImage` format ("png", "jpeg"). `origin_px` is where the image's
    top-left pixel sits in the full frame: (0, 0) for a full frame, the region's corner for `/camera/roi`
    (from `/camera/roi/origin`; None if that sample is missing)."""

    time_s: float
    format: str
    frame_id: str
    data: bytes
    width: int = 0
    height: int = 0
    encoding: str = ""
    step: int = 0
    origin_px: tuple[int, int] | None = (0, 0)

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


class _Reread(Exception):
    """A chunk the index path could not take does not parse record by record either: read the file again the plain
    way, so that the outcome (error, or partial read) is exactly the plain scan's."""


class RecordingReader:
    """Opens and scans `path` at once; raises RecordingError if it cannot be read."""

    def __init__(self, path: Path | str, validate_crcs: bool = True, use_message_indexes: bool = True) -> None:
        """`use_message_indexes=False` reads every chunk record by record (the reference the indexed path is
        tested and benchmarked against); the results are the same either way."""
        self.path = Path(path)
        self.validate_crcs = validate_crcs
        self._reset()
        try:
            self._load(use_message_indexes)
        except _Reread:
            self._reset()
            self._load(False)
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

    # ------------------------------------------------------------------ loading

    def _reset(self) -> None:
        self.status = ScanStatus()
        self._schemas: dict[int, SchemaRecord] = {}
        self._channels: dict[int, ChannelRecord] = {}
        self._metadata: dict[str, dict[str, str]] = {}
        self._streams: dict[int, ChannelStream] = {}
        self.orphan_messages = 0  # messages whose channel record was lost
        self.chunks_indexed = 0  # chunks whose messages were taken through their message indexes

    def _load(self, indexed: bool) -> None:
        policy: Policy = "strict" if self.validate_crcs else "lenient"
        if not indexed:
            for record in scan(self.path, policy, self.status):
                self._take(record)
            return
        # Indexed chunks wait in `batch`; it is emptied, in file order, before anything that could change how a
        # later message is taken (a schema, a channel, a message outside the batch) and at the end.
        batch = IndexBatch()
        try:
            for item in scan_indexed(self.path, policy, self.status):
                if isinstance(item, ChunkCandidate):
                    self._add_chunk(batch, item)
                    continue
                if len(batch) and not isinstance(item, MetadataRecord):
                    self._drain(batch)
                self._take(item)
        except RecordingError:
            # The plain scan would have walked the waiting chunks before failing here: if one of them does not
            # pass, that walk might have failed first, with another message.
            if len(batch) and not batch.all_pass():
                raise _Reread from None
            raise
        if len(batch):
            self._drain(batch)

    def _add_chunk(self, batch: IndexBatch, chunk: ChunkCandidate) -> None:
        streams = [self._streams.get(channel_id) for channel_id in chunk.index_channels]
        if all(stream is not None for stream in streams):
            # Every channel already has a stream: taking this chunk later changes nothing in between.
            if chunk.count > SMALL_CHUNK or not all(stream.lazy for stream in streams):  # type: ignore[union-attr]
                batch.add(chunk)
                if batch.held_bytes > BATCH_BYTES:
                    self._drain(batch)
                return
            messages = check_small(chunk)
            if messages is not None:
                batch.add_checked(chunk.chunk_offset, messages)
                return
        if len(batch):
            self._drain(batch)
        self._take_chunk(chunk)

    def _drain(self, batch: IndexBatch) -> None:
        for kind, value in batch.take():
            if kind == "chunk":
                self._take_chunk(value)
                continue
            runs, chunks = value
            self.chunks_indexed += chunks
            for run in runs:
                stream = self._streams[run.channel_id]
                if stream.lazy:
                    stream.add_block(run.log_times, None)
                    offsets = run.chunk_offsets
                    for offset in offsets[np.concatenate(([True], offsets[1:] != offsets[:-1]))].tolist():
                        stream.add_chunk_offset(offset)
                else:
                    stream.add_block(run.log_times, run.payloads())

    def _take_chunk(self, chunk: ChunkCandidate) -> None:
        """One chunk on its own, in its place: through its indexes if they check out, else record by record."""
        records = split_chunk(chunk)
        if records is None:
            records = walk_chunk(chunk)
            if records is None:
                raise _Reread
        else:
            self.chunks_indexed += 1
        for record in records:
            self._take(record)

    def _take(self, record: object) -> None:
        if isinstance(record, MessageRecord):
            stream = self._streams.get(record.channel_id)
            if stream is None:
                if record.channel_id not in self._channels:
                    self.orphan_messages += 1
                    return
                stream = self._new_stream(record.channel_id)
            stream.add_record(record.log_time, record.data)
            if stream.lazy:
                stream.add_chunk_offset(record.chunk_offset)
        elif isinstance(record, ChunkMessages):
            for channel_id, log_times, starts, ends in record.channels:
                stream = self._streams.get(channel_id)
                if stream is None:
                    if channel_id not in self._channels:
                        self.orphan_messages += len(log_times)
                        continue
                    stream = self._new_stream(channel_id)
                if stream.lazy:
                    stream.add_block(log_times, None)
                    stream.add_chunk_offset(record.chunk_offset)
                else:
                    stream.add_block(log_times, record.payloads(starts, ends))
        elif isinstance(record, ChannelRecord):
            self._channels[record.id] = record
        elif isinstance(record, SchemaRecord):
            self._schemas[record.id] = record
        elif isinstance(record, MetadataRecord):
            self._metadata[record.name] = record.values

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
        return self._metadata.get(MetadataName.RUN_END, {}).get("exit_status")

    @property
    def exit_reason(self) -> str | None:
        return self._metadata.get(MetadataName.RUN_END, {}).get("reason")

    def topics(self) -> dict[str, TopicInfo]:
        out: dict[str, TopicInfo] = {}
        for channel_id, channel in sorted(self._channels.items()):
            stream = self._streams.get(channel_id)
            count = stream.count if stream else 0
            first = last = None
            span = stream.first_last_ns() if stream else None
            if span is not None:
                first = self._to_time_s(span[0])
                last = self._to_time_s(span[1])
            out[channel.topic] = TopicInfo(channel.topic, self._schema_name(channel_id), count, first, last)
        return out

    def log_times_s(self, topic: str) -> np.ndarray:
        """MCAP log_time of each message on `topic`, as seconds since the run start."""
        stream = self._stream(topic)
        return (stream.log_times() - self.start_time_ns) / 1e9

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
        if fields is None or schema is None:
            raise RecordingError(
                f"{self.path}: topic {topic} is not a scalar stream (schema {self._schema_name(channel.id)})"
            )
        stream = self._streams.get(channel.id) or ChannelStream()
        names = ("time_s", *fields)
        spec = schemas.ScalarSchema("", tuple(fields))
        # The fixed wire layout of a flat all-double message: tag byte then 8-byte double, per field.
        dtype = np.dtype([item for i, name in enumerate(names) for item in ((f"_tag{i}", "u1"), (name, "<f8"))])
        matrix = stream.payload_matrix(dtype.itemsize)
        if matrix is not None:
            packed = matrix.reshape(-1).view(dtype)
            tags_ok = all(np.all(packed[f"_tag{i}"] == tag) for i, tag in enumerate(spec.tags))
            if tags_ok:
                return {name: packed[name].astype(np.float64) for name in names}
        # Another writer may omit zero fields or order them differently: decode properly.
        cls = schemas.message_class(schema.name, schema.data)
        columns: dict[str, list[float]] = {name: [] for name in names}
        for payload in stream.payloads():
            msg = self._parse(cls, payload, topic)
            for name in names:
                columns[name].append(getattr(msg, name))
        return {name: np.asarray(values, dtype=np.float64) for name, values in columns.items()}

    def events(self) -> list[Event]:
        if Topic.EVENTS not in self._by_topic:
            return []
        cls = self._message_class(Topic.EVENTS, ("time_s", "step", "kind", "message", "data"))
        out = []
        for payload in self._stream(Topic.EVENTS).payloads():
            msg = self._parse(cls, payload, Topic.EVENTS)
            try:
                data = json.loads(msg.data) if msg.data else {}
            except ValueError:
                raise RecordingError(
                    f"{self.path}: event {msg.kind!r} at step {msg.step} has data that is not JSON"
                ) from None
            out.append(Event(msg.time_s, int(msg.step), msg.kind, msg.message, data))
        return out

    def traffic(self, topic: str) -> list[Traffic]:
        cls = self._message_class(topic, ("time_s", "direction", "data"))
        return [
            Traffic(m.time_s, m.direction, bytes(m.data))
            for m in (self._parse(cls, p, topic) for p in self._stream(topic).payloads())
        ]

    def images(self, topic: str = Topic.CAMERA_IMAGE) -> Iterator[Image]:
        """Frames in file order, read from disk chunk by chunk."""
        channel = self._channel(topic)
        schema_name = self._schema_name(channel.id)
        if schema_name not in schemas.IMAGE_SCHEMAS:
            raise RecordingError(
                f"{self.path}: topic {topic} is not an image stream ({' or '.join(schemas.IMAGE_SCHEMAS)}) but "
                f"{schema_name}"
            )
        raw = schema_name == schemas.RAW_IMAGE_SCHEMA
        cls = self._message_class(topic, ("timestamp", "frame_id", "data") + (
            ("width", "height", "encoding", "step") if raw else ("format",)))
        stamp = cls.DESCRIPTOR.fields_by_name["timestamp"].message_type
        if stamp is None or not {"seconds", "nanos"} <= set(stamp.fields_by_name):
            raise RecordingError(f"{self.path}: topic {topic}: its schema {schema_name} has no timestamp seconds "
                                 "and nanos")
        stream = self._streams.get(channel.id)
        if stream is None:
            return
        origins = self._region_origins(topic)
        for offset in stream.chunk_offsets:
            for record in read_chunk_messages(self.path, offset, self.validate_crcs):
                if record.channel_id != channel.id:
                    continue
                msg = self._parse(cls, record.data, topic)
                stamp_ns = msg.timestamp.seconds * 1_000_000_000 + msg.timestamp.nanos
                origin = (0, 0) if origins is None else origins.get(record.log_time)
                if raw:
                    yield Image(self._to_time_s(stamp_ns), "raw", msg.frame_id, bytes(msg.data), msg.width,
                                msg.height, msg.encoding, msg.step, origin)
                else:
                    yield Image(self._to_time_s(stamp_ns), msg.format, msg.frame_id, bytes(msg.data),
                                origin_px=origin)

    def _region_origins(self, topic: str) -> dict[int, tuple[int, int]] | None:
        """log time -> (x0, y0) of a region-of-interest topic's frames (its `<topic>/origin` stream, written at
        the frame's own time), or None for a topic of full frames."""
        origin_topic = f"{topic}/origin"
        if origin_topic not in self._by_topic:
            return None
        corners = self.scalars(origin_topic)
        log_ns = self._stream(origin_topic).log_times()
        return {int(t): (int(x), int(y)) for t, x, y in zip(log_ns, corners["x0_px"], corners["y0_px"],
                                                                     strict=True)}

    # ------------------------------------------------------------------ helpers

    def _start_time_ns(self) -> int:
        value = self._metadata.get(MetadataName.RECORDING, {}).get("start_time_ns")
        if value is not None:
            try:
                return int(value)
            except ValueError:
                raise RecordingError(
                    f"{self.path}: metadata recording.start_time_ns={value!r} is not an integer"
                ) from None
        spans = [span for s in self._streams.values() if (span := s.first_last_ns()) is not None]
        return min(first for first, _ in spans) if spans else 0

    def _to_time_s(self, log_ns: int) -> float:
        return (log_ns - self.start_time_ns) / 1e9

    def _new_stream(self, channel_id: int) -> ChannelStream:
        # Lazy or not is decided by the schema known at the channel's first message, as it always was.
        stream = self._streams[channel_id] = ChannelStream(self._schema_name(channel_id) in _LAZY_SCHEMAS)
        return stream

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

    def _stream(self, topic: str) -> ChannelStream:
        return self._streams.get(self._channel(topic).id) or ChannelStream()

    def _message_class(self, topic: str, fields: tuple[str, ...] = ()) -> Any:
        """The topic's message class from the schema stored in the file, which must hold `fields` (the schema
        record carries no checksum: a damaged or foreign one can decode with other field names)."""
        channel = self._channel(topic)
        schema = self._schemas.get(channel.schema_id)
        if schema is None or schema.encoding != "protobuf":
            raise RecordingError(f"{self.path}: topic {topic} has no protobuf schema")
        cls = schemas.message_class(schema.name, schema.data)
        missing = [f for f in fields if f not in cls.DESCRIPTOR.fields_by_name]
        if missing:
            raise RecordingError(f"{self.path}: topic {topic}: its schema {schema.name} has no field "
                                 f"{', '.join(missing)}")
        return cls

    def _parse(self, cls: Any, payload: bytes, topic: str) -> Any:
        try:
            return cls.FromString(payload)
        except Exception:  # protobuf's DecodeError and friends
            raise RecordingError(
                f"{self.path}: a message on {topic} does not decode as {cls.DESCRIPTOR.full_name}"
            ) from None
