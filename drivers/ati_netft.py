"""Driver for an ATI F/T sensor behind a Net F/T box, over its RDT UDP protocol (port 49152). Implements
`hamr_bench.interfaces.ForceSensor` on one force axis. An alternative to reading the Nano17's gauges with a
DAQ.

Protocol (ATI Net F/T manual, RDT interface): a request is 8 bytes big-endian `!HHI` = (0x1234, command,
sample count); command 2 starts high-speed streaming of `count` records (0 = until stopped), 0 stops, 0x42
sets the box's software bias. A record is 36 bytes `!IIIiiiiii` = (RDT sequence, F/T sequence, status, Fx, Fy,
Fz, Tx, Ty, Tz in counts); force = counts / counts-per-force, torque = counts / counts-per-torque, both
configured on the box (its web page shows them), hence required parameters here. A non-zero status word means
the box reports a problem (saturation, gauge or supply fault): DeviceFault.

Waiting happens in the socket (`settimeout`): a UDP reply has no modelled latency to advance a clock by, so
this driver is for real boxes and loopback emulators on a real clock. Stream sample times are the rig time of
the first record plus RDT sequence / `rdt_rate_Hz` (the output rate set on the box), so lost datagrams leave
gaps.
"""

from __future__ import annotations

import math
import socket
import struct
from typing import Literal, overload

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceProtocolError, DeviceTimeout
from hamr_bench.interfaces import ForceSample

RDT_PORT = 49152
HEADER = 0x1234
CMD_STOP, CMD_STREAM, CMD_BIAS = 0x0000, 0x0002, 0x0042
REQUEST = struct.Struct("!HHI")
RECORD = struct.Struct("!IIIiiiiii")
_AXES = ("Fx", "Fy", "Fz")


def request(command: int, count: int = 0) -> bytes:
    return REQUEST.pack(HEADER, command, count)


