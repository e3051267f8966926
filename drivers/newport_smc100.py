"""Driver for a Newport SMC100PP controller with its stage, over RS-232 (57600 8N1, XON/XOFF, CR LF).

Implements `hamr_bench.interfaces.Stage` in metres (the controller speaks mm) plus the controller's own
surface: status with every state code and error bit decoded (tables in `smc100_codes`), TE error read-back
after every command that can be rejected, stop, reset, enable/disable (MM), velocity and acceleration (VA/AC),
soft limits (SL/SR), motion-time query (PT), identity (VE, ID?). The command set, states and letters are the
reference's tables in `hamr_bench.instruments.smc100_reference`. Lessons from public drivers are rules here:
a motion command
(OR/PA/PR) is sent once and never retried; completion is "any READY code" (32-35), never "saw MOVING then
READY", so a move to the current position completes at once; TS is polled through the clock; a move that does
not finish in time is stopped and reported as DeviceTimeout. Moves outside the soft limits are refused before
anything is sent."""

from __future__ import annotations

import contextlib
import math

import serial

from drivers import smc100_codes as codes
from drivers.serial_line import PortOpener, SerialLine
from hamr_bench.clock import Clock
from hamr_bench.errors import DeviceError, DeviceFault, DeviceProtocolError, DeviceTimeout, SafetyLimitError

_MM = 1e-3


def format_mm(value_m: float) -> str:
    """Metres -> the decimal mm text sent to the controller (up to 6 decimals = 1 nm, no exponent)."""
    text = f"{value_m / _MM:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


