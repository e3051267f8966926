"""The simulated serial link: the base every line-protocol emulator builds on, and the registry of in-process
endpoints that `hamrsim://NAME` URLs resolve to.

An endpoint receives the host's bytes at the clock's present time and queues reply bytes with the time they
are due (the device's modelled latency plus the bytes' time on the wire). A port (in-process
`protocol_hamrsim.Serial` or the pty server) asks `output_until(t)` for the bytes due by `t` and
`next_output_s()` for when the next byte will be due, so a read on a virtual clock jumps straight to that
moment. Streamed lines are produced lazily up to the time asked for, each carrying the time it was produced.
Wire faults (no reply, garbage, dropped bytes, disconnect) are applied here, once, for every serial emulator.
"""

from __future__ import annotations

import re
import threading
from collections import deque
from typing import Protocol

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError
from sim_devices.faults import FaultInjector

# Flow-control bytes must never be emitted as "garbage": with XON/XOFF a stray 0x13 stalls the client.
_GARBAGE_BYTES = np.array([b for b in range(0x80, 0x100)], dtype=np.uint8)


class LineEndpoint:
    """Base of a serial device emulator's wire side: line splitting, reply queue with due times, wire faults.

    Subclasses implement `handle_line(line, time_s)` and call `send(text, time_s)`; streaming devices also
    override `produce_until(time_s)` and `next_produced_s()`.
    """

    def __init__(
        self,
        clock: Clock,
        faults: FaultInjector,
        *,
        device: str,
        baudrate: int,
        reply_latency_s: float,
        input_terminator: bytes,
        output_terminator: bytes = b"\r\n",
        keep_stray_line_ends: bool = False,
        rng: np.random.Generator | None = None,
    ) -> None:
        self.clock = clock
        self.faults = faults
        self.device = device
        self.reply_latency_s = float(reply_latency_s)
        # 8N1: ten bit times per byte on the wire.
        self.byte_time_s = 10.0 / float(baudrate)
        self.input_terminator = input_terminator
        self.output_terminator = output_terminator
        # False: a CR or LF inside a line is dropped; True: the line is handed over byte for byte (a device
        # that
        # only executes on its full terminator sees a stray CR or LF as part of the command).
        self.keep_stray_line_ends = keep_stray_line_ends
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.lock = threading.RLock()
        self._inbuf = bytearray()
        self._out: deque[tuple[float, bytes]] = deque()
        self._last_due_s = float("-inf")

    # -- to be provided by the device ----------------------------------------------------------------------
    def handle_line(self, line: str, time_s: float) -> None:
        raise NotImplementedError

    def produce_until(self, time_s: float) -> None:
        """Queue any streamed lines produced up to `time_s` (streaming devices override)."""

    def next_produced_s(self) -> float | None:
        """When the next streamed line will be produced, or None if the device is not streaming."""
        return None

    # -- host side ------------------------------------------------------------------------------------------
    def is_connected(self, time_s: float | None = None) -> bool:
        t = self.clock.now_s() if time_s is None else time_s
        return not self.faults.is_active("disconnect", t)

    def receive(self, data: bytes) -> None:
        """The host wrote `data` now."""
        time_s = self.clock.now_s()
        with self.lock:
            self.produce_until(time_s)
            self._inbuf += data
            while (index := self._inbuf.find(self.input_terminator)) >= 0:
                raw = bytes(self._inbuf[:index])
                del self._inbuf[: index + len(self.input_terminator)]
                if not self.keep_stray_line_ends:
                    raw = raw.replace(b"\r", b"").replace(b"\n", b"")
                text = raw.decode("latin-1")
                self.handle_line(text, time_s)

    def send(
        self, text: str, time_s: float, extra_delay_s: float = 0.0, latency_s: float | None = None
    ) -> None:
        """Queue one reply line, produced at `time_s`, applying the wire faults active then."""
        if self.faults.is_active("no_reply", time_s):
            return
        payload = text.encode("ascii") + self.output_terminator
        if self.faults.is_active("garbage_bytes", time_s):
            noise = self.rng.choice(_GARBAGE_BYTES, size=max(3, len(payload) - len(self.output_terminator)))
            payload = noise.tobytes() + self.output_terminator
        if self.faults.is_active("dropped_bytes", time_s) and len(payload) > 1:
            payload = payload[:-1]
            drop = int(self.rng.integers(0, len(payload)))
            payload = payload[:drop] + payload[drop + 1 :]
        latency_s = self.reply_latency_s if latency_s is None else latency_s
        # One UART: a line starts on the wire when it is ready and the previous line has left, and takes
        # its bytes' time; so replies stay in order and a stream cannot outrun the baud rate.
        start_s = max(time_s + latency_s + extra_delay_s, self._last_due_s)
        due_s = start_s + len(payload) * self.byte_time_s
        self._last_due_s = due_s
        self._out.append((due_s, payload))

    def send_stream_line(self, text: str, produced_s: float) -> None:
        """A streamed line leaves as it is produced (no command latency, only its bytes' wire time)."""
        self.send(text, produced_s, latency_s=0.0)

    @property
    def wire_free_s(self) -> float:
        """When the last queued byte will have left (a streaming device waits for it to sample again)."""
        return self._last_due_s

    def output_until(self, time_s: float) -> bytes:
        """Bytes due by `time_s`, removed from the queue."""
        with self.lock:
            self.produce_until(time_s)
            if not self.is_connected(time_s):
                return b""
            chunks = []
            while self._out and self._out[0][0] <= time_s:
                chunks.append(self._out.popleft()[1])
            return b"".join(chunks)

    def next_output_s(self) -> float | None:
        """When the next byte will be due (None: nothing will come unless the host writes)."""
        with self.lock:
            candidates = []
            if self._out:
                candidates.append(self._out[0][0])
            produced = self.next_produced_s()
            if produced is not None:
                candidates.append(produced)
            return min(candidates) if candidates else None

    def discard_output(self) -> None:
        """What `Serial.open()` does to the host's input buffer: bytes already due are lost."""
        with self.lock:
            now_s = self.clock.now_s()
            self.produce_until(now_s)
            while self._out and self._out[0][0] <= now_s:
                self._out.popleft()


