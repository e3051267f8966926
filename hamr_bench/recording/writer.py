"""The run recorder: one MCAP file per run, written by a single writer thread fed through a queue.

Callers (the runner's acquisition loop, a camera thread, the importer) only encode and enqueue, which costs a
microsecond or so per scalar sample; the writer thread owns the `McapFileWriter` (mcap_file.py; it has no locks)
and the file.

Crash safety: the writer thread closes the open chunk, flushes and `os.fsync`s at least every `flush_interval_s`
of wall time (not rig time: under the virtual clock an hour-long protocol runs in seconds, and durability is about
the disk, not the simulation), so a SIGKILL loses at most that much plus what the reorder window holds (below).
Metadata is written and fsynced before `add_metadata` returns. `recover()` turns the output of a killed writer
into a finished file.

Time: `time_s` is seconds on the rig clock since the run start. Each message carries it in a field, and its MCAP
log_time is `start_time_ns + time_s` in ns. log_time never decreases within a channel: a sample whose time is
earlier than its channel's previous one (or NaN) keeps its own time in the field but gets the previous log_time,
and is counted in `run_end`'s `out_of_order_by_topic`. Across channels, the writer thread puts messages back in
log-time order within `reorder_window_s` of rig time (reorder.py), so log times never decrease in file order; a
message later than that is logged at the file's latest log time and counted in `late_by_topic`.

Overflow: the queue is bounded (messages and image bytes). With `when_full="drop"` (the default, for real-time
callers that must never stall) a sample that does not fit is dropped, counted per topic, reported by `stats()` and
recorded in `run_end`; nothing is dropped silently. With `when_full="block"` (offline writers: importer, replay)
the caller waits for room instead.

Camera frames of `/camera/image` are kept as `camera` (a `CameraStorage`, camera_storage.py) says: by default
the region around the marker every frame and a full frame once a second, in compressed chunks. Frames kept whole
(`full`, `png`, or any other image topic) fill chunks that are written uncompressed (camera noise compresses badly
for its CPU cost, docs/performance.md); `compress_images=True` compresses them like the rest.

Taps (tap.py; the live view) are told of every channel and message beside the queue: they never stand between a
producer and the file.
"""

from __future__ import annotations

import atexit
import json
import math
import os
import queue
import struct
import threading
import time
from collections import Counter
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.errors import RecordingError
from hamr_bench.recording import event_topics, schemas
from hamr_bench.recording.camera_storage import CameraStorage, FramePlanner, marker_annotation_payload
from hamr_bench.recording.contract import TRAFFIC_PREFIX, EventKind, MetadataName, Topic
from hamr_bench.recording.image_payloads import compressed_image_payload, raw_image_payload
from hamr_bench.recording.images import encode_image, raw_image_fields
from hamr_bench.recording.mcap_file import McapFileWriter
from hamr_bench.recording.reorder import ReorderStage
from hamr_bench.recording.tap import RecorderTap, TapChannel
import contextlib

EXIT_STATUSES = ("success", "aborted", "failed")
FORMAT_NAME = "hamr-bench-recording"
FORMAT_VERSION = "2"
COMPRESSIONS = ("lz4", "zstd", "none")
# Rig time a message may arrive after a later one and still be written in order: 0.2-0.3 s measured on most
# protocols of the simulated bench; force samples that pile up while a stage move blocks reach 0.5-0.9 s (those
# are logged late and counted, docs/log-format.md "Time"). Held messages are not on disk yet, so window + flush
# interval is the crash window; 0.5 + 0.25 s keeps it under the 1 s the format promises.
DEFAULT_REORDER_WINDOW_S = 0.5
DEFAULT_FLUSH_INTERVAL_S = 0.25
_REORDER_MAX_BYTES = 64 * 1024 * 1024  # held frames beyond this are written at once (order kept as far as it can)
_MARKER_DIAMETER_PX = 12.0

# Writer-thread operations; data items use a channel index >= 0 in the same position.
_OP_REGISTER, _OP_METADATA, _OP_FLUSH, _OP_CLOSE = -1, -2, -3, -4
_DRAIN_BATCH = 2048  # items handled between two looks at the flush deadline
_IDLE_POLL_S = 0.02  # how long the writer thread waits when its queue is empty (latency, not durability)
_MAX_LOG_NS = 2**63 - 1
# How long a caller waits for the writer thread to confirm metadata / flush / close before giving up.
_WRITER_CONFIRM_TIMEOUT_S = 60.0


