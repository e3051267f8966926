"""A recorded serial conversation served back as a device: test a driver (or a changed driver) against what a
device actually said, byte for byte, with no emulator in between.

A recording made with `--record-traffic` holds `/traffic/<device>` messages: each write the driver made
('tx') and
each non-empty read it got ('rx'), stamped with the rig clock. `TrafficReplayEndpoint` serves that as an
in-process port (`hamrsim://NAME`, the same transport the emulators use):

- the driver's k-th write must equal the recording's k-th tx exactly; the first one that does not raises
  `TrafficMismatch` naming the write's index, its recorded time, and both byte strings (a driver change that
  alters
  the conversation is found at its first differing command);
- the rx bytes recorded after the k-th tx (up to the next tx) become readable once the driver has made that
write,
  each at the same delay after the write as in the recording. The recorded time of an rx is when the driver
  read it,
  so replies arrive no later than they were read, and a stream (rx after rx with no tx) is delivered at the
  pace it
  was read. Bytes recorded before the first tx are due from the moment the endpoint is created.

The port never loses bytes on `reset_input_buffer` (the recording holds only what the driver did read).
"""

from __future__ import annotations

import re
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

    # -- what the driver did
    # -------------------------------------------------------------------------------------
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

    # -- the port's side (protocol_hamrsim)
    # ------------------------------------------------------------------------
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
    from hamr_bench.recording.contract import TRAFFIC_PREFIX

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


# -- a recorded conversation played to an emulator
# ----------------------------------------------------------------
_NUMBER_LINE = re.compile(r"^-?\d+(\.\d+)?$")


def line_shape(line: str) -> str:
    """What must agree between a recorded reply line and the emulator's when the values cannot (a force
    reading
    depends on what pushed on the sensor): a number keeps its sign-free format (digits before and after the
    point),
    any other text itself."""
    if _NUMBER_LINE.match(line):
        whole, _, decimals = line.lstrip("-").partition(".")
        return f"number with {len(decimals)} decimals" if decimals else "integer"
    return line


def emulator_disagreements(
    exchanges: list[tuple[bytes | None, bytes | None]], times_s: list[float], endpoint: Any, clock: Any, exact: bool
) -> list[str]:
    """Send each recorded write to `endpoint` (an emulator on a VirtualClock `clock`) at its recorded time and
    compare what it answers with what the device answered; one line per disagreement.

    exact=True (request/reply devices: the SMC100): each exchange's reply byte for byte. exact=False (the
    Loadstar,
    whose readings follow the force on it and whose stream is read in arbitrary batches): the reply lines
    over the
    whole conversation, see `_line_disagreements`."""
    start_s = clock.now_s()
    found: list[str] = []
    recorded_lines: list[str] = []
    emulated_lines: list[str] = []
    for k, ((sent, reply), t) in enumerate(zip(exchanges, times_s, strict=True)):
        # A reply the driver read just before its next write is due at that write's time (to the file's 1 ns
        # rounding): a microsecond of slack keeps it in this exchange.
        until_s = start_s + (times_s[k + 1] if k + 1 < len(times_s) else t + 1.0) + 1e-6
        clock.advance_to(max(clock.now_s(), start_s + t))
        if sent is not None:
            endpoint.receive(sent)
        got = endpoint.output_until(until_s)
        if exact and got != (reply or b""):
            found.append(f"exchange {k} at {t:.6f} s: sent {sent!r}: device {reply!r}, emulator {got!r}")
        recorded_lines += (reply or b"").decode("latin-1").split("\r\n")[:-1] if reply else []
        emulated_lines += got.decode("latin-1").split("\r\n")[:-1]
    if not exact:
        found += _line_disagreements(recorded_lines, emulated_lines)
    return found


STREAM_COUNT_TOLERANCE = 0.05


def _runs(lines: list[str]) -> list[tuple[str, int]]:
    """Consecutive lines of one shape -> (shape, count)."""
    runs: list[tuple[str, int]] = []
    for line in lines:
        shape = line_shape(line)
        if runs and runs[-1][0] == shape and shape.startswith(("number", "integer")):
            runs[-1] = (shape, runs[-1][1] + 1)
        else:
            runs.append((shape, 1))
    return runs


def _line_disagreements(recorded: list[str], emulated: list[str]) -> list[str]:
    """Every text reply equal and in the same order; numbers in the same format; a stream's length within 5
    %. (A
    stream at 9600 baud is paced by the bytes of its lines, so its length follows how many readings carry a
    minus
    sign: it cannot agree to the line when the readings do not.)"""
    found = []
    device, emulator = _runs(recorded), _runs(emulated)
    for k, ((shape_a, count_a), (shape_b, count_b)) in enumerate(zip(device, emulator, strict=False)):
        if shape_a != shape_b:
            found.append(f"reply {k}: device {shape_a!r}, emulator {shape_b!r}")
        elif abs(count_a - count_b) > STREAM_COUNT_TOLERANCE * max(count_a, count_b):
            counts = f"{count_a} lines of {shape_a} from the device, {count_b} from the emulator"
            found.append(f"reply {k}: {counts}")
    if len(device) != len(emulator):
        found.append(f"{len(device)} replies from the device, {len(emulator)} from the emulator")
    return found
