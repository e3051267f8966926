"""Serve a serial emulator on a pseudo-terminal, so any program (a terminal, MATLAB, a driver) can open the
slave's path as if it were `/dev/ttyUSB0`. The emulator should run on a RealClock.

Pitfalls handled (pyserial 3.5 on Linux): the slave is put in raw mode before anything is written (otherwise
the line discipline echoes the emulator's bytes back); this server keeps its own slave fd open for its whole
life (closing it gives EIO on the master whenever no client has the port open); the master is non-blocking so
a client that stops reading cannot stall the loop (bytes beyond `max_pending_bytes` are dropped, as a UART
overruns); XON/XOFF bytes a client's line discipline sends are stripped before the emulator sees them; baud
rate is meaningless on a pty, so latency comes from the emulator's model. A `disconnect` fault closes the
master: the client's next read or write fails, as with a pulled USB adapter."""

from __future__ import annotations

import contextlib
import errno
import os
import pty
import select
import threading
import tty

from sim_devices.serial_link import LineEndpoint

_FLOW_CONTROL = bytes([0x11, 0x13])


class PtyServer:
    """One emulator on one pty pair. `path` is what clients open."""

    def __init__(
        self, endpoint: LineEndpoint, max_wait_s: float = 0.05, max_pending_bytes: int = 65536
    ) -> None:
        self.endpoint = endpoint
        self.max_wait_s = max_wait_s
        self.max_pending_bytes = max_pending_bytes
        self.master_fd, self.slave_fd = pty.openpty()
        tty.setraw(self.slave_fd)
        os.set_blocking(self.master_fd, False)
        self.path = os.ttyname(self.slave_fd)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._pending = bytearray()
        self.disconnected = False

    def serve_forever(self) -> None:
        """Pump bytes both ways until `stop()` or a disconnect fault."""
        endpoint = self.endpoint
        clock = endpoint.clock
        while not self._stop.is_set():
            now_s = clock.now_s()
            if not endpoint.is_connected(now_s):
                self._disconnect()
                return
            self._pending += endpoint.output_until(now_s)
            if len(self._pending) > self.max_pending_bytes:
                del self._pending[: len(self._pending) - self.max_pending_bytes]
            self._flush_pending()
            next_s = endpoint.next_output_s()
            wait_s = self.max_wait_s
            if next_s is not None:
                wait_s = min(wait_s, max(0.0, next_s - clock.now_s()))
            if self._pending:
                wait_s = min(wait_s, 0.002)
            try:
                readable, _, _ = select.select([self.master_fd], [], [], wait_s)
            except (OSError, ValueError):
                return
            if readable:
                try:
                    data = os.read(self.master_fd, 4096)
                except BlockingIOError:
                    continue
                except OSError as exc:
                    if exc.errno == errno.EIO:
                        continue  # no client right now
                    raise
                data = bytes(b for b in data if b not in _FLOW_CONTROL)
                if data:
                    endpoint.receive(data)

    def _flush_pending(self) -> None:
        while self._pending:
            try:
                written = os.write(self.master_fd, self._pending)
            except BlockingIOError:
                return
            except OSError:
                self._pending.clear()
                return
            del self._pending[:written]

    def _disconnect(self) -> None:
        self.disconnected = True
        with contextlib.suppress(OSError):
            os.close(self.master_fd)
        self.master_fd = -1

    def start(self) -> PtyServer:
        """Serve from a background thread (tests, benchmarks)."""
        self._thread = threading.Thread(target=self.serve_forever, name=f"pty:{self.path}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None

    def close(self) -> None:
        self.stop()
        for fd in (self.master_fd, self.slave_fd):
            if fd >= 0:
                with contextlib.suppress(OSError):
                    os.close(fd)
        self.master_fd = self.slave_fd = -1

    def __enter__(self) -> PtyServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.close()
