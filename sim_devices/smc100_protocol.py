"""The SMC100's RS-232 line protocol in front of `Smc100Emulator`: parses `nnAAxx` lines (case-insensitive, CR
LF), dispatches to the state machine, echoes queries (`1TP` -> `1TP1.2345`), stores the TE letter of a
rejected command and stays silent for it, ignores lines for other addresses on the chain, and is deaf while
the controller reboots (RS) or saves its configuration (PW0). Units on the wire are mm, mm/s, mm/s^2 and s."""

from __future__ import annotations

import math
import re
from collections.abc import Callable

import numpy as np

from sim_devices.serial_link import LineEndpoint
from sim_devices.smc100_emulator import Smc100Emulator

_LINE = re.compile(r"^\s*(\d{0,2})\s*([A-Za-z]{2})\s*(.*?)\s*$")
_MM = 1e-3


def format_number(value: float) -> str:
    """Shortest fixed-point text with at most 6 decimals (plain decimals, never an exponent)."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _number(arg: str) -> float | None:
    try:
        value = float(arg)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


class Smc100Protocol(LineEndpoint):
    """Wire side of one SMC100 controller: register it with `serial_link.register_endpoint`, or serve it on
    a pty."""

    def __init__(self, emulator: Smc100Emulator, rng: np.random.Generator | None = None) -> None:
        p = emulator.params
        super().__init__(
            emulator.clock,
            emulator.faults,
            device="smc100",
            baudrate=p.baudrate,
            reply_latency_s=p.reply_latency_s,
            input_terminator=b"\n",
            rng=rng,
        )
        self.emulator = emulator
        self._handlers: dict[str, Callable[[str, str, float], None]] = {
            "TP": self._tp,
            "TS": self._ts,
            "TE": self._te,
            "OR": self._or,
            "PA": self._pa,
            "PR": self._pr,
            "PT": self._pt,
            "ST": self._st,
            "RS": self._rs,
            "MM": self._mm,
            "PW": self._pw,
            "VA": self._va,
            "AC": self._ac,
            "SL": self._sl,
            "SR": self._sr,
            "ID": self._id,
            "VE": self._ve,
        }

    # The terminal user may send CR alone; LF-only and CRLF both end a line. A lone CR is accepted too.
    def receive(self, data: bytes) -> None:
        super().receive(data.replace(b"\r\n", b"\n").replace(b"\r", b"\n"))

    def handle_line(self, line: str, time_s: float) -> None:
        emu = self.emulator
        emu.update(time_s)
        if emu.is_silent(time_s) or not line.strip():
            return
        match = _LINE.match(line)
        if match is None:
            emu.record_error("A")
            return
        address_text, command, arg = match.groups()
        command = command.upper()
        if address_text == "":
            if command == "ST":  # ST without an address stops every controller on the chain
                emu.stop(time_s)
            return
        if int(address_text) != emu.address:
            return  # another controller's command on the RS-485 chain
        handler = self._handlers.get(command)
        if handler is None:
            emu.record_error("A")
            return
        handler(f"{emu.address}{command}", arg.strip(), time_s)

    # -- queries -------------------------------------------------------------------------------------------
    def _tp(self, prefix: str, arg: str, t: float) -> None:
        if arg not in ("", "?"):
            self.emulator.record_error("C")
            return
        self.send(prefix + format_number(self.emulator.counter_m(t) / _MM), t)

    def _ts(self, prefix: str, arg: str, t: float) -> None:
        state, bits = self.emulator.status(t)
        self.send(f"{prefix}{bits:04X}{state:02X}", t)

    def _te(self, prefix: str, arg: str, t: float) -> None:
        self.send(prefix + self.emulator.take_error_letter(), t)

    def _pt(self, prefix: str, arg: str, t: float) -> None:
        value = _number(arg)
        if value is None:
            self.emulator.record_error("C")
            return
        self.send(prefix + format_number(self.emulator.motion_time_s(value * _MM)), t)

    def _id(self, prefix: str, arg: str, t: float) -> None:
        self.send(prefix + self.emulator.params.stage_id, t)

    def _ve(self, prefix: str, arg: str, t: float) -> None:
        self.send(f"{prefix} SMC_PP hamr-bench emulator", t)

    # -- actions -------------------------------------------------------------------------------------------
    def _or(self, prefix: str, arg: str, t: float) -> None:
        self.emulator.home(t)

    def _pa(self, prefix: str, arg: str, t: float) -> None:
        value = _number(arg)
        if value is None:
            self.emulator.record_error("C")
            return
        self.emulator.move_absolute(t, value * _MM)

    def _pr(self, prefix: str, arg: str, t: float) -> None:
        value = _number(arg)
        if value is None:
            self.emulator.record_error("C")
            return
        self.emulator.move_relative(t, value * _MM)

    def _st(self, prefix: str, arg: str, t: float) -> None:
        self.emulator.stop(t)

    def _rs(self, prefix: str, arg: str, t: float) -> None:
        self.emulator.reset(t)

    def _mm(self, prefix: str, arg: str, t: float) -> None:
        if arg not in ("0", "1"):
            self.emulator.record_error("C")
            return
        self.emulator.set_enabled(t, arg == "1")

    def _pw(self, prefix: str, arg: str, t: float) -> None:
        if arg not in ("0", "1"):
            self.emulator.record_error("C")
            return
        self.emulator.set_configuration(t, arg == "1")

    # -- settings with a query form ------------------------------------------------------------------------
    def _setting(
        self, prefix: str, arg: str, t: float, value_mm: float, setter: Callable[[float, float], object]
    ) -> None:
        if arg == "?":
            self.send(prefix + format_number(value_mm), t)
            return
        value = _number(arg)
        if value is None:
            self.emulator.record_error("C")
            return
        setter(t, value * _MM)

    def _va(self, prefix: str, arg: str, t: float) -> None:
        emu = self.emulator
        self._setting(prefix, arg, t, emu.velocity_m_per_s / _MM, emu.set_velocity)

    def _ac(self, prefix: str, arg: str, t: float) -> None:
        emu = self.emulator
        self._setting(prefix, arg, t, emu.acceleration_m_per_s2 / _MM, emu.set_acceleration)

    def _sl(self, prefix: str, arg: str, t: float) -> None:
        emu = self.emulator
        low_mm = emu.soft_limits_m[0] / _MM
        self._setting(prefix, arg, t, low_mm, lambda tt, v: emu.set_soft_limit(tt, "low", v))

    def _sr(self, prefix: str, arg: str, t: float) -> None:
        emu = self.emulator
        high_mm = emu.soft_limits_m[1] / _MM
        self._setting(prefix, arg, t, high_mm, lambda tt, v: emu.set_soft_limit(tt, "high", v))
