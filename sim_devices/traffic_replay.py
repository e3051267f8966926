"""A recorded serial conversation served back as a device: test a driver (or a changed driver) against what a
device actually said, byte for byte, with no emulator in between.

A recording made with `--record-traffic` holds `/traffic/<device>` messages: each write the driver made ('tx') and
each non-empty read it got ('rx'), stamped with the rig clock. `TrafficReplayEndpoint` serves that as an
in-process port (`hamrsim://NAME`, the same transport the emulators use):

- the driver's k-th write must equal the recording's k-th tx exactly; the first one that does not raises
  `TrafficMismatch` naming the write's index, its recorded time, and both byte strings (a driver change that alters
  the conversation is found at its first differing command);
- the rx bytes recorded after the k-th tx (up to the next tx) become readable once the driver has made that write,
  each at the same delay after the write as in the recording. The recorded time of an rx is when the driver read it,
  so replies arrive no later than they were read, and a stream (rx after rx with no tx) is delivered at the pace it
  was read. Bytes recorded before the first tx are due from the moment the endpoint is created.

The port never loses bytes on `reset_input_buffer` (the recording holds only what the driver did read).
"""

from __future__ import annotations

import threading
from collections import deque
from pathlib import Path
from typing import Any

from hamr_bench.errors import DeviceProtocolError, RecordingError
from sim_devices.serial_link import register_endpoint, unregister_endpoint


class TrafficMismatch(DeviceProtocolError):
    """The driver wrote something other than what the recorded conversation holds at that point."""


class TrafficReplayEndpoint:
    """The device side of a recorded conversation (duck-typed like `serial_link.LineEndpoint`)."""

    def __init__(self, traffic: list[Any], clock: Any, device: str = "device", source: str = "") -> None:
        self.clock = clock
        self.device = device
        self.source = source
        self.lock = threading.RLock()
        self._tx: list[tuple[float, bytes]] = []
        self._rx_after: list[list[tuple[float, bytes]]] = [[]]  # [k]: rx following tx k-1 (k=0: before any tx)
        for item in traffic:
            if item.direction == "tx":
                self._tx.append((item.time_s, bytes(item.data)))
                self._rx_after.append([])
            elif item.direction == "rx":
                self._rx_after[-1].append((item.time_s, bytes(item.data)))
            else:
                raise RecordingError(f"{source}: traffic for {device} has direction {item.direction!r} "
                                     "(expected 'tx' or 'rx')")
        self.writes = 0            # how many of the recorded writes the driver has made
        self.mismatch: str | None = None
        self._out: deque[tuple[float, bytes]] = deque()
        self._queue_rx(0, clock.now_s(), reference_s=None)

    # -- what the driver did -------------------------------------------------------------------------------------
    def _queue_rx(self, block: int, now_s: float, reference_s: float | None) -> None:
        for time_s, data in self._rx_after[block]:
            delay_s = 0.0 if reference_s is None else max(0.0, time_s - reference_s)
            due = now_s + delay_s if reference_s is not None else max(now_s, time_s)
            if self._out and due < self._out[-1][0]:
                due = self._out[-1][0]  # keep the recorded order
            self._out.append((due, data))

    def receive(self, data: bytes) -> None:
        """The driver wrote `data` now: check it against the recording, then release the recorded answer."""
        with self.lock:
            k = self.writes
            if k >= len(self._tx):
                self.mismatch = (f"traffic replay {self.device}: write #{k + 1} {bytes(data)!r} goes beyond the "
                                 f"recording ({len(self._tx)} writes in {self.source or 'the recording'})")
                raise TrafficMismatch(self.mismatch, self.device)
            recorded_s, expected = self._tx[k]
            if bytes(data) != expected:
                self.mismatch = (f"traffic replay {self.device}: write #{k + 1} differs from the recording: "
                                 f"expected {expected!r} (recorded at {recorded_s:.6f} s), got {bytes(data)!r}")
                raise TrafficMismatch(self.mismatch, self.device)
            self.writes = k + 1
            self._queue_rx(k + 1, self.clock.now_s(), reference_s=recorded_s)

    # -- the port's side (protocol_hamrsim) ------------------------------------------------------------------------
    def is_connected(self, time_s: float | None = None) -> bool:
        return True

    def output_until(self, time_s: float) -> bytes:
        with self.lock:
            chunks = []
            while self._out and self._out[0][0] <= time_s:
                chunks.append(self._out.popleft()[1])
            return b"".join(chunks)

    def next_output_s(self) -> float | None:
        with self.lock:
            return self._out[0][0] if self._out else None

    def discard_output(self) -> None:
        """Nothing is discarded: every recorded rx byte is one the driver did read."""

    @property
    def complete(self) -> bool:
        """True once the driver has made every recorded write."""
        return self.writes == len(self._tx)

    @property
    def recorded_writes(self) -> int:
        return len(self._tx)


def traffic_topics(path: Path | str) -> list[str]:
    from hamr_bench.recording import RecordingReader
    from hamr_bench.recording.schemas import TRAFFIC_PREFIX

    return sorted(t for t in RecordingReader(path).topics() if t.startswith(TRAFFIC_PREFIX))


def load_traffic(path: Path | str, topic: str) -> list[Any]:
    from hamr_bench.recording import RecordingReader

    reader = RecordingReader(path)
    if topic not in reader.topics():
        raise RecordingError(f"{path} has no traffic topic {topic} (record the run with --record-traffic); "
                             f"traffic topics: {', '.join(traffic_topics(path)) or 'none'}")
    return reader.traffic(topic)


_names = iter(range(1, 1 << 30))


def serve_traffic(path: Path | str, topic: str, clock: Any, name: str | None = None) -> tuple[str, TrafficReplayEndpoint]:
    """Register the conversation on `topic` of recording `path` as `hamrsim://NAME`; returns (url, endpoint).
    Call `unregister_endpoint(NAME)` (or `close_served(url)`) when done."""
    device = topic.rsplit("/", 1)[-1]
    endpoint = TrafficReplayEndpoint(load_traffic(path, topic), clock, device=device, source=str(path))
    url = register_endpoint(name or f"traffic-{device}-{next(_names)}", endpoint, replace=True)
    return url, endpoint


def close_served(url: str) -> None:
    unregister_endpoint(url.split("://", 1)[-1])


def role_of(topic: str) -> str | None:
    """The rig role a traffic topic belongs to ('stage', 'force_sensor'), from the device name the rig builder
    gave it (`stage`, `force_sensor`)."""
    device = topic.rsplit("/", 1)[-1]
    if device.startswith("stage"):
        return "stage"
    if device.startswith("force"):
        return "force_sensor"
    return None
