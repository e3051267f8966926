"""Driver for Loadstar Sensors load cells on a DI-1000 (DI-100U/DI-1000U) or iLoad interface, over a USB
serial port (9600 8N1 default, command + CR, replies end CR LF).

Implements `hamr_bench.interfaces.ForceSensor` in newtons: identify (MODEL and serial number), units,
capacity, tare, single reading, streaming with a clean stop. Opening the port stops and drains a sensor an
earlier program left streaming (CR, read until quiet, CR -> `A`). Readings are converted from the sensor's
unit (lb, kg, g, N, kN, oz; millipounds on iLoad). The zero is kept here, never in the sensor (its tare command
is not sent), so every reading the sensor sends is the load on it: a reading beyond the capacity is a DeviceFault
(overload) whenever it comes; the runner checks force limits of its own too. What each interface family accepts
and answers is Loadstar's published command pages, as tables in `hamr_bench.instruments.loadstar_reference`."""

from __future__ import annotations

import math
import serial

from drivers.serial_line import PortOpener, SerialLine
from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceProtocolError, DeviceTimeout
from hamr_bench.instruments.loadstar_reference import FAMILIES, NEWTONS_PER_UNIT
from hamr_bench.interfaces import ForceSample

__all__ = ["COMMAND_SETS", "NEWTONS_PER_UNIT", "LoadstarSensor"]

COMMAND_SETS = FAMILIES  # the interface families a rig file's `command_set` may name


