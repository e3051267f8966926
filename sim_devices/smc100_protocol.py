"""The SMC100's RS-232 line protocol in front of `Smc100Emulator`, driven by the command table of the
reference
(`hamr_bench.instruments.smc100_reference`): a command is executed when CR LF arrives (a bare CR or LF does
not end
it); blanks anywhere are ignored; `nn` addresses one controller on the chain (another address is ignored, a
missing
or bad one stores B unless the command may be broadcast); unknown commands store A, commands for the other
variant
W; a command refused in the present state stores the letter its row gives; a query echoes the command
(`1TP` -> `1TP1.2345`); characters after what a command needs are ignored, as the reference says. The
controller is
deaf while it reboots (RS) or saves (PW0). Units on the wire are mm, mm/s, mm/s^2, s and A."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hamr_bench.instruments import smc100_reference as ref
from sim_devices.serial_link import LineEndpoint
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Settings

_MM = 1e-3
_ADDRESS = re.compile(r"^(\d*)(\.?)")
_NUMBER = re.compile(r"^[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?")
_RA_RESOLUTION_V = 0.078125  # the RA page: a +/-7 bit converter over +/-10 V


def format_number(value: float) -> str:
    """Shortest fixed-point text with at most 6 decimals (plain decimals, never an exponent)."""
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def leading_number(text: str) -> float | None:
    """The number a parameter starts with (what follows it is ignored, as the reference says of any remaining
    characters), or None when it does not start with one."""
    match = _NUMBER.match(text)
    if match is None:
        return None
    value = float(match.group(0))
    return value if math.isfinite(value) else None


@dataclass(frozen=True)
class Setting:
    """A parameter that `nnXXvalue` sets and `nnXX?` reads: the Smc100Settings field, the wire unit in SI
    (1e-3 for
    mm), and the range the reference gives (exclusive bounds where it says > or <)."""

    attribute: str
    unit: float = 1.0
    low: float = -math.inf
    high: float = math.inf
    low_inclusive: bool = True
    high_inclusive: bool = True
    integer: bool = False

    def accepts(self, value: float) -> bool:
        above = value >= self.low if self.low_inclusive else value > self.low
        below = value <= self.high if self.high_inclusive else value < self.high
        return above and below and (not self.integer or value == int(value))


# The settings without motion side effects (VA, AC, SL, SR go through the state machine's own checks).
SETTINGS: dict[str, Setting] = {
    "BA": Setting("backlash_compensation_m", _MM, 0.0, 1e12, high_inclusive=False),
    "BH": Setting("hysteresis_compensation_m", _MM, 0.0, 1e12, high_inclusive=False),
    "HT": Setting("home_type", low=0, high=4, integer=True),
    "JM": Setting("keypad_enabled", low=0, high=1, integer=True),
    "JR": Setting("jerk_time_s", low=0.001, high=1e12, low_inclusive=False, high_inclusive=False),
    "OH": Setting("home_velocity_m_per_s", _MM, 1e-6, 1e12, low_inclusive=False, high_inclusive=False),
    "OT": Setting("home_timeout_s", low=1.0, high=1e3, low_inclusive=False, high_inclusive=False),
    "SA": Setting("rs485_address", low=2, high=31, integer=True),
    "SB": Setting("ttl_outputs", low=0, high=15, integer=True),
    "VB": Setting("base_velocity_m_per_s", _MM, 0.0, 1e12),
    "ZX": Setting("esp_check", low=1, high=3, integer=True),
    "FRM": Setting("microstep_factor", low=0.0, high=2000.0, low_inclusive=False),
    "FRS": Setting("full_step_m", _MM, 1e-6, 1e12, low_inclusive=False, high_inclusive=False),
    "QIL": Setting("peak_current_A", low=0.05, high=3.0),
    "QIR": Setting("rms_current_A", low=0.05, high=1.5),
    "QIT": Setting("rms_period_s", low=0.01, high=100.0, low_inclusive=False),
}

# What `ZT` lists and how: wire name -> function of the settings giving the value in wire units.
_ZT_VALUES: dict[str, Callable[[Smc100Settings], float]] = {
    "AC": lambda s: s.acceleration_m_per_s2 / _MM,
    "SL": lambda s: s.soft_limit_low_m / _MM,
    "SR": lambda s: s.soft_limit_high_m / _MM,
    "VA": lambda s: s.velocity_m_per_s / _MM,
}


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
            input_terminator=b"\r\n",
            keep_stray_line_ends=True,
            rng=rng,
        )
        self.emulator = emulator
        self._handlers: dict[str, Callable[[str, str, str, float], None]] = {
            "AC": self._ac, "VA": self._va, "SL": self._sl, "SR": self._sr,
            "MM": self._mm, "PW": self._pw, "OR": self._or, "PA": self._pa, "PR": self._pr, "PT": self._pt,
            "RS": self._rs, "ST": self._st, "SE": self._se, "JD": self._refused_unless_jogging,
            "TB": self._tb, "TE": self._te, "TH": self._th, "TP": self._tp, "TS": self._ts, "VE": self._ve,
            "ZT": self._zt, "RA": self._ra, "RB": self._rb, "ID": self._id, "ZX": self._zx,
        }

    # -- parsing
    # -------------------------------------------------------------------------------------------------
    def handle_line(self, line: str, time_s: float) -> None:
        emu = self.emulator
        emu.update(time_s)
        if emu.is_silent(time_s):
            return
        text = line.replace(" ", "")
        if not text.strip("\r\n"):
            return  # an empty line: nothing to execute (UNVERIFIED whether a real unit stores an error)
        addressed = self._addressed_command(text)
        if addressed is None:
            return
        spec, name, rest = addressed
        if not ref.accepts(spec, emu.params.variant):
            emu.record_error(ref.variant_letter(emu.params.variant))
            return
        argument = rest[2:]
        sub = ""
        if spec.subcommands:
            sub, argument = argument[:1].upper(), argument[1:]
            if not sub or sub not in spec.subcommands:
                emu.record_error("C")
                return
        prefix = f"{emu.address}{name}{sub}"
        if spec.query is not None and argument.startswith("?"):
            self._query(spec, name + sub, prefix, time_s)
            return
        if emu.family not in spec.states:
            emu.refuse(name)
            return
        handler = self._handlers.get(name, self._setting)
        handler(name + sub, prefix, argument, time_s)

    def _addressed_command(self, text: str) -> tuple[ref.CommandSpec, str, str] | None:
        """(spec, name, the text after the address) of a command for this controller; None (after recording the
        error letter where the reference says one) for a malformed one or another controller's."""
        emu = self.emulator
        match = _ADDRESS.match(text)
        assert match is not None  # both groups may be empty
        address_text, point = match.groups()
        rest = text[match.end():]
        name = rest[:2].upper()
        if point or len(name) < 2 or not name.isalpha() or name not in ref.COMMANDS:
            emu.record_error("A")  # floating point address, or not a command the reference knows
            return None
        spec = ref.COMMANDS[name]
        address = int(address_text) if address_text else 0
        if address == 0 and not spec.broadcast or address > 31:
            emu.record_error("B")
            return None
        if address not in (0, emu.address):
            return None  # another controller's command on the RS-485 chain
        return spec, name, rest

    def _query(self, spec: ref.CommandSpec, key: str, prefix: str, t: float) -> None:
        emu = self.emulator
        if spec.query == ref.QUERY_TARGET:
            target_m = emu.se_target_m if key == "SE" else emu.target_m(t)
            self.send(prefix + format_number((target_m or 0.0) / _MM), t)
        elif spec.query == ref.QUERY_STATE:
            entered = ("READY", "MOVING", "HOMING", "JOGGING") if key == "MM" else ("CONFIGURATION",)
            self.send(prefix + ("1" if emu.family in entered else "0"), t)
        elif key == "ID":
            self.send(prefix + emu.settings.stage_id, t)
        elif key == "ZX":
            self.send(prefix + emu.settings.stage_id, t)  # the ZX page: "returns the current stage reference"
        else:
            self.send(prefix + format_number(self._wire_value(key)), t)

    def _wire_value(self, key: str) -> float:
        settings = self.emulator.settings
        if key in _ZT_VALUES:
            return _ZT_VALUES[key](settings)
        setting = SETTINGS[key]
        return float(getattr(settings, setting.attribute)) / setting.unit

    # -- settings
    # ------------------------------------------------------------------------------------------------
    def _setting(self, key: str, prefix: str, argument: str, t: float) -> None:
        emu = self.emulator
        setting = SETTINGS[key]
        value = leading_number(argument)
        if value is None or not setting.accepts(value):
            # The JM page lists B for a missing value and A for one out of range (it has no C).
            letter = ("B" if value is None else "A") if key == "JM" else "C"
            emu.record_error(letter)
            return
        if key == "QIR" and value > emu.settings.peak_current_A:
            emu.record_error("C")  # the rms limit must not exceed the peak limit
            return
        if key == "VB" and value * _MM > emu.settings.velocity_m_per_s:
            emu.record_error("C")
            return
        if key in ("BA", "BH") and value > 0 and getattr(emu.settings, SETTINGS["BH" if key == "BA" else "BA"]
                                                         .attribute) > 0:
            # backlash and hysteresis compensation exclude each other (the pages list no letter for it)
            emu.record_error("D")
            return
        stored = int(value) if setting.integer else value * setting.unit
        setattr(emu.settings, setting.attribute, stored)

    def _with_number(self, argument: str, action: Callable[[float], object]) -> None:
        value = leading_number(argument)
        if value is None:
            self.emulator.record_error("C")
            return
        action(value)

    def _ac(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._with_number(argument, lambda v: self.emulator.set_acceleration(t, v * _MM))

    def _va(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._with_number(argument, lambda v: self.emulator.set_velocity(t, v * _MM))

    def _sl(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._with_number(argument, lambda v: self.emulator.set_soft_limit(t, "low", v * _MM))

    def _sr(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._with_number(argument, lambda v: self.emulator.set_soft_limit(t, "high", v * _MM))

    def _id(self, key: str, prefix: str, argument: str, t: float) -> None:
        if not 1 <= len(argument) <= 31:
            self.emulator.record_error("C")
            return
        self.emulator.settings.stage_id = argument

    def _zx(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._setting(key, prefix, argument, t)

    # -- state changes and motion
    # --------------------------------------------------------------------------------
    def _zero_or_one(self, argument: str, action: Callable[[bool], object]) -> None:
        value = leading_number(argument)
        if value not in (0.0, 1.0):
            self.emulator.record_error("C")
            return
        action(value == 1.0)

    def _mm(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._zero_or_one(argument, lambda on: self.emulator.set_enabled(t, on))

    def _pw(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._zero_or_one(argument, lambda on: self.emulator.set_configuration(t, on))

    def _or(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.emulator.home(t)

    def _pa(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._with_number(argument, lambda v: self.emulator.move_absolute(t, v * _MM))

    def _pr(self, key: str, prefix: str, argument: str, t: float) -> None:
        self._with_number(argument, lambda v: self.emulator.move_relative(t, v * _MM))

    def _pt(self, key: str, prefix: str, argument: str, t: float) -> None:
        value = leading_number(argument)
        if value is None or not 1e-6 < value < 1e12:
            self.emulator.record_error("C")
            return
        self.send(prefix + format_number(self.emulator.motion_time_s(value * _MM)), t)

    def _rs(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.emulator.reset(t)

    def _st(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.emulator.stop(t)

    def _se(self, key: str, prefix: str, argument: str, t: float) -> None:
        if argument == "":
            self.emulator.start_simultaneous(t)
            return
        self._with_number(argument, lambda v: self.emulator.set_simultaneous_target(t, v * _MM))

    def _refused_unless_jogging(self, key: str, prefix: str, argument: str, t: float) -> None:
        """JD in JOGGING: this emulator never jogs, so the state check before this has already refused it."""

    # -- queries without a `?` form
    # ------------------------------------------------------------------------------
    def _tb(self, key: str, prefix: str, argument: str, t: float) -> None:
        emu = self.emulator
        if argument == "":
            letter = emu.take_error_letter()  # the current error, read and cleared as TE does (TS page notes)
        else:
            letter = argument[0].upper()
            if letter not in ref.ERROR_TEXTS:
                emu.record_error("C")
                return
        self.send(f"{prefix}{letter} {ref.ERROR_TEXTS[letter]}", t)

    def _te(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.send(prefix + self.emulator.take_error_letter(), t)

    def _th(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.send(prefix + format_number(self.emulator.counter_m(t) / _MM), t)

    def _tp(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.send(prefix + format_number(self.emulator.counter_m(t) / _MM), t)

    def _ts(self, key: str, prefix: str, argument: str, t: float) -> None:
        state, bits = self.emulator.read_status(t)
        self.send(f"{prefix}{bits:04X}{state:02X}", t)

    def _ve(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.send(f"{prefix} {self.emulator.params.identity}", t)

    def _ra(self, key: str, prefix: str, argument: str, t: float) -> None:
        volts = self.emulator.params.analog_input_V
        self.send(prefix + format_number(round(volts / _RA_RESOLUTION_V) * _RA_RESOLUTION_V), t)

    def _rb(self, key: str, prefix: str, argument: str, t: float) -> None:
        self.send(f"{prefix}{self.emulator.params.ttl_inputs}", t)

    def _zt(self, key: str, prefix: str, argument: str, t: float) -> None:
        """Every configuration parameter as the command that would set it, six decimals, between `PW1` lines
        (as
        the ZT page prints it: it starts and ends with PW1)."""
        emu = self.emulator
        address = emu.address
        lines = [f"{address}PW1"]
        for key in ref.ZT_PARAMETERS_PP:
            if key == "ZX":
                lines.append(f"{address}ZX{emu.settings.esp_check}")
            else:
                lines.append(f"{address}{key}{self._wire_value(key):.6f}")
        lines.append(f"{address}PW1")
        for line in lines:
            self.send(line, t)
