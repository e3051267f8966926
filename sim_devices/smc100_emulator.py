"""The SMC100PP controller and its stepper stage as a state machine in simulated time (Lewis style): states
with their real codes, error bits and error letters, trapezoidal motion with the VA/AC settings, soft limits,
encoder-step rounding, homing, stop, reset, enable/disable, configuration, optional backlash, and the stage
fault states. The wire protocol lives apart, in `smc100_protocol`.

Time is passed in by the caller (the protocol adapter uses its clock); `update(time_s)` settles every state
change due by then (a move finishing, a scheduled fault). Positions inside are in metres in the stage's
mechanical frame; the controller's counter (what `TP` reports) is the motor position minus a counter offset
that homing zeroes. `position_m(time_s)` is the true mechanical position (with backlash), for the simulated
bench."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from hamr_bench.clock import Clock
from sim_devices.faults import SERIAL_FAULTS, STAGE_FAULTS, FaultInjector


class codes:
    """The controller codes this emulator emits, written out again from the manual (sim_devices does not
    import drivers, so a wrong table in one is caught by tests of the other)."""

    NOT_REFERENCED_FROM_RESET = 0x0A
    NOT_REFERENCED_FROM_HOMING = 0x0B
    NOT_REFERENCED_FROM_CONFIGURATION = 0x0C
    NOT_REFERENCED_STAGE_ERROR = 0x10
    CONFIGURATION = 0x14
    HOMING_RS232 = 0x1E
    MOVING = 0x28
    READY_FROM_HOMING = 0x32
    READY_FROM_MOVING = 0x33
    READY_FROM_DISABLE = 0x34
    DISABLE_FROM_READY = 0x3C
    DISABLE_FROM_MOVING = 0x3D
    FAMILY = {
        0x0A: "NOT REFERENCED", 0x0B: "NOT REFERENCED", 0x0C: "NOT REFERENCED", 0x10: "NOT REFERENCED",
        0x14: "CONFIGURATION", 0x1E: "HOMING", 0x28: "MOVING",
        0x32: "READY", 0x33: "READY", 0x34: "READY", 0x3C: "DISABLE", 0x3D: "DISABLE",
    }
    BIT_NEGATIVE_END_OF_RUN = 0
    BIT_POSITIVE_END_OF_RUN = 1
    BIT_FOLLOWING_ERROR = 5
    # TE letter for a command that arrives in a state that does not accept it.
    STATE_REJECTION_LETTER = {
        "NOT REFERENCED": "H", "CONFIGURATION": "I", "DISABLE": "J",
        "READY": "K", "HOMING": "L", "MOVING": "M",
    }


@dataclass(frozen=True)
class Smc100Params:
    """Controller and stage settings. Defaults follow the UTS100PP on an SMC100PP (several UNVERIFIED)."""

    address: int = 1
    soft_limit_low_m: float = -0.050
    soft_limit_high_m: float = 0.050
    travel_low_m: float = -0.0505  # end-of-run switches; SL/SR may not be set beyond them
    travel_high_m: float = 0.0505
    velocity_m_per_s: float = 5e-3
    acceleration_m_per_s2: float = 20e-3
    max_velocity_m_per_s: float = 8e-3  # 20 mm/s nominal, PP controllers run steppers at nominal / 2.5
    max_acceleration_m_per_s2: float = 80e-3
    home_velocity_m_per_s: float = 2.5e-3
    home_settle_s: float = 0.2  # index search at the end of homing
    step_m: float = 0.3e-6  # targets and positions are rounded to this (UTS100PP minimum incremental motion)
    initial_position_m: float = 0.0  # mechanical position at power-up; the counter starts at 0 there
    # command in, processing, reply out: with the reply's bytes on the wire, ~10 ms for TP as in the manual
    reply_latency_s: float = 0.008
    reset_time_s: float = 2.0  # RS: silent while the controller reboots (init < 5 s)
    config_exit_time_s: float = 5.0  # PW0: silent while saving (up to 10 s)
    baudrate: int = 57600
    backlash_m: float = 0.0  # dead band on reversal between motor and carriage (effect `stage_backlash`)
    stage_id: str = "UTS100PP"

    def __post_init__(self) -> None:
        if not 1 <= self.address <= 31:
            raise ValueError(f"SMC100 address {self.address} outside 1..31")
        if self.backlash_m < 0:
            raise ValueError(f"backlash_m must be >= 0, got {self.backlash_m}")


@dataclass(frozen=True)
class _Segment:
    t0: float
    x0: float
    v0: float
    a: float
    dur: float


@dataclass
class _Motion:
    """One monotonic motion of the motor (constant-acceleration pieces) and the carriage's backlash state."""

    t0: float
    x0: float
    x_end: float
    segments: list[_Segment]
    mech0: float
    half_play_m: float
    kind: str = "move"  # move | home | stop | stop_homing | hold
    t_end: float = field(init=False)

    def __post_init__(self) -> None:
        self.t_end = self.segments[-1].t0 + self.segments[-1].dur if self.segments else self.t0

    def motor_at(self, t: float) -> float:
        if t <= self.t0:
            return self.x0
        for seg in self.segments:
            if t < seg.t0 + seg.dur:
                dt = t - seg.t0
                return seg.x0 + seg.v0 * dt + 0.5 * seg.a * dt * dt
        return self.x_end

    def velocity_at(self, t: float) -> float:
        for seg in self.segments:
            if seg.t0 <= t < seg.t0 + seg.dur:
                return seg.v0 + seg.a * (t - seg.t0)
        return 0.0

    def mech_at(self, t: float) -> float:
        x = self.motor_at(t)
        direction = math.copysign(1.0, self.x_end - self.x0) if self.x_end != self.x0 else 0.0
        if direction > 0:
            return max(self.mech0, x - self.half_play_m)
        if direction < 0:
            return min(self.mech0, x + self.half_play_m)
        return self.mech0

    def truncated(self, t: float) -> _Motion:
        """The motor stops dead at `t` (stall, switch, reset)."""
        x = self.motor_at(t)
        segs = []
        for seg in self.segments:
            if seg.t0 >= t:
                break
            segs.append(_Segment(seg.t0, seg.x0, seg.v0, seg.a, min(seg.dur, t - seg.t0)))
        return _Motion(self.t0, self.x0, x, segs, self.mech0, self.half_play_m, self.kind)