class LoadstarSensor:
    """One Loadstar sensor. Opening it drains a stream left running and reads its units and capacity."""

    def __init__(
        self,
        url_or_port: str,
        clock: Clock,
        *,
        command_set: str = "di1000",
        baudrate: int = 9600,
        timeout_s: float = 0.5,
        tare_readings: int = 16,
        drain_quiet_s: float = 0.05,
        stream_rate_Hz: float = 150.0,
        capacity_N: float | None = None,
        device: str = "force_sensor",
        port_opener: PortOpener = serial.serial_for_url,
    ) -> None:
        if command_set not in COMMAND_SETS:
            raise ValueError(f"{device}: command_set {command_set!r} not one of {sorted(COMMAND_SETS)}")
        self.clock = clock
        self.device = device
        self.family = FAMILIES[command_set]
        self.timeout_s = float(timeout_s)
        if not (isinstance(tare_readings, int) and tare_readings >= 1):
            raise ConfigError(f"{device}: tare_readings must be a whole number >= 1, got {tare_readings!r}")
        self.tare_readings = tare_readings
        self._zero_N = 0.0  # the tare: what the sensor read with nothing on it, taken off every reading
        self.drain_quiet_s = float(drain_quiet_s)
        self.stream_rate_Hz = float(stream_rate_Hz)
        self._streaming = False
        self._last_stream_data_s = 0.0
        self._last_sample_s = -math.inf
        if not (isinstance(baudrate, (int, float)) and baudrate > 0):
            raise ConfigError(f"{device}: baudrate must be a positive number, got {baudrate!r}")
        self._byte_time_s = 10.0 / float(baudrate)  # 8N1: a start bit, 8 data bits, a stop bit
        self._line = SerialLine(
            url_or_port,
            clock,
            device=device,
            baudrate=baudrate,
            timeout_s=timeout_s,
            xonxoff=False,
            write_terminator=b"\r",
            read_terminator=b"\r\n",
            port_opener=port_opener,
        )
        try:
            self._stop_and_drain()
            self.reading_unit = self.family.reading_unit or self.units()
            self._newtons_per_reading_unit = self._unit_factor(self.reading_unit)
            if capacity_N is None:
                capacity_unit = self.family.capacity_unit or self.reading_unit
                capacity = self._number(self._line.query(self._command("capacity")), "capacity")
                capacity_N = capacity * self._unit_factor(capacity_unit)
        except Exception:
            self._line.close()
            raise
        if not capacity_N > 0:
            raise DeviceProtocolError(f"{device}: capacity {capacity_N} N is not positive", device)
        self._capacity_N = float(capacity_N)

    # -- helpers -------------------------------------------------------------------------------------------
    def _command(self, role: str) -> str:
        command = self.family.command(role)
        if command is None:
            message = f"{self.device}: {self.family.title} has no {role} command"
            raise DeviceProtocolError(message, self.device)
        return command

    def _unit_factor(self, unit: str) -> float:
        factor = NEWTONS_PER_UNIT.get(unit.strip().upper())
        if factor is None:
            known = ", ".join(NEWTONS_PER_UNIT)
            raise DeviceProtocolError(f"{self.device}: unknown unit {unit!r} (known: {known})", self.device)
        return factor

    def _number(self, text: str, what: str) -> float:
        try:
            value = float(text)
        except ValueError:
            value = math.nan
        if not math.isfinite(value):
            raise DeviceProtocolError(f"{self.device}: {what} reply {text!r} is not a number", self.device)
        return value

    def _gross_N(self, text: str, time_s: float) -> float:
        """The load on the sensor a reading says, before the tare; DeviceFault beyond the capacity."""
        force_N = self._number(text, "reading") * self._newtons_per_reading_unit
        if abs(force_N) > self._capacity_N:
            raise DeviceFault(
                f"{self.device}: overload: {force_N:.4g} N at t={time_s:.3f} s "
                f"beyond capacity {self._capacity_N:.4g} N",
                self.device,
            )
        return force_N

    def _to_N(self, text: str, time_s: float) -> float:
        return self._gross_N(text, time_s) - self._zero_N

    def _stop_and_drain(self) -> None:
        """CR stops a stream; discard everything until the line is quiet; CR must then answer `A`."""
        self._line.write_line("")
        self._line.drain(self.drain_quiet_s)
        reply = self._line.query("")
        if reply.upper() != "A":
            raise DeviceProtocolError(f"{self.device}: expected 'A' after CR, got {reply!r}", self.device)

    # -- identity ------------------------------------------------------------------------------------------
    def identify(self) -> tuple[str, str]:
        """(model, identifier): MODEL and ID on a DI-1000, SS0 and SS1 on an iLoad."""
        return self._line.query(self._command("model")), self._line.query(self._command("identify"))

    def units(self) -> str:
        if self.family.command("units") is None:
            return self.family.reading_unit or "MLB"
        return self._line.query(self._command("units")).upper()

    # -- ForceSensor surface -------------------------------------------------------------------------------
    @property
    def capacity_N(self) -> float:
        return self._capacity_N

    @property
    def zero_N(self) -> float:
        """The load the last tare found on the sensor (its reading then), taken off every reading since."""
        return self._zero_N

    def tare(self) -> None:
        """The zero is the mean of `tare_readings` single readings, each checked against the capacity.

        Not the sensor's own tare (CT0): a sensor that saturates while it tares zeroes at its saturation level and
        then reads ~0 whatever pushes on it, so no later reading could show the overload and a contact search
        would drive the leg into it blind. Kept here, every reading is the load on the sensor and is checked
        before the zero is taken off."""
        command = self._command("read")
        total_N = 0.0
        for _ in range(self.tare_readings):
            total_N += self._gross_N(self._line.query(command), self.clock.now_s())
        self._zero_N = total_N / self.tare_readings

    def read_N(self) -> float:
        reply = self._line.query(self._command("read"))
        return self._to_N(reply, self.clock.now_s())

    def start_stream(self) -> None:
        self._line.write_line(self._command("stream"))
        self._streaming = True
        self._last_stream_data_s = self.clock.now_s()

    def read_stream(self) -> list[ForceSample]:
        """Samples received since the last call. They arrive without timestamps; the last one of a batch is
        stamped with its arrival time and earlier ones are spaced back at the stream period or the time a line
        takes on the wire at the baud rate, whichever is longer (never before the previous batch).
        DeviceTimeout when no line has come for the timeout."""
        if not self._streaming:
            return []
        lines = self._line.read_available_lines("stream")
        now_s = self.clock.now_s()
        if not lines:
            if now_s - self._last_stream_data_s > self.timeout_s:
                pending = self._line.pending_bytes
                if pending:
                    raise DeviceProtocolError(
                        f"{self.device}: stream bytes without line ends for {self.timeout_s:g} s "
                        f"({pending[:40]!r}...)",
                        self.device,
                    )
                message = f"{self.device}: stream silent for more than {self.timeout_s:g} s"
                raise DeviceTimeout(message, self.device)
            return []
        self._last_stream_data_s = now_s
        period_s = 1.0 / self.stream_rate_Hz
        # A sensor sends its next reading a period later, or once the previous line has left if the baud rate
        # is the limit (9600 baud carries ~100 short lines/s, less than the 150 Hz stream): a batch that piled
        # up while the caller was busy is spaced back at that pace, not squeezed to the nominal rate.
        spacing_s = [max(period_s, (len(text) + 2) * self._byte_time_s) for text in lines]
        stamps = [now_s] * len(lines)
        for i in range(len(lines) - 2, -1, -1):
            stamps[i] = stamps[i + 1] - spacing_s[i]
        samples: list[ForceSample] = []
        for text, stamp in zip(lines, stamps, strict=True):
            time_s = min(max(stamp, self._last_sample_s + 1e-9), now_s)
            try:
                force_N = self._to_N(text, time_s)
            except (DeviceFault, DeviceProtocolError) as exc:
                # The readings before the bad line are good: they travel with the error (`samples_before`) so
                # the caller can keep them.
                exc.samples_before = samples
                raise
            samples.append(ForceSample(time_s=time_s, force_N=force_N))
            self._last_sample_s = time_s
        return samples

    def stop_stream(self) -> None:
        self._streaming = False
        self._stop_and_drain()

    def close(self) -> None:
        if self._streaming:
            try:
                self.stop_stream()
            except (DeviceTimeout, DeviceProtocolError, DeviceFault):
                pass  # closing anyway; the next open drains
        self._line.close()
