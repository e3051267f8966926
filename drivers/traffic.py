"""Recording the raw bytes a driver exchanges with a serial device (`hamr-bench run --record-traffic`). A tapped
port behaves exactly like the port it wraps and reports every write ('tx') and every non-empty read ('rx') with
the rig-clock time to a sink, which the runner points at the recording's `/traffic/<device>` topic."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from hamr_bench.recording.contract import TRAFFIC_PREFIX


class TappedPort:
    def __init__(self, port: Any, device: str, clock: Any, sink: Callable[[str, float, str, bytes], None]):
        object.__setattr__(self, "_port", port)
        object.__setattr__(self, "_clock", clock)
        object.__setattr__(self, "_sink", sink)
        object.__setattr__(self, "_topic", f"{TRAFFIC_PREFIX}{device}")

    def write(self, data: bytes) -> int:
        self._sink(self._topic, self._clock.now_s(), "tx", bytes(data))
        return self._port.write(data)

    def read(self, size: int = 1) -> bytes:
        data = self._port.read(size)
        if data:
            self._sink(self._topic, self._clock.now_s(), "rx", bytes(data))
        return data

    def read_until(self, expected: bytes = b"\n", size: int | None = None) -> bytes:
        data = self._port.read_until(expected, size)
        if data:
            self._sink(self._topic, self._clock.now_s(), "rx", bytes(data))
        return data

    def __getattr__(self, name: str) -> Any:
        return getattr(self._port, name)

    def __setattr__(self, name: str, value: Any) -> None:  # timeout and friends belong to the real port
        setattr(self._port, name, value)


def tapped_opener(opener: Callable[..., Any], device: str, clock: Any, sink) -> Callable[..., Any]:
    def open_tapped(*args: Any, **kwargs: Any) -> TappedPort:
        return TappedPort(opener(*args, **kwargs), device, clock, sink)

    return open_tapped
