"""The live server: a foxglove-sdk WebSocket server and the thread that publishes a run's tap to it.

Every recorded channel is advertised with the file's topic, schema (the same protobuf descriptor) and channel
metadata (units). Each publishing tick (`TICK_S` of wall time) the thread empties the tap and, for each channel a
client subscribes to:
- scalar streams: all samples up to `max_rate_Hz` a second of wall time, beyond that the peak samples of equal
  groups (decimate.py): a 10 kHz force stream reaches a client as 500 messages a second with its envelope intact;
- images (frames, regions of interest) and marker annotations: the newest of the tick, at most `frame_rate_Hz` a
  second; whole frames the file does not keep (`--camera-storage roi` keeps one a second) are asked of the
  recorder only while a client watches `/camera/image`;
- everything else (events, log lines, steps, traffic): every message.
The rates are wall-clock rates, so a simulated run that goes 50 times faster than real time is thinned 50 times
more, not sent 50 times faster. The SDK queues messages per client and drops a slow client's oldest ones: one
stalled client never holds up the others, this thread, or the recording (which does not go through here at all).
"""

from __future__ import annotations

import json
import math
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from hamr_bench.errors import ConfigError
from hamr_bench.live.control import ABORT_SERVICE, REQUEST_SCHEMA, RESPONSE_SCHEMA, AbortControl
from hamr_bench.live.decimate import peak_indices
from hamr_bench.live.options import LiveOptions
from hamr_bench.live.tap import LiveTap
from hamr_bench.recording import schemas
from hamr_bench.recording.contract import Topic
from hamr_bench.recording.tap import TapChannel

TICK_S = 0.02
DEFAULT_MAX_RATE_HZ = 250.0
DEFAULT_FRAME_RATE_HZ = 10.0
MAX_PASS_THROUGH_PER_TICK = 500  # events / logs / traffic: a burst beyond this keeps its newest
BACKLOG_MESSAGES = 2048  # per client, in the SDK: ~0.2 s of everything a client can subscribe to


def import_foxglove() -> Any:
    try:
        import foxglove
    except ImportError:
        raise ConfigError("--live needs the foxglove-sdk package: pip install foxglove-sdk") from None
    return foxglove


@dataclass
class _Published:
    """A channel as the publisher handles it."""

    sdk: Any  # foxglove.Channel
    topic: str
    kind: str  # scalar | image | all
    value_offset: int = 0  # scalar: byte offset of the first field's double in the payload
    payload_size: int = 0
    next_wall: float = 0.0  # image: not before this wall time


