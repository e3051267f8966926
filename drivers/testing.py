"""Byte-exact driver tests in the spirit of PyMeasure's `expected_protocol`: a scripted fake serial port that
checks every byte string a driver writes against a list of (sent, reply) exchanges and hands back the scripted
replies. Usable by any driver that opens its port through a `port_opener(url, **settings)` argument.

Write the exchanges from the instrument's manual (or from traffic recorded on real hardware), never by running
the driver. `sent=None` means bytes the device sends on its own after the previous exchange (a stream, a
leftover); `reply=None` means the device stays silent, so a read waits out its timeout on the (virtual) clock.
"""

from __future__ import annotations

import contextlib
import weakref
from collections.abc import Iterator, Sequence
from typing import Any

from hamr_bench.clock import Clock, VirtualClock

Exchange = tuple[bytes | None, bytes | None]

_PORTS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


class ScriptedPort:
    """A fake pyserial port driven by a script of exchanges. Mismatches raise AssertionError at once."""

    def __init__(self, exchanges: Sequence[Exchange], clock: Clock) -> None:
        self.exchanges = list(exchanges)
        self.clock = clock
        self.settings: dict[str, Any] = {}
        self.timeout: float | None = None
        self.is_open = True
        self._index = 0
        self._written = bytearray()
        self._rx = bytearray()
        self._release_unsolicited()

    def open_for(self, url: str, **settings: Any) -> ScriptedPort:
        """Stands in for `serial.serial_for_url`: records the settings the driver asked for."""
        self.url = url
        self.settings = dict(settings)
        self.timeout = settings.get("timeout")
        return self

    def _release_unsolicited(self) -> None:
        while self._index < len(self.exchanges) and self.exchanges[self._index][0] is None:
            self._rx += self.exchanges[self._index][1] or b""
            self._index += 1

    def write(self, data: bytes) -> int:
        self._written += bytes(data)
        while self._written:
            if self._index >= len(self.exchanges):
                raise AssertionError(f"driver wrote {bytes(self._written)!r} after the script ended")
            sent, reply = self.exchanges[self._index]
            assert sent is not None
            if len(self._written) < len(sent):
                if sent.startswith(bytes(self._written)):
                    break  # the rest of the command comes in a later write
                raise AssertionError(
                    f"exchange {self._index}: driver wrote {bytes(self._written)!r}, expected {sent!r}"
                )
            if bytes(self._written[: len(sent)]) != sent:
                raise AssertionError(
                    f"exchange {self._index}: driver wrote {bytes(self._written[: len(sent)])!r}, "
                    f"expected {sent!r}"
                )
            del self._written[: len(sent)]
            self._index += 1
            self._rx += reply or b""
            self._release_unsolicited()
        return len(data)

    @property
    def in_waiting(self) -> int:
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        if not self._rx:
            if self.timeout is None:
                raise AssertionError("blocking read with no timeout and nothing scripted to arrive")
            self.clock.sleep(self.timeout)  # silence costs the driver its whole timeout
            return b""
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def reset_input_buffer(self) -> None:
        self._rx.clear()

    def reset_output_buffer(self) -> None:
        pass

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self.is_open = False

    def assert_done(self) -> None:
        if self._written:
            raise AssertionError(f"driver left a partial command {bytes(self._written)!r}")
        if self._index < len(self.exchanges):
            rest = self.exchanges[self._index :]
            raise AssertionError(f"driver never sent the rest of the script: {rest!r}")


@contextlib.contextmanager
def expected_protocol(
    driver_class: type,
    exchanges: Sequence[Exchange],
    *,
    clock: Clock | None = None,
    url: str = "scripted://",
    **driver_kwargs: Any,
) -> Iterator[Any]:
    """Build `driver_class(url, clock, port_opener=..., **driver_kwargs)` on a scripted port, yield the
    driver, and on a clean exit check that every scripted exchange happened.

        with expected_protocol(NewportSMC100, [(b"1TP\\r\\n", b"1TP2.5\\r\\n")]) as stage:
            assert stage.position_m() == 2.5e-3
    """
    clock = clock if clock is not None else VirtualClock()
    port = ScriptedPort(exchanges, clock)
    driver = driver_class(url, clock, port_opener=port.open_for, **driver_kwargs)
    _PORTS[driver] = port
    yield driver
    port.assert_done()


def scripted_port(driver: Any) -> ScriptedPort:
    """The scripted port under a driver built by `expected_protocol` (e.g. to check `.settings`, the baud rate
    and flow control the driver opened it with)."""
    return _PORTS[driver]