class AtiNetFt:
    """An F/T sensor on a Net F/T box at `host`."""

    def __init__(
        self,
        clock: Clock,
        host: str,
        *,
        counts_per_force: float,
        counts_per_torque: float,
        capacity_N: float,
        port: int = RDT_PORT,
        axis: str = "Fz",
        sign: float = 1.0,
        rdt_rate_Hz: float = 1000.0,
        timeout_s: float = 1.0,
        drain_settle_s: float = 0.05,
        name: str = "force_sensor",
    ) -> None:
        checks = (("counts_per_force", counts_per_force), ("counts_per_torque", counts_per_torque),
                  ("capacity_N", capacity_N), ("rdt_rate_Hz", rdt_rate_Hz), ("timeout_s", timeout_s))
        for label, value in checks:
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"AtiNetFt {name}: {label} must be positive, got {value!r}")
        if axis not in _AXES or sign not in (1, -1, 1.0, -1.0):
            raise ConfigError(
                f"AtiNetFt {name}: axis must be Fx/Fy/Fz and sign +1/-1, got {axis!r}, {sign!r}"
            )
        self._clock = clock
        self._address = (host, int(port))
        self._cpf = float(counts_per_force)
        self._cpt = float(counts_per_torque)
        self._capacity = float(capacity_N)
        self._axis = _AXES.index(axis)
        self._sign = float(sign)
        self._rate = float(rdt_rate_Hz)
        self._timeout_s = float(timeout_s)
        self._settle_s = float(drain_settle_s)
        self._name = name
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.settimeout(self._timeout_s)
        self._streaming = False
        # (rig time of the first streamed record, its RDT sequence)
        self._stream_origin: tuple[float, int] | None = None

    @property
    def capacity_N(self) -> float:
        return self._capacity

    def tare(self) -> None:
        """The box takes its current reading as the bias (software bias command; it sends no reply)."""
        self._send(request(CMD_BIAS))

    def read_wrench(self) -> tuple[float, ...]:
        """One record: (Fx, Fy, Fz in N, Tx, Ty, Tz in N m)."""
        if self._streaming:
            raise ConfigError(f"{self._name}: single readings while streaming; call stop_stream() first")
        self._send(request(CMD_STREAM, 1))
        _, wrench = self._parse(self._receive(blocking=True))
        return wrench

    def read_N(self) -> float:
        return self._sign * self.read_wrench()[self._axis]

    def start_stream(self) -> None:
        self._drain()
        self._send(request(CMD_STREAM, 0))
        self._streaming = True
        self._stream_origin = None

    def read_stream(self) -> list[ForceSample]:
        if not self._streaming:
            return []
        samples: list[ForceSample] = []
        while True:
            data = self._receive(blocking=False)
            if data is None:
                return samples
            rdt_seq, wrench = self._parse(data)
            if self._stream_origin is None:
                self._stream_origin = (self._clock.now_s(), rdt_seq)
            t0, seq0 = self._stream_origin
            samples.append(ForceSample(t0 + ((rdt_seq - seq0) & 0xFFFFFFFF) / self._rate,
                                       self._sign * wrench[self._axis]))

    def stop_stream(self) -> None:
        if self._streaming:
            self._send(request(CMD_STOP))
            self._streaming = False
        self._drain()

    def close(self) -> None:
        try:
            self.stop_stream()
        finally:
            self._sock.close()

    # ---- internals -----------------------------------------------------------------------------------------
    def _send(self, payload: bytes) -> None:
        try:
            self._sock.sendto(payload, self._address)
        except OSError as exc:
            raise DeviceFault(f"{self._name}: cannot reach Net F/T at {self._address[0]}:{self._address[1]} "
                              f"({exc.strerror or exc})", device=self._name) from None

    @overload
    def _receive(self, blocking: Literal[True], wait_s: float | None = None) -> bytes: ...

    @overload
    def _receive(self, blocking: bool, wait_s: float | None = None) -> bytes | None: ...

    def _receive(self, blocking: bool, wait_s: float | None = None) -> bytes | None:
        """One record; None when not `blocking` and none has come within `wait_s` (blocking: DeviceTimeout)."""
        try:
            self._sock.settimeout(self._timeout_s if blocking else (wait_s or 0.0))
            data, _ = self._sock.recvfrom(1024)
            return data
        except (TimeoutError, BlockingIOError):
            if blocking:
                raise DeviceTimeout(f"{self._name}: no record from Net F/T at {self._address[0]} within "
                                    f"{self._timeout_s:g} s", device=self._name) from None
            return None
        except OSError as exc:  # e.g. ICMP port unreachable reported on the next receive
            raise DeviceFault(
                f"{self._name}: Net F/T at {self._address[0]} unreachable ({exc.strerror or exc})",
                device=self._name,
            ) from None

    def _drain(self) -> None:
        # records still in flight after a stop arrive late: wait until the line has been quiet for
        # `drain_settle_s` (bounded by the timeout, for a box that ignores the stop)
        deadline = self._clock.now_s() + self._timeout_s
        budget = int(self._timeout_s * self._rate) + 100  # also bounds it on a clock that does not run
        while self._receive(blocking=False, wait_s=self._settle_s) is not None:
            budget -= 1
            if self._clock.now_s() > deadline or budget < 0:
                raise DeviceFault(
                    f"{self._name}: Net F/T keeps streaming after a stop request", device=self._name
                )

    def _parse(self, data: bytes) -> tuple[int, tuple[float, ...]]:
        if len(data) != RECORD.size:
            raise DeviceProtocolError(
                f"{self._name}: Net F/T record of {len(data)} bytes, expected {RECORD.size}",
                device=self._name,
            )
        rdt_seq, _ft_seq, status, *counts = RECORD.unpack(data)
        if status != 0:
            raise DeviceFault(
                f"{self._name}: Net F/T reports status 0x{status:08X} (saturation or sensor fault)",
                device=self._name,
            )
        wrench = tuple(c / self._cpf for c in counts[:3]) + tuple(c / self._cpt for c in counts[3:])
        if abs(wrench[self._axis]) > self._capacity:
            raise DeviceFault(
                f"{self._name}: overload: {_AXES[self._axis]} reads {wrench[self._axis]:.4g} N, "
                f"capacity {self._capacity:g} N",
                device=self._name,
            )
        return rdt_seq, wrench