@dataclass(frozen=True)
class RecorderStats:
    """Counts per topic so far: written by the writer thread, dropped on a full queue, log_time clamped within the
    topic (out_of_order) or across topics (late)."""

    written: dict[str, int] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    out_of_order: dict[str, int] = field(default_factory=dict)
    late: dict[str, int] = field(default_factory=dict)  # logged later than their own time (reorder window passed)

    @property
    def dropped_total(self) -> int:
        return sum(self.dropped.values())


@dataclass
class _Channel:
    """Producer-side view of a channel (immutable after registration)."""

    index: int
    topic: str
    schema: schemas.ScalarSchema | None
    is_image: bool = False
    pack: Any = None  # scalar channels: (time_s, fields) -> payload bytes
    schema_name: str = ""
    stored: bool = False  # its messages fill uncompressed chunks (frames kept whole)


def _one_line(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    raise TypeError(f"{type(value).__name__} is not JSON serialisable")


class Recorder:
    """Writes one run to an MCAP file. See docs/log-format.md for what lands in the file."""

    def __init__(
        self,
        path: Path | str,
        *,
        overwrite: bool = False,
        flush_interval_s: float = DEFAULT_FLUSH_INTERVAL_S,
        chunk_size: int = 256 * 1024,
        start_time_ns: int | None = None,
        compression: str = "lz4",
        max_queue_messages: int = 500_000,
        max_queue_bytes: int = 256 * 1024 * 1024,
        when_full: str = "drop",
        compress_images: bool = False,
        camera: CameraStorage | None = None,
        reorder_window_s: float = DEFAULT_REORDER_WINDOW_S,
    ) -> None:
        self.path = Path(path)
        if not 0 < flush_interval_s <= 1.0:
            raise RecordingError(f"flush_interval_s={flush_interval_s} must be in (0, 1] s")
        if when_full not in ("drop", "block"):
            raise RecordingError(f"when_full={when_full!r} must be 'drop' (real-time callers) or 'block' (offline)")
        if compression not in COMPRESSIONS:
            raise RecordingError(f"compression={compression!r} must be one of {', '.join(COMPRESSIONS)}")
        if not (math.isfinite(reorder_window_s) and 0 <= reorder_window_s <= 1.0):
            raise RecordingError(f"reorder_window_s={reorder_window_s!r} must be in [0, 1] s (the crash window)")
        self.camera = camera or CameraStorage()
        self.reorder_window_s = float(reorder_window_s)
        self.start_time_ns = int(time.time_ns() if start_time_ns is None else start_time_ns)
        self.flush_interval_s = float(flush_interval_s)
        self._max_queue_messages = int(max_queue_messages)
        self._max_queue_bytes = int(max_queue_bytes)
        self._block_when_full = when_full == "block"
        try:
            self._file = open(self.path, "wb" if overwrite else "xb")
        except FileExistsError:
            raise RecordingError(f"{self.path} already exists; use --force to overwrite it") from None
        except OSError as exc:
            raise RecordingError(f"cannot create recording {self.path}: {exc.strerror or exc}") from None
        _fsync_directory(self.path.parent)
        self._writer = McapFileWriter(self._file, chunk_size=int(chunk_size),
                                      compression="" if compression == "none" else compression)
        from hamr_bench import __version__

        self._writer.start(profile="", library=f"hamr-bench {__version__}")
        # Frames kept whole go in chunks written uncompressed, unless asked otherwise (see the module docstring).
        self._store_images = not compress_images and compression != "none"
        self._frames = FramePlanner(self.camera, Topic.CAMERA_IMAGE, Topic.CAMERA_ROI)
        self._taps: list[RecorderTap] = []
        self._tap_channels: list[TapChannel] = []

        # Producer side (any thread).
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._wake = threading.Event()  # set for operations a caller waits on
        self._space = threading.Event()  # set by the writer after draining (when_full='block' waits on it)
        self._lock = threading.Lock()  # registration, drop counts, image byte accounting
        self._channels: dict[str, _Channel] = {}
        self._dropped: Counter[str] = Counter()
        self._queued_image_bytes = 0
        self._closed = False  # no more writes accepted
        self._close_stats: RecorderStats | None = None

        # Writer-thread side, indexed by channel index.
        self._w_channel_ids: list[int] = []
        self._w_topics: list[str] = []
        self._w_is_image: list[bool] = []
        self._w_last_log: list[int] = []
        self._w_written: list[int] = []
        self._w_out_of_order: list[int] = []
        self._w_stored: list[bool] = []
        self._w_schema_ids: dict[str, int] = {}
        self._failure: BaseException | None = None
        self._reorder = ReorderStage(self._write_ordered, lambda: len(self._w_topics),
                                     window_ns=round(self.reorder_window_s * 1e9),
                                     idle_release_s=max(self.reorder_window_s, 0.05), max_bytes=_REORDER_MAX_BYTES)

        self._thread = threading.Thread(target=self._run, name=f"recorder:{self.path.name}", daemon=True)
        self._thread.start()
        start_utc = datetime.fromtimestamp(self.start_time_ns / 1e9, tz=UTC).isoformat()
        try:
            self.add_metadata(
                MetadataName.RECORDING,
                {
                    "format": FORMAT_NAME,
                    "format_version": FORMAT_VERSION,
                    "start_time_ns": str(self.start_time_ns),
                    "start_time_utc": start_utc,
                    "flush_interval_s": repr(self.flush_interval_s),
                    "chunk_size": str(int(chunk_size)),
                    "compression": compression,
                    "reorder_window_s": repr(self.reorder_window_s),
                    "camera_storage": self.camera.describe(),
                },
            )
        except RecordingError:
            self._closed = True  # the writer thread has stopped; nothing more to finish
            raise
        atexit.register(self._close_at_exit)

    # ------------------------------------------------------------------ producer API

    def add_metadata(self, name: str, values: dict[str, str]) -> None:
        """Write a metadata record now (flushed and fsynced before this returns)."""
        if not isinstance(name, str) or not name:
            raise RecordingError(f"metadata name {name!r} must be a non-empty string")
        for key, value in values.items():
            if not isinstance(key, str) or not isinstance(value, str):
                raise RecordingError(f"metadata {name}: key {key!r} and its value must both be strings")
        self._check_open()
        done = threading.Event()
        self._queue.put((_OP_METADATA, None, (name, dict(values), done)))
        self._wake.set()
        self._wait_for_writer(done, f"metadata {name}")

    def write_scalar(self, topic: str, time_s: float, **fields: float) -> None:
        """One sample of a scalar stream, e.g. `write_scalar("/force", t, force_N=0.01)`."""
        channel = self._channels.get(topic)
        if channel is None:
            channel = self._register_scalar(topic, tuple(fields))
        try:
            payload = channel.pack(time_s, fields)
        except (KeyError, TypeError, ValueError, OverflowError, struct.error):
            schema = channel.schema
            if schema is None:
                raise RecordingError(f"topic {topic} carries images, events or traffic, not scalars") from None
            raise RecordingError(
                f"topic {topic}: expected time_s and a number for each of {', '.join(schema.fields)}; "
                f"got time_s={time_s!r}, {', '.join(f'{k}={v!r}' for k, v in fields.items()) or 'no fields'}"
            ) from None
        self._put(channel, time_s, payload)

    def write_event(self, time_s: float, kind: str, step: int, message: str = "", **data: Any) -> None:
        """A protocol event on /events (`data` stored as a JSON object), the same as a `foxglove.Log` line on /log,
        and for a `step` event its condition as typed fields on /step (event_topics.py)."""
        channel = self._channels.get(Topic.EVENTS) or self._register_special(
            Topic.EVENTS, schemas.EVENT_SCHEMA, schemas.event_descriptor_set(), ("time_s",)
        )
        try:
            data_json = json.dumps(data, sort_keys=True, default=_json_default)
        except (TypeError, ValueError) as exc:
            raise RecordingError(f"event {kind!r} at step {step}: data is not JSON serialisable ({exc})") from None
        cls = schemas.message_class(schemas.EVENT_SCHEMA, schemas.event_descriptor_set())
        try:
            payload = cls(
                time_s=float(time_s), step=int(step), kind=str(kind), message=str(message), data=data_json
            ).SerializeToString()
            timestamp_ns = self.start_time_ns + (round(float(time_s) * 1e9) if math.isfinite(time_s) else 0)
        except (TypeError, ValueError, OverflowError) as exc:
            raise RecordingError(f"event {kind!r}: bad time_s={time_s!r} or step={step!r} ({exc})") from None
        self._put(channel, time_s, payload)
        plain = json.loads(data_json)  # the values as stored (numpy scalars made plain)
        log = self._channels.get(Topic.LOG) or self._register_special(
            Topic.LOG, schemas.LOG_SCHEMA, schemas.log_descriptor_set(), ())
        self._put(log, time_s, event_topics.log_payload(timestamp_ns, str(kind), int(step), str(message), plain))
        if kind == EventKind.STEP:
            step_channel = self._channels.get(Topic.STEP) or self._register_special(
                Topic.STEP, schemas.STEP_SCHEMA, schemas.step_descriptor_set(),
                tuple(name for name, _ in schemas.STEP_FIELDS))
            self._put(step_channel, time_s, event_topics.step_payload(time_s, int(step), str(message), plain))

    def write_image(
        self,
        topic: str,
        time_s: float,
        image: np.ndarray | bytes,
        format: str = "raw",  # noqa: A002 - the field is called `format` in foxglove.CompressedImage
        frame_id: str = "camera",
        marker_px: tuple[float, float] | None = None,
    ) -> None:
        """A camera frame. `format="raw"` (default): the array as `foxglove.RawImage` (mono8/mono16/bgr8/bgr16),
        no encoding cost. `"png"` (lossless) or `"jpeg"`: as `foxglove.CompressedImage`, arrays encoded here,
        bytes taken as already encoded. A topic carries one of the two schemas. A raw frame of the camera
        (`/camera/image`) is kept as the recorder's `camera` storage says, around `marker_px` (the marker tracked
        in this frame, full-frame pixels) when given; the marker is also drawn on /camera/annotations."""
        schemas.check_topic(topic)
        try:
            finite = math.isfinite(time_s)
        except TypeError:
            finite = False
        if not finite:
            raise RecordingError(f"topic {topic}: image time_s={time_s!r} is not a finite time")
        if topic == Topic.CAMERA_IMAGE and format == "raw" and isinstance(image, np.ndarray):
            self._write_camera_frame(time_s, image, frame_id, marker_px)
        else:
            self._write_one_image(topic, time_s, image, format, frame_id, self._store_images)

    def _write_camera_frame(self, time_s: float, image: np.ndarray, frame_id: str,
                            marker_px: tuple[float, float] | None) -> None:
        writes, origin = self._frames.plan(time_s, image, marker_px)
        kept_whole = False
        for w in writes:
            self._write_one_image(w.topic, time_s, w.image, w.format, frame_id, w.stored and self._store_images)
            kept_whole = kept_whole or w.topic == Topic.CAMERA_IMAGE
        if origin is not None:
            self.write_scalar(Topic.CAMERA_ROI_ORIGIN, time_s, x0_px=float(origin[0]), y0_px=float(origin[1]))
        timestamp_ns = self.start_time_ns + round(time_s * 1e9)
        if marker_px is not None and math.isfinite(marker_px[0]) and math.isfinite(marker_px[1]):
            channel = self._channels.get(Topic.CAMERA_ANNOTATIONS) or self._register_special(
                Topic.CAMERA_ANNOTATIONS, schemas.ANNOTATIONS_SCHEMA, schemas.annotations_descriptor_set(), ())
            self._put(channel, time_s, marker_annotation_payload(timestamp_ns, marker_px, _MARKER_DIAMETER_PX))
        if not kept_whole and self._taps:
            # The live view may still want the whole frame (at its own, lower rate): built only if one asks.
            for tap in list(self._taps):
                try:
                    if tap.wants_frame(time_s):
                        tap.frame(time_s, raw_image_payload(timestamp_ns, frame_id, *raw_image_fields(image)))
                except Exception:  # noqa: BLE001 - a failing tap is dropped; the recording goes on
                    self._drop_tap(tap)

    def _write_one_image(self, topic: str, time_s: float, image: np.ndarray | bytes, format: str,  # noqa: A002
                         frame_id: str, stored: bool) -> None:
        raw = format == "raw"
        schema_name = schemas.RAW_IMAGE_SCHEMA if raw else schemas.IMAGE_SCHEMA
        channel = self._channels.get(topic) or self._register_special(
            topic, schema_name, schemas.raw_image_descriptor_set() if raw else schemas.image_descriptor_set(),
            (), is_image=True, stored=stored,
        )
        if not channel.is_image:
            raise RecordingError(f"topic {topic} already carries another message type, not images")
        if channel.schema_name != schema_name:
            raise RecordingError(f"topic {topic} carries {channel.schema_name}; format={format!r} would need "
                                 f"{schema_name} (one schema per topic)")
        timestamp_ns = self.start_time_ns + round(time_s * 1e9)
        if raw:
            if not isinstance(image, np.ndarray):
                raise RecordingError(f"topic {topic}: format='raw' needs a numpy array, not {type(image).__name__}")
            self._put(channel, time_s, raw_image_payload(timestamp_ns, frame_id, *raw_image_fields(image)))
            return
        if isinstance(image, np.ndarray):
            data = encode_image(image, format)
        elif isinstance(image, (bytes, bytearray, memoryview)):
            data = bytes(image)
        else:
            raise RecordingError(f"topic {topic}: image must be a numpy array or bytes, not {type(image).__name__}")
        image_format = "jpeg" if format == "jpg" else format
        try:
            payload = compressed_image_payload(timestamp_ns, frame_id, image_format, data)
        except (TypeError, ValueError, OverflowError):  # odd inputs: let protobuf encode (or refuse) them
            from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

            msg = CompressedImage(frame_id=frame_id, format=image_format, data=data)
            msg.timestamp.FromNanoseconds(timestamp_ns)
            payload = msg.SerializeToString()
        self._put(channel, time_s, payload)

    def write_bytes(self, topic: str, time_s: float, direction: str, data: bytes) -> None:
        """Raw serial traffic of one device on `/traffic/<device>`; direction 'tx' (to device) or 'rx'."""
        if not topic.startswith(TRAFFIC_PREFIX):
            raise RecordingError(f"traffic topic {topic!r} must start with {TRAFFIC_PREFIX}")
        if direction not in ("tx", "rx"):
            raise RecordingError(f"topic {topic}: direction {direction!r} must be 'tx' or 'rx'")
        schemas.check_topic(topic)
        channel = self._channels.get(topic) or self._register_special(
            topic, schemas.TRAFFIC_SCHEMA, schemas.traffic_descriptor_set(), ("time_s",)
        )
        cls = schemas.message_class(schemas.TRAFFIC_SCHEMA, schemas.traffic_descriptor_set())
        try:
            payload = cls(time_s=float(time_s), direction=direction, data=bytes(data)).SerializeToString()
        except (TypeError, ValueError) as exc:
            raise RecordingError(f"topic {topic}: bad time_s={time_s!r} or data ({exc})") from None
        self._put(channel, time_s, payload)

    def flush(self) -> None:
        """Block until everything queued so far is on disk (fsynced)."""
        self._check_open()
        done = threading.Event()
        self._queue.put((_OP_FLUSH, None, done))
        self._wake.set()
        self._wait_for_writer(done, "flush")

    def stats(self) -> RecorderStats:
        if self._close_stats is not None:
            return self._close_stats
        return self._collect_stats()

    def close(self, exit_status: str, reason: str = "") -> RecorderStats:
        """Write the `run_end` record and finish the file. Idempotent: later calls return the same stats.
        Stop every producer first: writes racing with close are refused or may be lost."""
        if exit_status not in EXIT_STATUSES:
            raise ValueError(f"exit_status {exit_status!r} must be one of {EXIT_STATUSES}")
        with self._lock:
            if self._closed:
                already = True
            else:
                already = False
                self._closed = True
        if already:
            self._thread.join(_WRITER_CONFIRM_TIMEOUT_S)
            if self._close_stats is None:
                raise RecordingError(f"recording {self.path} could not be finished ({self._failure_text()})")
            return self._close_stats
        atexit.unregister(self._close_at_exit)
        done = threading.Event()
        self._queue.put((_OP_CLOSE, None, (exit_status, str(reason), done)))
        self._wake.set()
        self._wait_for_writer(done, "close")
        self._thread.join(_WRITER_CONFIRM_TIMEOUT_S)
        assert self._close_stats is not None
        return self._close_stats

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: Any) -> None:
        if self._closed:
            return
        if exc is None:
            self.close("success")
        elif isinstance(exc, KeyboardInterrupt):
            self._close_quietly("aborted", "interrupted (Ctrl-C)")
        else:
            self._close_quietly("failed", _one_line(exc))

    # ------------------------------------------------------------------ producer internals

    def _check_open(self) -> None:
        if self._failure is not None:
            raise RecordingError(f"recording {self.path} failed: {self._failure_text()}")
        if self._closed:
            raise RecordingError(f"recording {self.path} is already closed")

    def _failure_text(self) -> str:
        exc = self._failure
        if exc is None:
            return "writer thread stopped"
        if isinstance(exc, OSError):
            return exc.strerror or str(exc)
        return _one_line(exc)

    def _put(self, channel: _Channel, time_s: float, payload: bytes) -> None:
        if self._closed or self._failure is not None:
            self._check_open()
        if channel.is_image:
            with self._lock:
                fits = self._image_fits(len(payload))
                if fits:
                    self._queued_image_bytes += len(payload)
        else:
            fits = self._queue.qsize() < self._max_queue_messages
        if not fits:
            if not self._block_when_full:
                with self._lock:
                    self._dropped[channel.topic] += 1
                return
            self._wait_for_space(channel, len(payload))
        self._queue.put((channel.index, time_s, payload))
        if self._taps:
            # Beside the queue, after it: the message is already on its way to the file whatever a tap does.
            for tap in self._taps:
                try:
                    tap.message(channel.index, time_s, payload)
                except Exception:  # noqa: BLE001 - a failing tap is dropped; the recording goes on
                    self._drop_tap(tap)

    def add_tap(self, tap: RecorderTap) -> None:
        """Tell `tap` (the live view) of every channel so far and from now on, and of every message queued from
        now on (tap.py)."""
        with self._lock:
            known = list(self._tap_channels)
            self._taps = [*self._taps, tap]
        for channel in known:
            tap.channel(channel)

    def remove_tap(self, tap: RecorderTap) -> None:
        with self._lock:
            self._taps = [t for t in self._taps if t is not tap]

    def _drop_tap(self, tap: RecorderTap) -> None:
        import warnings

        self.remove_tap(tap)
        warnings.warn(f"recording {self.path}: a tap failed and was removed (the recording goes on)", stacklevel=3)

    def _image_fits(self, size: int) -> bool:
        # An image larger than the whole budget still goes in when nothing else is queued (block mode only).
        return self._queued_image_bytes + size <= self._max_queue_bytes or (
            self._block_when_full and self._queued_image_bytes == 0
        )

    def _wait_for_space(self, channel: _Channel, size: int) -> None:
        """when_full='block': wait until the writer has made room (offline writers such as the importer)."""
        while True:
            self._space.clear()
            if channel.is_image:
                with self._lock:
                    if self._image_fits(size):
                        self._queued_image_bytes += size
                        return
            elif self._queue.qsize() < self._max_queue_messages:
                return
            if not self._thread.is_alive():
                self._check_open()
                raise RecordingError(f"recording {self.path}: writer stopped ({self._failure_text()})")
            self._wake.set()  # the writer may be idling between polls: there is work now
            self._space.wait(0.05)

    def _register_scalar(self, topic: str, field_names: tuple[str, ...]) -> _Channel:
        schema = schemas.scalar_schema_for(topic, field_names)
        return self._register(topic, schema.name, schema.descriptor_set(), schema.all_fields, scalar=schema)

    def _register_special(self, topic: str, schema_name: str, data: bytes, unit_fields: tuple[str, ...],
                          is_image: bool = False, stored: bool = False) -> _Channel:
        return self._register(topic, schema_name, data, unit_fields, is_image=is_image, stored=stored)

    def _register(
        self,
        topic: str,
        schema_name: str,
        descriptor_set: bytes,
        unit_fields: tuple[str, ...],
        scalar: schemas.ScalarSchema | None = None,
        is_image: bool = False,
        stored: bool = False,
    ) -> _Channel:
        self._check_open()
        with self._lock:
            existing = self._channels.get(topic)
            if existing is not None:
                return existing
            if scalar is None and topic in schemas.KNOWN_SCALAR_TOPICS:
                raise RecordingError(f"topic {topic} is a scalar topic; write it with write_scalar")
            channel = _Channel(
                len(self._channels), topic, scalar, is_image, scalar.packer() if scalar is not None else None,
                schema_name, stored,
            )
            metadata = schemas.units_metadata(unit_fields)
            # Put under the lock so the registration reaches the writer before any sample of this channel.
            self._queue.put((_OP_REGISTER, None, (topic, schema_name, descriptor_set, metadata, is_image, stored)))
            self._channels[topic] = channel
            tap_channel = TapChannel(channel.index, topic, schema_name, descriptor_set, metadata, is_image)
            self._tap_channels.append(tap_channel)
            taps = list(self._taps)
        for tap in taps:
            try:
                tap.channel(tap_channel)
            except Exception:  # noqa: BLE001 - a failing tap is dropped; the recording goes on
                self._drop_tap(tap)
        return channel

    def _wait_for_writer(self, done: threading.Event, what: str) -> None:
        """Wait until the writer thread has done `what`; give up if it died, or if it made no progress for
        _WRITER_CONFIRM_TIMEOUT_S (a hung disk), never while it is still working through a backlog."""
        progress = sum(self._w_written)
        deadline = time.monotonic() + _WRITER_CONFIRM_TIMEOUT_S
        while not done.wait(0.1):
            # The thread ends right after confirming a close: only a dead thread with `done` unset has failed.
            if not self._thread.is_alive() and not done.is_set():
                raise RecordingError(f"recording {self.path}: writer stopped before {what} ({self._failure_text()})")
            now_progress = sum(self._w_written)
            if now_progress != progress:
                progress, deadline = now_progress, time.monotonic() + _WRITER_CONFIRM_TIMEOUT_S
            elif time.monotonic() > deadline:
                raise RecordingError(
                    f"recording {self.path}: writer made no progress for {_WRITER_CONFIRM_TIMEOUT_S:.0f} s "
                    f"while waiting for {what}"
                )
        if self._failure is not None:
            raise RecordingError(f"recording {self.path} failed: {self._failure_text()}")

    def _collect_stats(self) -> RecorderStats:
        with self._lock:
            dropped = {k: v for k, v in self._dropped.items() if v}
        topics = list(self._w_topics)
        return RecorderStats(
            written={t: self._w_written[i] for i, t in enumerate(topics)},
            dropped=dropped,
            out_of_order={t: self._w_out_of_order[i] for i, t in enumerate(topics) if self._w_out_of_order[i]},
            late={topics[i]: n for i, n in enumerate(list(self._reorder.late)) if n and i < len(topics)},
        )

    def _close_quietly(self, exit_status: str, reason: str) -> None:
        try:
            self.close(exit_status, reason)
        except RecordingError as exc:
            import warnings

            warnings.warn(f"recording {self.path} could not be closed: {exc}", stacklevel=3)

    def _close_at_exit(self) -> None:
        if not self._closed:
            self._close_quietly("failed", "recorder not closed before the program exited")

    # ------------------------------------------------------------------ writer thread

    def _run(self) -> None:
        try:
            self._loop()
        except BaseException as exc:  # the producer side reports it; the file stays recoverable
            self._failure = exc
            try:
                self._file.flush()
                os.fsync(self._file.fileno())
            except (OSError, ValueError):
                pass
            with contextlib.suppress(OSError, ValueError):
                self._file.close()

    def _loop(self) -> None:
        q = self._queue
        start_ns = self.start_time_ns
        last_log = self._w_last_log
        out_of_order = self._w_out_of_order
        is_image = self._w_is_image
        push = self._reorder.push
        interval = self.flush_interval_s
        next_flush = time.monotonic() + interval
        dirty = False
        wake = self._wake
        while True:
            try:
                item = q.get_nowait()
            except queue.Empty:
                # Producers do not signal each sample: waking per sample (a futex and a GIL hand-over each time)
                # cost more CPU than writing it. Poll every _IDLE_POLL_S instead; operations callers wait for
                # (metadata, flush, close) set `wake` so they are handled at once.
                self._reorder.release()  # producers silent: what the window holds goes out after a while
                timeout = min(_IDLE_POLL_S, next_flush - time.monotonic())
                if timeout > 0:
                    wake.wait(timeout)
                wake.clear()
                item = None
                try:  # not contextlib.suppress: the writer thread's loop, a context manager every pass
                    item = q.get_nowait()
                except queue.Empty:
                    pass
            handled = 0
            while item is not None:
                index, time_s, payload = item
                if index >= 0:
                    try:
                        log_ns = start_ns + round(time_s * 1e9)
                    except (ValueError, OverflowError, TypeError):
                        log_ns = -1  # NaN / inf time: clamp below
                    previous = last_log[index]
                    if log_ns < previous or log_ns > _MAX_LOG_NS:
                        log_ns = previous
                        out_of_order[index] += 1
                    else:
                        last_log[index] = log_ns
                    push(log_ns, index, payload)
                    if is_image[index]:
                        with self._lock:
                            self._queued_image_bytes -= len(payload)
                    dirty = True
                elif self._control(index, payload):
                    return
                handled += 1
                if handled >= _DRAIN_BATCH:
                    break
                try:
                    item = q.get_nowait()
                except queue.Empty:
                    item = None
            if handled:
                self._reorder.release()
                if self._block_when_full:
                    self._space.set()
            if time.monotonic() >= next_flush:
                if dirty:
                    self._sync()
                    dirty = False
                next_flush = time.monotonic() + interval

    def _write_ordered(self, index: int, log_ns: int, payload: bytes) -> None:
        """The reorder stage's output: one message into the file, in log-time order."""
        self._writer.add_message(self._w_channel_ids[index], log_ns, payload, log_ns, 0, self._w_stored[index])
        self._w_written[index] += 1

    def _sync(self) -> None:
        self._writer.flush()
        os.fsync(self._file.fileno())

    def _control(self, op: int, arg: Any) -> bool:
        """Handle a writer operation; True when the file is finished."""
        if op == _OP_REGISTER:
            topic, schema_name, descriptor_set, metadata, image, stored = arg
            schema_id = self._w_schema_ids.get(schema_name)
            if schema_id is None:
                schema_id = self._writer.register_schema(schema_name, "protobuf", descriptor_set)
                self._w_schema_ids[schema_name] = schema_id
            self._w_channel_ids.append(self._writer.register_channel(topic, "protobuf", schema_id, metadata))
            self._w_topics.append(topic)
            self._w_is_image.append(image)
            self._w_stored.append(stored)
            self._w_last_log.append(0)
            self._w_written.append(0)
            self._w_out_of_order.append(0)
            return False
        if op == _OP_METADATA:
            name, values, done = arg
            self._writer.add_metadata(name, values)
            self._sync()
            done.set()
            return False
        if op == _OP_FLUSH:
            self._reorder.drain()  # "everything queued so far is on disk" includes what the window holds
            self._sync()
            arg.set()
            return False
        if op == _OP_CLOSE:
            exit_status, reason, done = arg
            self._reorder.drain()
            self._writer.flush()  # close the last chunk first, so run_end is the last record of the data section
            stats = self._collect_stats()
            end_ns = time.time_ns()
            self._writer.add_metadata(
                MetadataName.RUN_END,
                {
                    "exit_status": exit_status,
                    "reason": reason,
                    "end_time_ns": str(end_ns),
                    "end_time_utc": datetime.fromtimestamp(end_ns / 1e9, tz=UTC).isoformat(),
                    "messages_written": str(sum(stats.written.values())),
                    "dropped_total": str(stats.dropped_total),
                    "dropped_by_topic": json.dumps(stats.dropped, sort_keys=True),
                    "out_of_order_by_topic": json.dumps(stats.out_of_order, sort_keys=True),
                    "late_by_topic": json.dumps(stats.late, sort_keys=True),
                },
            )
            self._writer.finish()
            self._file.flush()
            os.fsync(self._file.fileno())
            self._file.close()
            self._close_stats = stats
            done.set()
            return True
        raise AssertionError(f"unknown recorder operation {op}")


def _fsync_directory(directory: Path) -> None:
    """Make the new file's directory entry durable too (a no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory if str(directory) else ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)