def trapezoid_segments(t0: float, x0: float, x1: float, v_max: float, a: float) -> list[_Segment]:
    """Constant-acceleration pieces of a point-to-point move (triangular when the distance is too short)."""
    d = abs(x1 - x0)
    if d == 0:
        return []
    s = math.copysign(1.0, x1 - x0)
    if d >= v_max * v_max / a:
        ta = v_max / a
        tc = (d - v_max * v_max / a) / v_max
        xa = x0 + s * 0.5 * v_max * ta
        return [
            _Segment(t0, x0, 0.0, s * a, ta),
            _Segment(t0 + ta, xa, s * v_max, 0.0, tc),
            _Segment(t0 + ta + tc, xa + s * v_max * tc, s * v_max, -s * a, ta),
        ]
    ta = math.sqrt(d / a)
    return [_Segment(t0, x0, 0.0, s * a, ta), _Segment(t0 + ta, x0 + s * d / 2, s * a * ta, -s * a, ta)]


def trapezoid_time_s(distance_m: float, v_max: float, a: float) -> float:
    d = abs(distance_m)
    if d >= v_max * v_max / a:
        return d / v_max + v_max / a
    return 2.0 * math.sqrt(d / a)


class Smc100Emulator:
    """The controller state machine. Command methods take the time the command arrived and return the TE error
    letter they store, or None when accepted."""

    FAULTS = SERIAL_FAULTS + STAGE_FAULTS

    def __init__(self, clock: Clock, params: Smc100Params | None = None) -> None:
        self.clock = clock
        self.params = params or Smc100Params()
        p = self.params
        self.faults = FaultInjector(self.FAULTS, device="smc100 emulator", clock=clock)
        self.address = p.address
        self.velocity_m_per_s = p.velocity_m_per_s
        self.acceleration_m_per_s2 = p.acceleration_m_per_s2
        self.soft_limits_m = (p.soft_limit_low_m, p.soft_limit_high_m)
        self.state_code = codes.NOT_REFERENCED_FROM_RESET
        self.error_bits = 0
        self.error_letter = "@"
        self._half_play_m = p.backlash_m / 2.0
        self._counter_offset_m = p.initial_position_m
        self._silent_until_s = float("-inf")
        self._after_silence_state: int | None = None
        t0 = clock.now_s()
        x0 = p.initial_position_m
        hold = _Motion(t0, x0, x0, [], x0, self._half_play_m, "hold")
        self._history: list[_Motion] = [hold]
        # Called with the time from which the stage's motion changes (a command, a fault): the simulated bench
        # recomputes its physics from there.
        self.motion_listeners: list[Callable[[float], None]] = []

    def _motion_changes(self, time_s: float) -> None:
        for listener in self.motion_listeners:
            listener(time_s)

    # -- time ----------------------------------------------------------------------------------------------
    @property
    def _motion(self) -> _Motion:
        return self._history[-1]

    @property
    def family(self) -> str:
        return codes.FAMILY[self.state_code]

    def update(self, time_s: float) -> None:
        """Settle every change due by `time_s`: silence ending, motion finishing, scheduled stage faults."""
        events = [(f.at_s, f.name) for name in STAGE_FAULTS for f in self.faults.take_due(name, time_s)]
        for at_s, name in sorted(events):
            self._settle(max(at_s, self._motion.t0))
            self._apply_fault(name, max(at_s, self._motion.t0))
        self._settle(time_s)

    def _settle(self, time_s: float) -> None:
        if self._after_silence_state is not None and time_s >= self._silent_until_s:
            self.state_code = self._after_silence_state
            self._after_silence_state = None
        motion = self._motion
        if self.family in ("MOVING", "HOMING") and motion.t_end <= time_s:
            if motion.kind == "home":
                self._counter_offset_m = 0.0
                self.state_code = codes.READY_FROM_HOMING
            elif motion.kind == "stop_homing":
                self.state_code = codes.NOT_REFERENCED_FROM_HOMING
            else:
                self.state_code = codes.READY_FROM_MOVING

    def _apply_fault(self, name: str, t: float) -> None:
        motion = self._motion
        was_moving = self.family in ("MOVING", "HOMING") and t < motion.t_end
        direction = motion.velocity_at(t)
        self._history[-1] = motion.truncated(t)
        self._motion_changes(t)
        if name == "following_error":
            self.state_code = codes.DISABLE_FROM_MOVING if was_moving else codes.DISABLE_FROM_READY
            self.error_bits |= 1 << codes.BIT_FOLLOWING_ERROR
        elif name == "end_of_run":
            if direction == 0:
                direction = 1.0 if self._motion.x_end >= 0 else -1.0
            bit = codes.BIT_POSITIVE_END_OF_RUN if direction > 0 else codes.BIT_NEGATIVE_END_OF_RUN
            # UNVERIFIED which NOT REFERENCED code a tripped switch gives; the driver treats any as a fault.
            self.state_code = codes.NOT_REFERENCED_STAGE_ERROR
            self.error_bits |= 1 << bit

    def is_silent(self, time_s: float) -> bool:
        """True while the controller ignores its serial input (reboot after RS, saving after PW0)."""
        return time_s < self._silent_until_s

    # -- observation ---------------------------------------------------------------------------------------
    def _round_step(self, x_m: float) -> float:
        step = self.params.step_m
        return round(x_m / step) * step

    def counter_m(self, time_s: float) -> float:
        """What TP reports: the motor position in the controller's frame, in whole steps."""
        self.update(time_s)
        motion = self._find(time_s)
        return self._round_step(motion.motor_at(time_s) - self._counter_offset_m)

    def status(self, time_s: float) -> tuple[int, int]:
        self.update(time_s)
        return self.state_code, self.error_bits

    def _find(self, time_s: float) -> _Motion:
        for motion in reversed(self._history):
            if motion.t0 <= time_s:
                return motion
        return self._history[0]

    def position_m(self, time_s: float) -> float:
        """True mechanical position of the carriage at `time_s` (backlash included), for the bench."""
        self.update(min(time_s, self.clock.now_s()))
        return self._find(time_s).mech_at(time_s)

    def positions_m(self, times_s: Sequence[float]) -> list[float]:
        """`position_m` at each time. With no stage fault scheduled the controller is settled once (to the latest
        time asked, or now) instead of once per time: the same positions, since motion history is kept and
        settling only changes state codes. (A fault truncates the motion it hits, so then each time is asked in
        turn, as `position_m` would.)"""
        times = [float(t) for t in times_s]
        if not times:
            return []
        if any(self.faults.any_scheduled(name) for name in STAGE_FAULTS):
            return [self.position_m(t) for t in times]
        self.update(min(max(times), self.clock.now_s()))
        last = self._history[-1]
        first = min(times)
        if first >= last.t0 and first >= last.t_end:
            # The usual question (the stage holds still while the drive plays): after its latest motion has
            # ended the carriage stays where it stopped, so every time gets that one position.
            return [last.mech_at(first)] * len(times)
        return [self._find(t).mech_at(t) for t in times]

    def take_error_letter(self) -> str:
        letter, self.error_letter = self.error_letter, "@"
        return letter

    def record_error(self, letter: str) -> str:
        self.error_letter = letter
        return letter

    def _reject(self) -> str:
        return self.record_error(codes.STATE_REJECTION_LETTER.get(self.family, "D"))

    # -- commands ------------------------------------------------------------------------------------------
    def _start(self, t: float, x1: float, v: float, kind: str) -> None:
        motion = self._motion
        x0 = motion.motor_at(t)
        mech0 = motion.mech_at(t)
        segments = trapezoid_segments(t, x0, x1, v, self.acceleration_m_per_s2)
        if kind == "home":
            end = segments[-1].t0 + segments[-1].dur if segments else t
            segments.append(_Segment(end, x1, 0.0, 0.0, self.params.home_settle_s))
        self._history.append(_Motion(t, x0, x1, segments, mech0, self._half_play_m, kind))
        self._motion_changes(t)

    def home(self, t: float) -> str | None:
        self.update(t)
        if self.family == "HOMING":
            return self.record_error("E")
        if self.family != "NOT REFERENCED":
            return self._reject()
        self.error_bits = 0
        self.state_code = codes.HOMING_RS232
        self._start(t, 0.0, self.params.home_velocity_m_per_s, "home")
        return None

    def move_absolute(self, t: float, target_m: float) -> str | None:
        self.update(t)
        if not math.isfinite(target_m):
            return self.record_error("C")
        if self.family != "READY":
            return self._reject()
        low, high = self.soft_limits_m
        if not low <= target_m <= high:
            return self.record_error("G")
        target = self._round_step(target_m)
        if target == self.counter_m(t):
            return None  # already there: the controller never leaves READY
        self.state_code = codes.MOVING
        self._start(t, target + self._counter_offset_m, self.velocity_m_per_s, "move")
        return None

    def move_relative(self, t: float, delta_m: float) -> str | None:
        self.update(t)
        if self.family != "READY":
            return self._reject()
        return self.move_absolute(t, self.counter_m(t) + delta_m)

    def stop(self, t: float) -> str | None:
        self.update(t)
        if self.family not in ("MOVING", "HOMING"):
            return None
        motion = self._motion
        x, v = motion.motor_at(t), motion.velocity_at(t)
        self._history[-1] = motion.truncated(t)
        self._motion_changes(t)
        a = self.acceleration_m_per_s2
        if v != 0:
            dur = abs(v) / a
            seg = _Segment(t, x, v, -math.copysign(a, v), dur)
            x_end = x + v * dur / 2
            kind = "stop_homing" if self.family == "HOMING" else "stop"
            self._history.append(_Motion(t, x, x_end, [seg], motion.mech_at(t), self._half_play_m, kind))
        else:
            self._settle(t)
            self.state_code = (
                codes.NOT_REFERENCED_FROM_HOMING if self.family == "HOMING" else codes.READY_FROM_MOVING
            )
        return None

    def reset(self, t: float) -> str | None:
        self.update(t)
        motion = self._motion
        self._history[-1] = motion.truncated(t)
        self._motion_changes(t)
        self._counter_offset_m = self._motion.x_end
        self.error_bits = 0
        self.error_letter = "@"
        self._silent_until_s = t + self.params.reset_time_s
        self._after_silence_state = codes.NOT_REFERENCED_FROM_RESET
        self.state_code = codes.NOT_REFERENCED_FROM_RESET
        self.velocity_m_per_s = self.params.velocity_m_per_s
        self.acceleration_m_per_s2 = self.params.acceleration_m_per_s2
        return None

    def set_enabled(self, t: float, enabled: bool) -> str | None:
        self.update(t)
        family = self.family
        if enabled:
            if family == "READY":
                return None
            if family != "DISABLE":
                return self._reject()
            self.error_bits = 0
            self.state_code = codes.READY_FROM_DISABLE
            return None
        if family == "DISABLE":
            return None
        if family != "READY":
            return self._reject()
        self.state_code = codes.DISABLE_FROM_READY
        return None

    def set_configuration(self, t: float, enter: bool) -> str | None:
        self.update(t)
        if enter:
            if self.family != "NOT REFERENCED":
                return self._reject()
            self.state_code = codes.CONFIGURATION
            return None
        if self.family != "CONFIGURATION":
            return self._reject()
        self._silent_until_s = t + self.params.config_exit_time_s
        self._after_silence_state = codes.NOT_REFERENCED_FROM_CONFIGURATION
        return None

    def _settable(self) -> str | None:
        if self.family in ("MOVING", "HOMING", "JOGGING"):
            return self._reject()
        return None

    def set_velocity(self, t: float, v_m_per_s: float) -> str | None:
        self.update(t)
        if (letter := self._settable()) is not None:
            return letter
        if not (math.isfinite(v_m_per_s) and 0 < v_m_per_s <= self.params.max_velocity_m_per_s):
            return self.record_error("C")
        self.velocity_m_per_s = v_m_per_s
        return None

    def set_acceleration(self, t: float, a_m_per_s2: float) -> str | None:
        self.update(t)
        if (letter := self._settable()) is not None:
            return letter
        if not (math.isfinite(a_m_per_s2) and 0 < a_m_per_s2 <= self.params.max_acceleration_m_per_s2):
            return self.record_error("C")
        self.acceleration_m_per_s2 = a_m_per_s2
        return None

    def set_soft_limit(self, t: float, which: str, value_m: float) -> str | None:
        self.update(t)
        if (letter := self._settable()) is not None:
            return letter
        low, high = self.soft_limits_m
        p = self.params
        if which == "low":
            if not (math.isfinite(value_m) and p.travel_low_m <= value_m <= min(0.0, high)):
                return self.record_error("C")
            self.soft_limits_m = (value_m, high)
        else:
            if not (math.isfinite(value_m) and max(0.0, low) <= value_m <= p.travel_high_m):
                return self.record_error("C")
            self.soft_limits_m = (low, value_m)
        return None

    def motion_time_s(self, distance_m: float) -> float:
        return trapezoid_time_s(distance_m, self.velocity_m_per_s, self.acceleration_m_per_s2)