class LiveServer:
    """Serves the runs of one command (see the module docstring); `attach` each run's recorder in turn."""

    def __init__(self, options: LiveOptions, control: AbortControl, *, max_rate_Hz: float = DEFAULT_MAX_RATE_HZ,
                 frame_rate_Hz: float = DEFAULT_FRAME_RATE_HZ) -> None:
        self.options = options
        self.control = control
        self.max_rate_Hz = max_rate_Hz
        self.frame_rate_Hz = frame_rate_Hz
        self._foxglove = import_foxglove()
        self._context = self._foxglove.Context()
        self._server: Any = None
        self._lock = threading.Lock()
        self._tap: LiveTap | None = None
        self._start_ns = 0
        self._channels: dict[int, _Published] = {}
        self._frame_channel: _Published | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._runs = 0
        self.published = 0
        self.dropped_by_tap = 0
        self.publish_delays_ms: list[float] = []  # the newest message of each batch: its age when handed to the SDK

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        fg = self._foxglove
        from foxglove.websocket import Capability

        service = fg.Service(
            name=ABORT_SERVICE,
            schema=fg.ServiceSchema(
                name="hamr_bench.Abort",
                request=fg.MessageSchema(encoding="json", schema=fg.Schema(
                    name="hamr_bench.AbortRequest", encoding="jsonschema", data=json.dumps(REQUEST_SCHEMA).encode())),
                response=fg.MessageSchema(encoding="json", schema=fg.Schema(
                    name="hamr_bench.AbortResponse", encoding="jsonschema",
                    data=json.dumps(RESPONSE_SCHEMA).encode())),
            ),
            handler=self._abort_request,
        )
        try:
            self._server = fg.start_server(
                name="hamr-bench", host=self.options.host, port=self.options.port, context=self._context,
                capabilities=[Capability.Services], supported_encodings=["json"], services=[service],
                message_backlog_size=BACKLOG_MESSAGES)
        except Exception as exc:  # the SDK raises its own error types for a busy port or a bad address
            raise ConfigError(f"--live {self.options.host}:{self.options.port}: cannot listen ({exc})") from None
        self._thread = threading.Thread(target=self._publish_loop, name="live-publisher", daemon=True)
        self._thread.start()

    @property
    def port(self) -> int:
        return int(self._server.port) if self._server is not None else self.options.port

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5.0)
        if self._server is not None:
            self._server.stop()
            self._server = None

    def attach(self, tap: LiveTap, start_time_ns: int, frames_only_live: bool = False) -> None:
        """Publish `tap` (one run's) from now on, in place of the previous run's. `frames_only_live`: the file
        keeps no camera frames (`--camera-storage none`), so `/camera/image` exists only here."""
        with self._lock:
            self._close_channels()
            if self._runs and self._server is not None:
                self._server.clear_session()  # clients drop the previous run's state
            self._runs += 1
            self._tap = tap
            self._start_ns = int(start_time_ns)
            if frames_only_live:
                from hamr_bench.recording.tap import TapChannel

                self._advertise(TapChannel(-1, Topic.CAMERA_IMAGE, schemas.RAW_IMAGE_SCHEMA,
                                           schemas.raw_image_descriptor_set(), {}, True))

    def detach(self) -> None:
        """The run ended: publish what its tap still holds, then stop following it."""
        with self._lock:
            if self._tap is not None:
                self._publish_once(time.monotonic() - TICK_S)
                self.dropped_by_tap += self._tap.dropped
            self._tap = None

    # ------------------------------------------------------------------ control
    def _abort_request(self, request: Any) -> bytes:
        response = self.control.handle(bytes(request.payload), f"#{request.client_id}")
        return json.dumps(response).encode()

    # ------------------------------------------------------------------ publishing
    def _publish_loop(self) -> None:
        last = time.monotonic()
        while not self._stop.wait(TICK_S):
            now = time.monotonic()
            with self._lock:
                if self._tap is not None:
                    self._publish_once(last)
            last = now

    def _publish_once(self, last_wall: float) -> None:
        tap = self._tap
        assert tap is not None
        for channel in tap.take_channels():
            self._advertise(channel)
        items = tap.take_items()
        elapsed = max(time.monotonic() - last_wall, TICK_S)
        by_channel: dict[int, list[tuple[float, bytes]]] = {}
        for index, time_s, payload in items:
            by_channel.setdefault(index, []).append((time_s, payload))
        budget = max(2, int(round(self.max_rate_Hz * elapsed)))
        for index, messages in by_channel.items():
            published = self._channels.get(index)
            if published is None or not published.sdk.has_sinks():
                continue
            if published.kind == "scalar":
                messages = self._thin(published, messages, budget)
            elif published.kind == "image":
                messages = self._due_image(published, messages)
            elif len(messages) > MAX_PASS_THROUGH_PER_TICK:
                messages = messages[-MAX_PASS_THROUGH_PER_TICK:]
            self._log(published, messages)
        frames = self._frame_channel
        tap.frames_wanted = frames is not None and frames.sdk.has_sinks()
        frame = tap.take_frame()
        if frame is not None and frames is not None:
            self._log(frames, [frame])

    def _log(self, published: _Published, messages: list[tuple[float, bytes]]) -> None:
        start_ns = self._start_ns
        log = published.sdk.log
        for time_s, payload in messages:
            log_ns = start_ns + round(time_s * 1e9) if math.isfinite(time_s) else start_ns
            log(payload, log_time=max(log_ns, 0))
        if messages:
            self.publish_delays_ms.append((time.time_ns() - log_ns) / 1e6)
        self.published += len(messages)

    def _thin(self, published: _Published, messages: list[tuple[float, bytes]],
              budget: int) -> list[tuple[float, bytes]]:
        if len(messages) <= budget:
            return messages
        size = published.payload_size
        if any(len(payload) != size for _, payload in messages):
            step = math.ceil(len(messages) / budget)  # not the fixed layout (cannot happen with the recorder)
            return messages[::step]
        joined = np.frombuffer(b"".join(payload for _, payload in messages), dtype=np.uint8)
        values = joined.reshape(len(messages), size)[:, published.value_offset:published.value_offset + 8]
        picked = peak_indices(values.copy().view("<f8").ravel(), budget)
        return [messages[i] for i in picked.tolist()]

    def _due_image(self, published: _Published, messages: list[tuple[float, bytes]]) -> list[tuple[float, bytes]]:
        now = time.monotonic()
        if now < published.next_wall:
            return []
        published.next_wall = now + 1.0 / self.frame_rate_Hz
        return messages[-1:]

    # ------------------------------------------------------------------ channels
    def _advertise(self, channel: TapChannel) -> None:
        fg = self._foxglove
        sdk = fg.Channel(channel.topic, message_encoding="protobuf", context=self._context,
                         schema=fg.Schema(name=channel.schema_name, encoding="protobuf", data=channel.schema_data),
                         metadata=dict(channel.metadata))
        fields = None if channel.is_image else schemas.scalar_fields_from_descriptor(channel.schema_name,
                                                                                   channel.schema_data)
        if channel.is_image or channel.topic == Topic.CAMERA_ANNOTATIONS:
            published = _Published(sdk, channel.topic, "image")
        elif fields is not None:
            # the recorder's fixed layout: per field a tag byte and a double; time_s first, then the fields
            published = _Published(sdk, channel.topic, "scalar", value_offset=9 + 1, payload_size=9 * (len(fields) + 1))
        else:
            published = _Published(sdk, channel.topic, "all")
        self._channels[channel.index] = published
        if channel.topic == Topic.CAMERA_IMAGE and channel.schema_name == schemas.RAW_IMAGE_SCHEMA:
            self._frame_channel = published

    def _close_channels(self) -> None:
        for published in self._channels.values():
            published.sdk.close()
        self._channels.clear()
        self._frame_channel = None
