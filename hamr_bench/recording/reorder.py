"""The recorder's bounded reorder stage: messages of all channels leave it in log-time order, so a recording's log
times never decrease in file order (what `mcap doctor --strict-message-order` checks, and what lets a reader or a
live view follow the file as it grows without sorting).

Why it is needed: producers deliver in batches. A force sensor's stream is drained every pass of the runner's loop
(a batch of samples up to "now"), a camera frame is written after its exposure ended (its time is mid-exposure),
a stage move blocks while force samples pile up in the port. So arrival order is time order only to within a
batch: measured on the simulated bench, up to 0.2 s on a blocked-force run.

How: every message waits in a heap keyed by (log time, arrival number) until the newest log time seen is more
than `window_ns` past it, then leaves in order. The window is rig time, so a simulated run (virtual clock) is
reordered the same way however fast or loaded the machine. Three things release messages early, so memory and the
crash window stay bounded: the producers falling silent for `idle_release_s` of wall time (on a real rig, a long
move with nothing recorded), the held bytes passing `max_bytes` (full camera frames), and `drain()` (an explicit
flush, and the close).
A message that arrives after a later one has already left (later than the window allows) keeps its data (its own
time is in its `time_s` / `timestamp` field) but is logged at the last log time written, and counted per
channel: the file stays in order and nothing is lost or hidden.
"""

from __future__ import annotations

import heapq
import time
from collections.abc import Callable

# (log time ns, arrival number, channel index, payload)
Item = tuple[int, int, int, bytes]


class ReorderStage:
    """Puts messages back in log-time order within a bounded window; see the module docstring."""

    def __init__(self, sink: Callable[[int, int, bytes], None], n_channels: Callable[[], int], *,
                 window_ns: int, idle_release_s: float, max_bytes: int) -> None:
        """`sink(channel_index, log_ns, payload)` receives the messages in order; `n_channels()` says how many
        channels exist (for the per-channel late counts)."""
        if window_ns < 0 or idle_release_s <= 0 or max_bytes <= 0:
            raise ValueError("reorder window, idle release and byte budget must be positive")
        self._sink = sink
        self._window_ns = int(window_ns)
        self._idle_release_s = float(idle_release_s)
        self._max_bytes = int(max_bytes)
        self._n_channels = n_channels
        self._heap: list[Item] = []
        self._arrivals = 0
        self._held_bytes = 0
        self._newest_ns = 0
        self._last_out_ns = 0
        self._last_push_wall = time.monotonic()
        self.late: list[int] = []  # per channel index: messages logged at a later time than their own

    def push(self, log_ns: int, index: int, payload: bytes) -> None:
        self._arrivals += 1
        heapq.heappush(self._heap, (log_ns, self._arrivals, index, payload))
        self._held_bytes += len(payload)
        if log_ns > self._newest_ns:
            self._newest_ns = log_ns
        self._last_push_wall = time.monotonic()

    def release(self) -> None:
        """Let go of everything the window no longer needs to hold (call after each batch of pushes)."""
        if not self._heap:
            return
        if self._held_bytes > self._max_bytes or time.monotonic() - self._last_push_wall > self._idle_release_s:
            self.drain()
            return
        self._pop_until(self._newest_ns - self._window_ns)

    def drain(self) -> None:
        """Write every held message, in order."""
        self._pop_until(None)

    @property
    def held(self) -> int:
        return len(self._heap)

    def _pop_until(self, limit_ns: int | None) -> None:
        heap = self._heap
        sink = self._sink
        pop = heapq.heappop
        last = self._last_out_ns
        while heap and (limit_ns is None or heap[0][0] <= limit_ns):
            log_ns, _, index, payload = pop(heap)
            self._held_bytes -= len(payload)
            if log_ns < last:
                self._count_late(index)
                log_ns = last
            else:
                last = log_ns
            sink(index, log_ns, payload)
        self._last_out_ns = last

    def _count_late(self, index: int) -> None:
        if index >= len(self.late):
            self.late.extend([0] * (max(self._n_channels(), index + 1) - len(self.late)))
        self.late[index] += 1
