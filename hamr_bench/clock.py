"""Time for the whole application: a real clock for a rig, a virtual clock for the simulated bench.

Every wait in drivers, the runner and the emulators goes through a `Clock`, never through `time.sleep`, so the same
code runs in real time on a rig and in simulated time on the simulated bench, where an hour-long protocol takes
seconds and every run is reproducible. On the virtual clock `sleep` advances time instantly; a blocking read on a
simulated serial port advances it to the moment the device's reply is due.
"""

from __future__ import annotations

import threading
import time
from typing import Protocol, runtime_checkable


@runtime_checkable
class Clock(Protocol):
    """Seconds since an arbitrary epoch, and a way to wait."""

    def now_s(self) -> float: ...

    def sleep(self, duration_s: float) -> None: ...

    @property
    def is_virtual(self) -> bool: ...


class RealClock:
    """Wall time from `time.monotonic`, for real rigs and for interactive emulators."""

    is_virtual = False

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now_s(self) -> float:
        return time.monotonic() - self._t0

    def sleep(self, duration_s: float) -> None:
        if duration_s > 0:
            time.sleep(duration_s)


class VirtualClock:
    """Simulated time that only moves when someone waits. Thread-safe; never goes backwards."""

    is_virtual = True

    def __init__(self, start_s: float = 0.0) -> None:
        self._now_s = float(start_s)
        self._lock = threading.Lock()

    def now_s(self) -> float:
        return self._now_s

    def sleep(self, duration_s: float) -> None:
        if duration_s > 0:
            self.advance_to(self._now_s + duration_s)

    def advance_to(self, time_s: float) -> None:
        """Move time forward to `time_s`; a time in the past is ignored (time never runs backwards)."""
        with self._lock:
            if time_s > self._now_s:
                self._now_s = float(time_s)
