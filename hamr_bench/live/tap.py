"""The live view's side of the recorder's tap (hamr_bench/recording/tap.py): bounded queues that producers append
to and the publishing thread empties. Appending never waits; when the publisher falls behind (it is starved of CPU,
say) the oldest queued messages are dropped here, counted, and the recording does not notice.
"""

from __future__ import annotations

import itertools
import time
from collections import deque

from hamr_bench.recording.tap import TapChannel

DEFAULT_MAX_ITEMS = 100_000  # ~8 s of the full acquisition load (12,000 messages/s) if the publisher stalls


class LiveTap:
    """One run's messages on their way to the live server (see the module docstring)."""

    def __init__(self, max_items: int = DEFAULT_MAX_ITEMS, frame_interval_s: float = 0.1) -> None:
        self._channels: deque[TapChannel] = deque()
        # (arrival number, channel index, time_s, payload); the numbers show the publisher what fell off the end
        self._items: deque[tuple[int, int, float, bytes]] = deque(maxlen=max_items)
        self._numbers = itertools.count()
        self._taken_up_to = -1
        self.dropped = 0
        self.frame_interval_s = frame_interval_s
        self.frames_wanted = False  # set by the publisher while a client watches /camera/image
        self._frame: tuple[float, bytes] | None = None
        self._next_frame_wall = 0.0

    # ------------------------------------------------------------------ the recorder's side (producer threads)
    def channel(self, channel: TapChannel) -> None:
        self._channels.append(channel)

    def message(self, index: int, time_s: float, payload: bytes) -> None:
        self._items.append((next(self._numbers), index, time_s, payload))

    def wants_frame(self, time_s: float) -> bool:
        return self.frames_wanted and time.monotonic() >= self._next_frame_wall

    def frame(self, time_s: float, payload: bytes) -> None:
        self._frame = (time_s, payload)
        self._next_frame_wall = time.monotonic() + self.frame_interval_s

    # ------------------------------------------------------------------ the publisher's side (one thread)
    def take_channels(self) -> list[TapChannel]:
        out = []
        while self._channels:
            out.append(self._channels.popleft())
        return out

    def take_items(self) -> list[tuple[int, float, bytes]]:
        """Everything queued since the last call, oldest first (and what fell off the end counted in `dropped`)."""
        items = self._items
        out = []
        last = self._taken_up_to
        for _ in range(len(items)):
            number, index, time_s, payload = items.popleft()
            if number != last + 1:
                self.dropped += number - last - 1
            last = number
            out.append((index, time_s, payload))
        self._taken_up_to = last
        return out

    def take_frame(self) -> tuple[float, bytes] | None:
        frame, self._frame = self._frame, None
        return frame
