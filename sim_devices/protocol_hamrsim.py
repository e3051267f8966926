"""pyserial URL handler for `hamrsim://NAME`: an in-process serial port onto an emulator registered with
`sim_devices.serial_link.register_endpoint`. Found by pyserial once "sim_devices" is in
`serial.protocol_handler_packages` (registering an endpoint does that).

Reads follow the endpoint's clock: on a VirtualClock a read with a timeout jumps virtual time to the moment
the next byte is due, or to now + timeout if nothing is due by then, and returns what has arrived; on a
RealClock it waits in real time. No path waits longer than the timeout; a blocking read (timeout None) with
nothing ever coming raises instead of hanging. A disconnected endpoint makes reads and writes raise
`serial.SerialException`, as a pulled USB adapter does."""

from __future__ import annotations

import urllib.parse
from typing import TYPE_CHECKING

from serial.serialutil import PortNotOpenError, SerialBase, SerialException

from sim_devices.serial_link import SerialEndpoint, get_endpoint, wait_until

if TYPE_CHECKING:
    from typing_extensions import Buffer  # collections.abc.Buffer from Python 3.12


class Serial(SerialBase):
    """A pyserial port backed by a registered `SerialEndpoint`."""

    def __init__(self, *args, **kwargs) -> None:
        self._endpoint: SerialEndpoint | None = None
        self._rx = bytearray()
        super().__init__(*args, **kwargs)

    def open(self) -> None:
        if self.is_open:
            raise SerialException("Port is already open.")
        if self.port is None:
            raise SerialException("Port must be configured before it can be used.")
        parts = urllib.parse.urlsplit(self.port)
        if parts.scheme != "hamrsim":
            raise SerialException(f"expected a URL hamrsim://NAME, got {self.port!r}")
        name = parts.netloc or parts.path.lstrip("/")
        endpoint = get_endpoint(name)
        if endpoint is None:
            raise SerialException(f"no simulated device registered as {name!r} ({self.port})")
        if not endpoint.is_connected():
            raise SerialException(f"could not open port {self.port}: device disconnected")
        self._endpoint = endpoint
        self.is_open = True
        # Serial.open() on a real port flushes input: bytes sent before the open are lost.
        self.reset_input_buffer()

    def close(self) -> None:
        self.is_open = False
        self._endpoint = None
        self._rx.clear()

    def _reconfigure_port(self) -> None:
        """Baud rate and framing have no meaning here; latency is modelled by the endpoint."""

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    def _update_break_state(self) -> None:
        pass

    def _check(self) -> SerialEndpoint:
        if not self.is_open or self._endpoint is None:
            raise PortNotOpenError()
        if not self._endpoint.is_connected():
            raise SerialException(f"{self.port}: device disconnected")
        return self._endpoint

    def _pull(self, endpoint: SerialEndpoint) -> None:
        self._rx += endpoint.output_until(endpoint.clock.now_s())

    @property
    def in_waiting(self) -> int:
        endpoint = self._check()
        self._pull(endpoint)
        return len(self._rx)

    def read(self, size: int = 1) -> bytes:
        endpoint = self._check()
        clock = endpoint.clock
        timeout_s = self.timeout
        deadline_s = None if timeout_s is None else clock.now_s() + timeout_s
        while True:
            self._pull(endpoint)
            if len(self._rx) >= size or timeout_s == 0:
                break
            next_s = endpoint.next_output_s()
            if next_s is None and deadline_s is None:
                raise SerialException(f"{self.port}: blocking read with no timeout and nothing will arrive")
            if deadline_s is not None and (next_s is None or next_s > deadline_s):
                wait_until(clock, deadline_s)
                self._check()
                self._pull(endpoint)
                break
            if next_s is not None and next_s > clock.now_s():
                wait_until(clock, next_s)
            self._check()
        data = bytes(self._rx[:size])
        del self._rx[:size]
        return data

    def write(self, data: Buffer) -> int:
        endpoint = self._check()
        data = bytes(data)
        endpoint.receive(data)
        return len(data)

    def reset_input_buffer(self) -> None:
        endpoint = self._check()
        self._rx.clear()
        endpoint.discard_output()

    def reset_output_buffer(self) -> None:
        self._check()

    def flush(self) -> None:
        self._check()

    @property
    def out_waiting(self) -> int:
        return 0