class NewportSMC100:
    """One SMC100 controller (address 1-31) and its stage."""

    def __init__(
        self,
        url_or_port: str,
        clock: Clock,
        *,
        address: int = 1,
        timeout_s: float = 0.5,
        poll_interval_s: float = 0.05,
        motion_timeout_s: float = 120.0,
        limits_m: tuple[float, float] | None = None,
        command_gap_s: float = 0.0,
        reset_timeout_s: float = 10.0,
        baudrate: int = 57600,
        device: str = "stage",
        port_opener: PortOpener = serial.serial_for_url,
    ) -> None:
        if not 1 <= int(address) <= 31:
            raise ValueError(f"{device}: SMC100 address must be 1..31, got {address}")
        self.clock = clock
        self.address = int(address)
        self.device = device
        self.poll_interval_s = float(poll_interval_s)
        self.motion_timeout_s = float(motion_timeout_s)
        self.reset_timeout_s = float(reset_timeout_s)
        if limits_m is not None and not limits_m[0] <= limits_m[1]:
            raise ValueError(f"{device}: limits_m low {limits_m[0]} > high {limits_m[1]}")
        self._configured_limits_m = None if limits_m is None else (float(limits_m[0]), float(limits_m[1]))
        self._controller_limits_m: tuple[float, float] | None = None
        self._line = SerialLine(
            url_or_port,
            clock,
            device=device,
            baudrate=baudrate,
            timeout_s=timeout_s,
            xonxoff=True,
            write_terminator=b"\r\n",
            read_terminator=b"\r\n",
            command_gap_s=command_gap_s,
            port_opener=port_opener,
        )
        if limits_m is None:
            # Read now, not lazily in the property: `isinstance(x, Stage)` evaluates properties on Python
            # 3.11.
            try:
                self._controller_limits_m = self.soft_limits_m()
            except Exception:
                self._line.close()
                raise

    # -- wire ----------------------------------------------------------------------------------------------
    def _send(self, command: str) -> None:
        self._line.write_line(f"{self.address}{command}")

    def _query(self, command: str, argument: str = "", timeout_s: float | None = None) -> str:
        """Send `nn<command><argument>` and return the value after the echoed `nn<command>`."""
        sent = f"{self.address}{command}{argument}"
        reply = self._line.query(sent, timeout_s)
        echo = f"{self.address}{command}"
        if not reply.upper().startswith(echo):
            message = f"{self.device}: reply {reply!r} to {sent!r} does not echo {echo!r}"
            raise DeviceProtocolError(message, self.device)
        return reply[len(echo) :].strip()

    def _query_number(self, command: str, argument: str = "") -> float:
        value = self._query(command, argument)
        try:
            number = float(value)
        except ValueError:
            number = math.nan
        if not math.isfinite(number):
            raise DeviceProtocolError(
                f"{self.device}: reply to {self.address}{command}{argument} is not a number: {value!r}",
                self.device,
            )
        return number

    def error_letter(self) -> str:
        """Read (and thereby clear) the controller's last command error letter; '@' means none."""
        value = self._query("TE")
        if len(value) != 1 or value not in codes.ERROR_LETTERS:
            message = f"{self.device}: TE reply {value!r} is not an error letter"
            raise DeviceProtocolError(message, self.device)
        return value

    def _checked(self, command: str) -> None:
        """Send a command the controller may reject, then read TE once."""
        self._send(command)
        letter = self.error_letter()
        if letter != "@":
            raise DeviceFault(
                f"{self.device}: controller rejected {self.address}{command}: "
                f"{letter} ({codes.ERROR_LETTERS[letter]})",
                self.device,
            )

    # -- status --------------------------------------------------------------------------------------------
    def status(self) -> codes.Smc100Status:
        value = self._query("TS")
        try:
            return codes.parse_status(value)
        except ValueError as exc:
            raise DeviceProtocolError(f"{self.device}: bad TS reply {value!r}: {exc}", self.device) from exc

    def is_moving(self) -> bool:
        """True while MOVING, HOMING or JOGGING, False when READY. Any other state (DISABLE, NOT REFERENCED
        after a
        tripped switch, ...) or an error bit is a DeviceFault: the carriage no longer holds its position, so a
        caller checking on it between moves must not take it for "still"."""
        status = self.status()
        if status.error_bits or not (status.is_ready or status.is_moving):
            raise DeviceFault(f"{self.device}: stage not holding position: {status.describe()}", self.device)
        return status.is_moving

    def position_m(self) -> float:
        return self._query_number("TP") * _MM

    def _wait_ready(self, what: str, timeout_s: float) -> codes.Smc100Status:
        """Poll TS until any READY code. A state that is neither READY nor in motion, or any error bit, is a
        DeviceFault; no READY within `timeout_s` stops the stage and raises DeviceTimeout."""
        deadline_s = self.clock.now_s() + timeout_s
        while True:
            status = self.status()
            if status.error_bits:
                raise DeviceFault(f"{self.device}: {what} failed: {status.describe()}", self.device)
            if status.is_ready:
                return status
            if not status.is_moving:
                raise DeviceFault(f"{self.device}: {what} ended in {status.describe()}", self.device)
            if self.clock.now_s() >= deadline_s:
                with contextlib.suppress(DeviceError):
                    self.stop()  # best effort: the timeout is the message that matters
                raise DeviceTimeout(
                    f"{self.device}: {what} not finished within {timeout_s:g} s (last {status.describe()}); "
                    "stage stopped",
                    self.device,
                )
            self.clock.sleep(self.poll_interval_s)

    # -- Stage surface -------------------------------------------------------------------------------------
    @property
    def limits_m(self) -> tuple[float, float]:
        """Driver-side travel limits: the configured ones, else the controller's SL/SR as last read or set."""
        if self._configured_limits_m is not None:
            return self._configured_limits_m
        assert self._controller_limits_m is not None
        return self._controller_limits_m

    def home(self, timeout_s: float | None = None) -> None:
        """Reference the stage (OR, sent once) and wait for READY. Already READY: nothing to do."""
        status = self.status()
        if status.is_ready:
            return
        if status.state != "NOT REFERENCED":
            raise DeviceFault(
                f"{self.device}: cannot home in {status.describe()}; reset() or enable() first", self.device
            )
        self._checked("OR")
        self._wait_ready("homing", self._motion_timeout(timeout_s))

    def _motion_timeout(self, timeout_s: float | None) -> float:
        return self.motion_timeout_s if timeout_s is None else timeout_s

    def _check_target(self, position_m: float) -> None:
        low, high = self.limits_m
        if not math.isfinite(position_m) or not low <= position_m <= high:
            raise SafetyLimitError(
                f"{self.device}: target {position_m:.6g} m outside stage limits [{low:.6g}, {high:.6g}] m"
            )

    def move_to(self, position_m: float, timeout_s: float | None = None) -> None:
        """Absolute move (PA, sent once); blocks until READY."""
        self._check_target(position_m)
        self._checked(f"PA{format_mm(position_m)}")
        self._wait_ready(f"move to {position_m:.6g} m", self._motion_timeout(timeout_s))

    def move_by(self, displacement_m: float, timeout_s: float | None = None) -> None:
        """Relative move (PR, sent once) after checking where it would end; blocks until READY."""
        self._check_target(self.position_m() + displacement_m)
        self._checked(f"PR{format_mm(displacement_m)}")
        self._wait_ready(f"move by {displacement_m:.6g} m", self._motion_timeout(timeout_s))

    def stop(self) -> None:
        """ST to this controller only (ST without an address would stop the whole chain), then TE. ST is
        refused in
        NOT REFERENCED and CONFIGURATION (H, I): nothing moves then, but the letter must be read here, or the
        next
        checked command would find it and report a rejection of its own."""
        self._send("ST")
        self.error_letter()

    def identify(self) -> tuple[str, str]:
        """(controller revision as `VE` gives it, stage identifier as `ID?` gives it)."""
        return self._query("VE"), self._query("ID", "?")

    def reset(self) -> None:
        """RS, then poll TS (the rebooting controller ignores it for a while) until NOT REFERENCED."""
        self._send("RS")
        deadline_s = self.clock.now_s() + self.reset_timeout_s
        while True:
            self.clock.sleep(self.poll_interval_s)
            try:
                status = self.status()
            except DeviceTimeout:
                if self.clock.now_s() >= deadline_s:
                    raise DeviceTimeout(
                        f"{self.device}: no answer within {self.reset_timeout_s:g} s after reset (RS)",
                        self.device,
                    ) from None
                continue
            if status.state != "NOT REFERENCED":
                message = f"{self.device}: after reset expected NOT REFERENCED, got {status.describe()}"
                raise DeviceFault(message, self.device)
            if self._configured_limits_m is None:
                self._controller_limits_m = self.soft_limits_m()
            return

    def enable(self) -> None:
        """MM1: DISABLE -> READY."""
        self._checked("MM1")

    def disable(self) -> None:
        """MM0: READY -> DISABLE (motor unpowered)."""
        self._checked("MM0")

    def velocity_m_per_s(self) -> float:
        return self._query_number("VA", "?") * _MM

    def set_velocity(self, velocity_m_per_s: float) -> None:
        self._checked(f"VA{format_mm(velocity_m_per_s)}")

    def acceleration_m_per_s2(self) -> float:
        return self._query_number("AC", "?") * _MM

    def set_acceleration(self, acceleration_m_per_s2: float) -> None:
        self._checked(f"AC{format_mm(acceleration_m_per_s2)}")

    def soft_limits_m(self) -> tuple[float, float]:
        """The controller's (SL, SR) in metres."""
        return self._query_number("SL", "?") * _MM, self._query_number("SR", "?") * _MM

    def set_soft_limits(self, low_m: float, high_m: float) -> None:
        if not low_m <= high_m:
            raise SafetyLimitError(f"{self.device}: soft limits low {low_m} m > high {high_m} m")
        self._checked(f"SL{format_mm(low_m)}")
        self._checked(f"SR{format_mm(high_m)}")
        self._controller_limits_m = (low_m, high_m)

    def motion_time_s(self, displacement_m: float) -> float:
        """PT: how long the controller will take for a relative move of `displacement_m`."""
        return self._query_number("PT", format_mm(abs(displacement_m)))

    def close(self) -> None:
        self._line.close()
