"""The SMC100PP controller and its stepper stage as a state machine in simulated time (Lewis style): the
states with
the codes the reference lists (`hamr_bench.instruments.smc100_reference`), the error bits and their latching,
the
stored TE letter, the working and saved settings, homing as the HOME type (HT) and time-out (OT) say,
trapezoidal
moves (kinematics in `smc100_motion`), stop, reset, enable/disable, configuration, optional backlash, and the
stage
faults. The wire protocol lives apart, in `smc100_protocol`.

Time is passed in by the caller (the protocol adapter uses its clock); `update(time_s)` settles every state
change
due by then (a move finishing, a homing search timing out, a scheduled fault). Positions inside are in metres
in
the stage's mechanical frame; the controller's counter (what `TP` reports) is the motor position minus a
counter
offset that homing sets. `position_m(time_s)` is the true mechanical position (with backlash), for the
bench."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from hamr_bench.clock import Clock
from hamr_bench.instruments import smc100_reference as ref
from sim_devices.faults import SERIAL_FAULTS, STAGE_FAULTS, FaultInjector
from sim_devices.smc100_motion import Motion, Segment, trapezoid_segments, trapezoid_time_s

__all__ = ["Smc100Emulator", "Smc100Params", "Smc100Settings", "trapezoid_segments", "trapezoid_time_s"]

# Codes the state machine enters (numbers from the reference's TS table).
NOT_REFERENCED_FROM_RESET = 0x0A
NOT_REFERENCED_FROM_HOMING = 0x0B
NOT_REFERENCED_FROM_CONFIGURATION = 0x0C
CONFIGURATION = 0x14
HOMING_RS232 = 0x1E
MOVING = 0x28
READY_FROM_HOMING = 0x32
READY_FROM_MOVING = 0x33
READY_FROM_DISABLE = 0x34
DISABLE_FROM_READY = 0x3C
DISABLE_FROM_MOVING = 0x3D

# Error bits that report an event: reading TS clears them (manual, TS notes). The end-of-run bits report a
# switch
# that stays pressed, so the controller sets them again at its next 1 ms update until the stage leaves the
# switch.
_EVENT_BITS = (1 << ref.BIT_FOLLOWING_ERROR) | (1 << ref.BIT_HOMING_TIME_OUT)
_END_OF_RUN_BITS = (1 << ref.BIT_NEGATIVE_END_OF_RUN) | (1 << ref.BIT_POSITIVE_END_OF_RUN)


@dataclass(frozen=True)
class Smc100Params:
    """Controller and stage as shipped. Defaults follow a UTS100PP on an SMC100PP (several UNVERIFIED)."""

    address: int = 1
    soft_limit_low_m: float = -0.050
    soft_limit_high_m: float = 0.050
    travel_low_m: float = -0.0505  # end-of-run switches; SL/SR may not be set beyond them
    travel_high_m: float = 0.0505
    velocity_m_per_s: float = 5e-3  # the saved VA: the velocity after power-up, and the most READY may set
    acceleration_m_per_s2: float = 20e-3  # the saved AC
    max_velocity_m_per_s: float = 8e-3  # what CONFIGURATION may set: 20 mm/s nominal / 2.5 on a PP controller
    max_acceleration_m_per_s2: float = 80e-3
    home_velocity_m_per_s: float = 2.5e-3  # OH
    home_settle_s: float = 0.2  # the index search at the end of an HT 0 homing
    home_timeout_s: float = 100.0  # OT (UNVERIFIED default)
    step_m: float = 0.3e-6  # targets and positions are rounded to this (UTS100PP minimum incremental motion)
    initial_position_m: float = 0.0  # mechanical position at power-up; the counter starts at 0 there
    # command in, processing, reply out: with the reply's bytes on the wire, ~10 ms for TP as in the manual
    reply_latency_s: float = 0.008
    reset_time_s: float = 2.0  # RS: silent while the controller reboots (init < 5 s)
    config_exit_time_s: float = 5.0  # PW0: silent while saving (up to 10 s)
    baudrate: int = 57600
    backlash_m: float = 0.0  # dead band on reversal between motor and carriage (effect `stage_backlash`)
    stage_id: str = "UTS100PP"
    variant: str = "PP"
    # The text after `nnVE `. Real CC units answer "SMC_CC - Controller-driver version  3. 1. 2" (two public
    # sources); the PP spelling and version are UNVERIFIED.
    identity: str = "SMC_PP - Controller-driver version  3. 1. 2"
    analog_input_V: float = 0.0  # what RA reads
    ttl_inputs: int = 15  # what RB reads: the GPIO inputs have pull-ups, so an unwired input reads 1

    def __post_init__(self) -> None:
        if not 1 <= self.address <= 31:
            raise ValueError(f"SMC100 address {self.address} outside 1..31")
        if self.backlash_m < 0:
            raise ValueError(f"backlash_m must be >= 0, got {self.backlash_m}")
        if self.variant != "PP":
            raise ValueError(f"only the PP variant is modelled, got {self.variant!r}")


@dataclass
class Smc100Settings:
    """The controller's parameters, SI inside (m, m/s, m/s^2, s, A). The emulator keeps a working copy (what
    moves
    use) and a saved copy (flash: restored by RS, written by PW0)."""

    velocity_m_per_s: float
    acceleration_m_per_s2: float
    soft_limit_low_m: float
    soft_limit_high_m: float
    home_velocity_m_per_s: float
    home_timeout_s: float
    home_type: int = 0
    stage_id: str = "UTS100PP"
    backlash_compensation_m: float = 0.0  # BA: stored and reported; the motion does not apply it
    hysteresis_compensation_m: float = 0.0  # BH: stored and reported; the motion does not apply it
    jerk_time_s: float = 0.005  # JR (UNVERIFIED default): stored; the profile is trapezoidal, without jerk
    base_velocity_m_per_s: float = 0.0  # VB
    keypad_enabled: int = 1  # JM
    rs485_address: int = 2  # SA (UNVERIFIED default)
    microstep_factor: float = 64.0  # FRM (UNVERIFIED default)
    full_step_m: float = 19.2e-6  # FRS (UNVERIFIED default; FRS / FRM = the 0.3 um step)
    peak_current_A: float = 1.0  # QIL (UNVERIFIED default)
    rms_current_A: float = 0.5  # QIR (UNVERIFIED default)
    rms_period_s: float = 1.0  # QIT (UNVERIFIED default)
    esp_check: int = 3  # ZX
    ttl_outputs: int = 0  # SB (working only)


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
        self.saved = Smc100Settings(
            velocity_m_per_s=p.velocity_m_per_s, acceleration_m_per_s2=p.acceleration_m_per_s2,
            soft_limit_low_m=p.soft_limit_low_m, soft_limit_high_m=p.soft_limit_high_m,
            home_velocity_m_per_s=p.home_velocity_m_per_s, home_timeout_s=p.home_timeout_s,
            stage_id=p.stage_id)
        self.settings = dataclasses.replace(self.saved)
        self.state_code = NOT_REFERENCED_FROM_RESET
        self.error_bits = 0
        self.error_letter = "@"
        self.se_target_m: float | None = None
        self._half_play_m = p.backlash_m / 2.0
        self._counter_offset_m = p.initial_position_m
        self._silent_until_s = float("-inf")
        self._after_silence_state: int | None = None
        self._home_fails_at_end = False  # an end-of-run switch tripped while homing: checked when homing ends
        t0 = clock.now_s()
        x0 = p.initial_position_m
        self._history: list[Motion] = [Motion(t0, x0, x0, [], x0, self._half_play_m, "hold")]
        # Called with the time from which the stage's motion changes (a command, a fault, a timeout): the simulated
        # bench recomputes its physics from there.
        self.motion_listeners: list[Callable[[float], None]] = []

    def _motion_changes(self, time_s: float) -> None:
        for listener in self.motion_listeners:
            listener(time_s)

    # -- settings the rest of the code reads often
    # -----------------------------------------------------------------
    @property
    def velocity_m_per_s(self) -> float:
        return self.settings.velocity_m_per_s

    @property
    def acceleration_m_per_s2(self) -> float:
        return self.settings.acceleration_m_per_s2

    @property
    def soft_limits_m(self) -> tuple[float, float]:
        return self.settings.soft_limit_low_m, self.settings.soft_limit_high_m

    # -- time ------------------------------------------------------------------------------------------------
    @property
    def _motion(self) -> Motion:
        return self._history[-1]

    @property
    def family(self) -> str:
        return ref.STATE_CODES[self.state_code][0]

    def update(self, time_s: float) -> None:
        """Settle every change due by `time_s`: silence ending, motion finishing, homing timing out, scheduled
        stage faults."""
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
        if self.family == "HOMING" and motion.kind == "home":
            deadline_s = motion.t0 + self.settings.home_timeout_s
            if motion.t_end > deadline_s and time_s >= deadline_s:
                self._history[-1] = motion.truncated(deadline_s)
                self._motion_changes(deadline_s)
                self.state_code = NOT_REFERENCED_FROM_HOMING
                self.error_bits |= 1 << ref.BIT_HOMING_TIME_OUT
                return
        if self.family in ("MOVING", "HOMING") and motion.t_end <= time_s:
            if motion.kind == "home" and self._home_fails_at_end:
                self._home_fails_at_end = False
                self.state_code = NOT_REFERENCED_FROM_HOMING
            elif motion.kind == "home":
                self._counter_offset_m = motion.x_end
                self.state_code = READY_FROM_HOMING
            elif motion.kind == "stop_homing":
                self.state_code = NOT_REFERENCED_FROM_HOMING
            else:
                self.state_code = READY_FROM_MOVING

    def _apply_fault(self, name: str, t: float) -> None:
        motion = self._motion
        family = self.family
        in_motion = family in ("MOVING", "HOMING") and t < motion.t_end
        direction = motion.velocity_at(t)
        if name == "following_error":
            self._history[-1] = motion.truncated(t)
            self._motion_changes(t)
            self.error_bits |= 1 << ref.BIT_FOLLOWING_ERROR
            if in_motion:
                self.state_code = DISABLE_FROM_MOVING
            elif family == "READY":
                # UNVERIFIED: the manual names only a following error during a move
                self.state_code = DISABLE_FROM_READY
        elif name == "end_of_run":
            if direction == 0:
                direction = 1.0 if motion.x_end >= 0 else -1.0
            bit = ref.BIT_POSITIVE_END_OF_RUN if direction > 0 else ref.BIT_NEGATIVE_END_OF_RUN
            self.error_bits |= 1 << bit
            # State diagram: MOVING aborts the motion and, like READY and DISABLE, falls to NOT REFERENCED
            # ("from"
            # the state it left); HOMING checks only at the end of the search; NOT REFERENCED and
            # CONFIGURATION
            # take no action.
            if family == "HOMING":
                self._home_fails_at_end = True
            elif family in ("MOVING", "READY", "DISABLE"):
                self._history[-1] = motion.truncated(t)
                self._motion_changes(t)
                self.state_code = ref.NOT_REFERENCED_FROM[family]

    def is_silent(self, time_s: float) -> bool:
        """True while the controller ignores its serial input (reboot after RS, saving after PW0)."""
        return time_s < self._silent_until_s

    # -- observation
    # ---------------------------------------------------------------------------------------------
    def _round_step(self, x_m: float) -> float:
        step = self.params.step_m
        return round(x_m / step) * step

    def counter_m(self, time_s: float) -> float:
        """What TP (and TH: an open-loop stepper's set-point is its position) reports: the motor position in
        the
        controller's frame, in whole steps."""
        self.update(time_s)
        motion = self._find(time_s)
        return self._round_step(motion.motor_at(time_s) - self._counter_offset_m)

    def target_m(self, time_s: float) -> float:
        """What PA? reports: where the latest move is going (the position itself when none was commanded)."""
        self.update(time_s)
        return self._round_step(self._motion.x_end - self._counter_offset_m)

    def status(self, time_s: float) -> tuple[int, int]:
        """(state code, error bits) at `time_s`, without the side effect of a TS read."""
        self.update(time_s)
        return self.state_code, self.error_bits

    def read_status(self, time_s: float) -> tuple[int, int]:
        """What a TS command returns; reading clears the event bits (the end-of-run bits stay while the stage
        sits
        on the switch)."""
        state, bits = self.status(time_s)
        self.error_bits &= ~_EVENT_BITS
        return state, bits

    def _find(self, time_s: float) -> Motion:
        for motion in reversed(self._history):
            if motion.t0 <= time_s:
                return motion
        return self._history[0]

    def position_m(self, time_s: float) -> float:
        """True mechanical position of the carriage at `time_s` (backlash included), for the bench."""
        self.update(min(time_s, self.clock.now_s()))
        return self._find(time_s).mech_at(time_s)

    def positions_m(self, times_s: Sequence[float]) -> list[float]:
        """`position_m` at each time. With no stage fault scheduled the controller is settled once (to the
        latest
        time asked, or now) instead of once per time: the same positions, since motion history is kept and
        settling only changes state codes. (A fault truncates the motion it hits, so then each time is asked
        in
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

    def refuse(self, command: str) -> str:
        """Store the letter `command` gets in the present state (the state is one it is not executed in)."""
        return self.record_error(ref.COMMANDS[command].refusal_letter(self.family))

    def _check_state(self, command: str) -> str | None:
        if self.family in ref.COMMANDS[command].states:
            return None
        return self.refuse(command)

    # -- motion commands
    # -----------------------------------------------------------------------------------------
    def _start(self, t: float, x1: float, v: float, kind: str, settle_s: float = 0.0) -> None:
        motion = self._motion
        x0 = motion.motor_at(t)
        mech0 = motion.mech_at(t)
        segments = trapezoid_segments(t, x0, x1, v, self.acceleration_m_per_s2)
        if settle_s > 0:
            end = segments[-1].t0 + segments[-1].dur if segments else t
            segments.append(Segment(end, x1, 0.0, 0.0, settle_s))
        self._history.append(Motion(t, x0, x1, segments, mech0, self._half_play_m, kind))
        self._motion_changes(t)

    def home(self, t: float) -> str | None:
        """OR: search home as the HOME type (HT) says. 0 and 2: the home switch (mechanical 0; 0 adds the
        index
        search), 1: the present position, 3 and 4: the negative end-of-run switch."""
        self.update(t)
        if (letter := self._check_state("OR")) is not None:
            return letter
        self.error_bits = 0
        self.state_code = HOMING_RS232
        home_type = self.settings.home_type
        if home_type == 1:
            x_home = self._motion.motor_at(t)
        elif home_type in (3, 4):
            x_home = self.params.travel_low_m
        else:
            x_home = 0.0
        settle_s = self.params.home_settle_s if home_type in (0, 3) else 0.0
        self._start(t, x_home, self.settings.home_velocity_m_per_s, "home", settle_s)
        return None

    def move_absolute(self, t: float, target_m: float) -> str | None:
        self.update(t)
        if not math.isfinite(target_m):
            return self.record_error("C")
        if (letter := self._check_state("PA")) is not None:
            return letter
        low, high = self.soft_limits_m
        if not low <= target_m <= high:
            return self.record_error("G")
        target = self._round_step(target_m)
        if target == self.counter_m(t):
            return None  # already there: the controller never leaves READY
        self.state_code = MOVING
        self._start(t, target + self._counter_offset_m, self.velocity_m_per_s, "move")
        return None

    def move_relative(self, t: float, delta_m: float) -> str | None:
        self.update(t)
        if not math.isfinite(delta_m):
            return self.record_error("C")
        if (letter := self._check_state("PR")) is not None:
            return letter
        # "nn units away from the current target position"
        return self.move_absolute(t, self.target_m(t) + delta_m)

    def stop(self, t: float) -> str | None:
        self.update(t)
        if (letter := self._check_state("ST")) is not None:
            return letter
        if self.family not in ("MOVING", "HOMING"):
            return None
        motion = self._motion
        x, v = motion.motor_at(t), motion.velocity_at(t)
        self._history[-1] = motion.truncated(t)
        self._motion_changes(t)
        a = self.acceleration_m_per_s2
        kind = "stop_homing" if self.family == "HOMING" else "stop"
        if v != 0:
            dur = abs(v) / a
            seg = Segment(t, x, v, -math.copysign(a, v), dur)
            x_end = x + v * dur / 2
            self._history.append(Motion(t, x, x_end, [seg], motion.mech_at(t), self._half_play_m, kind))
        else:
            self._history.append(Motion(t, x, x, [], motion.mech_at(t), self._half_play_m, kind))
            self._settle(t)
        return None

    def reset(self, t: float) -> str | None:
        self.update(t)
        if (letter := self._check_state("RS")) is not None:
            return letter
        motion = self._motion
        self._history[-1] = motion.truncated(t)
        self._motion_changes(t)
        self._counter_offset_m = self._motion.x_end
        self.error_bits = 0
        self.error_letter = "@"
        self._home_fails_at_end = False
        self._silent_until_s = t + self.params.reset_time_s
        self._after_silence_state = NOT_REFERENCED_FROM_RESET
        self.state_code = NOT_REFERENCED_FROM_RESET
        self.settings = dataclasses.replace(self.saved)  # working values are lost at reboot
        self.se_target_m = None
        return None

    def set_enabled(self, t: float, enabled: bool) -> str | None:
        self.update(t)
        if (letter := self._check_state("MM")) is not None:
            return letter
        if enabled and self.family == "DISABLE":
            self.error_bits &= _END_OF_RUN_BITS  # "the residual following error gets cleared"
            self.state_code = READY_FROM_DISABLE
        elif not enabled and self.family == "READY":
            self.state_code = DISABLE_FROM_READY
        return None

    def set_configuration(self, t: float, enter: bool) -> str | None:
        self.update(t)
        if (letter := self._check_state("PW")) is not None:
            return letter
        if enter and self.family == "NOT REFERENCED":
            self.state_code = CONFIGURATION
        elif not enter and self.family == "CONFIGURATION":
            self.saved = dataclasses.replace(self.settings, ttl_outputs=0)
            self._silent_until_s = t + self.params.config_exit_time_s
            self._after_silence_state = NOT_REFERENCED_FROM_CONFIGURATION
        # PW1 in CONFIGURATION or PW0 in NOT REFERENCED: already there (UNVERIFIED: the page lists no letter)
        return None

    def set_simultaneous_target(self, t: float, target_m: float) -> str | None:
        """xxSEnn: store a target the next bare SE starts (READY only, within the soft limits)."""
        self.update(t)
        if not math.isfinite(target_m):
            return self.record_error("C")
        if (letter := self._check_state("SE")) is not None:
            return letter
        low, high = self.soft_limits_m
        if not low <= target_m <= high:
            return self.record_error("G")
        self.se_target_m = self._round_step(target_m)
        return None

    def start_simultaneous(self, t: float) -> str | None:
        """Bare SE: start the stored move, if any."""
        self.update(t)
        if self.se_target_m is None:
            return None
        target, self.se_target_m = self.se_target_m, None
        return self.move_absolute(t, target)

    # -- settings
    # ------------------------------------------------------------------------------------------------
    def set_velocity(self, t: float, v_m_per_s: float) -> str | None:
        self.update(t)
        return self._set_limited(t, "VA", "velocity_m_per_s", v_m_per_s, self.params.max_velocity_m_per_s)

    def set_acceleration(self, t: float, a_m_per_s2: float) -> str | None:
        self.update(t)
        return self._set_limited(t, "AC", "acceleration_m_per_s2", a_m_per_s2,
                                 self.params.max_acceleration_m_per_s2)

    def _set_limited(
        self, t: float, command: str, attribute: str, value: float, stage_max: float
    ) -> str | None:
        """VA/AC: up to the stage's maximum in CONFIGURATION, up to the saved value in DISABLE or READY."""
        if (letter := self._check_state(command)) is not None:
            return letter
        limit = stage_max if self.family == "CONFIGURATION" else getattr(self.saved, attribute)
        if not (math.isfinite(value) and 0 < value <= limit):
            return self.record_error("C")
        setattr(self.settings, attribute, value)
        return None

    def set_soft_limit(self, t: float, which: str, value_m: float) -> str | None:
        self.update(t)
        if (letter := self._check_state("SL" if which == "low" else "SR")) is not None:
            return letter
        low, high = self.soft_limits_m
        p = self.params
        # Outside CONFIGURATION a working limit must not cut off the set-point position (SL/SR pages).
        position = self.counter_m(t) if self.family != "CONFIGURATION" else None
        if which == "low":
            if position is not None and math.isfinite(value_m) and value_m > position:
                return self.record_error("C")
            if not (math.isfinite(value_m) and p.travel_low_m <= value_m <= min(0.0, high)):
                return self.record_error("C")
            self.settings.soft_limit_low_m = value_m
        else:
            if position is not None and math.isfinite(value_m) and value_m < position:
                return self.record_error("C")
            if not (math.isfinite(value_m) and max(0.0, low) <= value_m <= p.travel_high_m):
                return self.record_error("C")
            self.settings.soft_limit_high_m = value_m
        return None

    def motion_time_s(self, distance_m: float) -> float:
        return trapezoid_time_s(distance_m, self.velocity_m_per_s, self.acceleration_m_per_s2)
