"""A line-oriented serial port for drivers: open by URL, write one command, read one terminated reply within a
timeout measured on the injected Clock, and map every way that can fail onto the `hamr_bench.errors` types.

Owned here: opening (`serial.serial_for_url`, so `/dev/ttyUSB0`, `COM3`, a pty path and `hamrsim://NAME` all
work), the line buffer, timeouts, the inter-command gap, draining, and the error mapping: silence ->
DeviceTimeout, bytes that are not a line of printable ASCII -> DeviceProtocolError,
`serial.SerialException`/`OSError` -> DeviceFault ("disconnected").

pyserial's own `read_until` measures its timeout in wall time, which would let a virtual-clock read spin
through simulated time; this module measures every deadline on the Clock instead and only asks the port for
one chunk at a time with the time that is left."""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from typing import Any

import serial

from hamr_bench.clock import Clock
from hamr_bench.errors import DeviceFault, DeviceProtocolError, DeviceTimeout

PortOpener = Callable[..., Any]

_PRINTABLE = set(range(0x20, 0x7F)) | {0x09}


class SerialLine:
    """One open serial port speaking a line protocol. All waiting goes through `clock`."""

    def __init__(
        self,
        url_or_port: str,
        clock: Clock,
        *,
        device: str,
        baudrate: int,
        timeout_s: float,
        xonxoff: bool = False,
        write_terminator: bytes = b"\r\n",
        read_terminator: bytes = b"\r\n",
        command_gap_s: float = 0.0,
        max_line_bytes: int = 256,
        port_opener: PortOpener = serial.serial_for_url,
    ) -> None:
        if timeout_s <= 0:
            raise ValueError(f"{device}: timeout_s must be > 0, got {timeout_s}")
        self.url = url_or_port
        self.clock = clock
        self.device = device
        self.timeout_s = float(timeout_s)
        self.write_terminator = write_terminator
        self.read_terminator = read_terminator
        self.command_gap_s = float(command_gap_s)
        self.max_line_bytes = int(max_line_bytes)
        self._buffer = bytearray()
        self._last_write_s: float | None = None
        try:
            self._port = port_opener(
                url_or_port,
                baudrate=baudrate,
                bytesize=serial.EIGHTBITS,
                parity=serial.PARITY_NONE,
                stopbits=serial.STOPBITS_ONE,
                xonxoff=xonxoff,
                timeout=self.timeout_s,
                write_timeout=self.timeout_s,
            )
        except (serial.SerialException, OSError, ValueError) as exc:
            raise DeviceFault(f"{device}: cannot open serial port {url_or_port!r}: {exc}", device) from exc

    # -- error mapping -------------------------------------------------------------------------------------
    @contextlib.contextmanager
    def _io(self, what: str) -> Iterator[None]:
        try:
            yield
        except serial.SerialTimeoutException as exc:
            message = f"{self.device}: {what} timed out on {self.url!r}: {exc}"
            raise DeviceTimeout(message, self.device) from exc
        except (serial.SerialException, OSError) as exc:
            message = f"{self.device}: disconnected ({self.url!r}) during {what}: {exc}"
            raise DeviceFault(message, self.device) from exc

    # -- writing -------------------------------------------------------------------------------------------
    def write_line(self, command: str) -> None:
        """Send `command` plus the write terminator, after waiting out the inter-command gap."""
        if self.command_gap_s > 0 and self._last_write_s is not None:
            wait_s = self._last_write_s + self.command_gap_s - self.clock.now_s()
            if wait_s > 0:
                self.clock.sleep(wait_s)
        with self._io(f"write of {command!r}"):
            self._port.write(command.encode("ascii") + self.write_terminator)
        self._last_write_s = self.clock.now_s()

    # -- reading -------------------------------------------------------------------------------------------
    def _read_chunk(self, timeout_s: float, what: str) -> bytes:
        with self._io(what):
            self._port.timeout = max(0.0, timeout_s)
            waiting = self._port.in_waiting
            return self._port.read(max(1, waiting))

    def _take_line(self) -> bytes | None:
        index = self._buffer.find(self.read_terminator)
        if index < 0:
            return None
        line = bytes(self._buffer[:index])
        del self._buffer[: index + len(self.read_terminator)]
        return line

    def _decode(self, raw: bytes, what: str) -> str:
        if any(b not in _PRINTABLE for b in raw):
            raise DeviceProtocolError(f"{self.device}: unreadable reply {raw!r} to {what}", self.device)
        return raw.decode("ascii").strip()

    def read_line(self, what: str = "a reply", timeout_s: float | None = None) -> str:
        """The next terminated line (terminator removed), within `timeout_s` on the clock."""
        timeout_s = self.timeout_s if timeout_s is None else timeout_s
        deadline_s = self.clock.now_s() + timeout_s
        while True:
            raw = self._take_line()
            if raw is not None:
                return self._decode(raw, what)
            if len(self._buffer) > self.max_line_bytes:
                junk = bytes(self._buffer[:40])
                self._buffer.clear()
                raise DeviceProtocolError(
                    f"{self.device}: no line terminator in {self.max_line_bytes} bytes ({junk!r}...) "
                    f"after {what}",
                    self.device,
                )
            remaining_s = deadline_s - self.clock.now_s()
            if remaining_s <= 0:
                partial = f"; partial bytes {bytes(self._buffer)!r}" if self._buffer else ""
                self._buffer.clear()
                raise DeviceTimeout(
                    f"{self.device}: no reply to {what} within {timeout_s:g} s on {self.url!r}{partial}",
                    self.device,
                )
            self._buffer += self._read_chunk(remaining_s, what)

    def query(self, command: str, timeout_s: float | None = None) -> str:
        self.write_line(command)
        return self.read_line(repr(command), timeout_s)

    def read_available_lines(self, what: str = "stream") -> list[str]:
        """Every complete line already received, without waiting (a partial line stays buffered)."""
        with self._io(what):
            waiting = self._port.in_waiting
            if waiting:
                self._port.timeout = 0
                self._buffer += self._port.read(waiting)
        lines = []
        while (raw := self._take_line()) is not None:
            try:
                lines.append(self._decode(raw, what))
            except DeviceProtocolError:
                if not lines:
                    raise
                # Hand over the good lines received before the bad one; the bad one raises on the next call.
                self._buffer[:0] = raw + self.read_terminator
                return lines
        if len(self._buffer) > self.max_line_bytes:
            junk = bytes(self._buffer[:40])
            self._buffer.clear()
            message = f"{self.device}: no line terminator in stream data ({junk!r}...)"
            raise DeviceProtocolError(message, self.device)
        return lines

    @property
    def pending_bytes(self) -> bytes:
        """Received bytes not yet part of a complete line."""
        return bytes(self._buffer)

    def drain(self, quiet_s: float, max_s: float | None = None) -> bytes:
        """Read and discard until the line is silent for `quiet_s`; DeviceProtocolError if it never goes quiet
        within `max_s` (default: the timeout)."""
        max_s = self.timeout_s if max_s is None else max_s
        deadline_s = self.clock.now_s() + max_s
        drained = bytearray(self._buffer)
        self._buffer.clear()
        while True:
            chunk = self._read_chunk(quiet_s, "drain")
            if not chunk:
                return bytes(drained)
            drained += chunk
            if self.clock.now_s() >= deadline_s:
                raise DeviceProtocolError(
                    f"{self.device}: still sending after {max_s:g} s of draining ({bytes(drained[-40:])!r})",
                    self.device,
                )

    def close(self) -> None:
        with contextlib.suppress(serial.SerialException, OSError):
            self._port.close()