# -- in-process endpoint registry ---------------------------------------------------------------------------
class SerialEndpoint(Protocol):
    """What a port (the `hamrsim://` handler) asks of the device side; `LineEndpoint` is one, a recorded
    conversation served back (`traffic_replay.TrafficReplayEndpoint`) another."""

    clock: Clock

    def is_connected(self, time_s: float | None = None) -> bool: ...

    def receive(self, data: bytes) -> None: ...

    def output_until(self, time_s: float) -> bytes: ...

    def next_output_s(self) -> float | None: ...

    def discard_output(self) -> None: ...


_ENDPOINTS: dict[str, SerialEndpoint] = {}
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")
_REGISTRY_LOCK = threading.Lock()


def register_endpoint(name: str, endpoint: SerialEndpoint, replace: bool = False) -> str:
    """Make `endpoint` reachable as `hamrsim://NAME` and return that URL."""
    if not _NAME.match(name):
        raise ConfigError(f"simulated port name {name!r}: use letters, digits, '_', '.', '-'")
    with _REGISTRY_LOCK:
        if name in _ENDPOINTS and not replace and _ENDPOINTS[name] is not endpoint:
            raise ConfigError(f"simulated port name {name!r} is already registered")
        _ENDPOINTS[name] = endpoint
    _ensure_handler_registered()
    return f"hamrsim://{name}"


def unregister_endpoint(name: str) -> None:
    with _REGISTRY_LOCK:
        _ENDPOINTS.pop(name, None)


def get_endpoint(name: str) -> SerialEndpoint | None:
    with _REGISTRY_LOCK:
        return _ENDPOINTS.get(name)


def _ensure_handler_registered() -> None:
    import serial

    if "sim_devices" not in serial.protocol_handler_packages:
        serial.protocol_handler_packages.append("sim_devices")


def wait_until(clock: Clock, time_s: float) -> None:
    """Wait on `clock` until `time_s`; on a virtual clock land on it exactly (no float creep)."""
    advance_to = getattr(clock, "advance_to", None)
    if advance_to is not None and clock.is_virtual:
        advance_to(time_s)
    else:
        clock.sleep(time_s - clock.now_s())
