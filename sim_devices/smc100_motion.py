"""Kinematics of the SMC100's stepper stage for the emulator: point-to-point moves as constant-acceleration
pieces
(trapezoidal, or triangular when the distance is too short to reach the velocity), a motion that can be cut
short
(stop, fault, reset), and the carriage behind the motor with a backlash dead band on reversal. Positions in
metres,
times in seconds on the emulator's clock."""

from __future__ import annotations

import math
from dataclasses import dataclass, field


@dataclass(frozen=True)
class Segment:
    t0: float
    x0: float
    v0: float
    a: float
    dur: float


@dataclass
class Motion:
    """One monotonic motion of the motor (constant-acceleration pieces) and the carriage's backlash state."""

    t0: float
    x0: float
    x_end: float
    segments: list[Segment]
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

    def truncated(self, t: float) -> Motion:
        """The motor stops dead at `t` (stall, switch, reset)."""
        x = self.motor_at(t)
        segs = []
        for seg in self.segments:
            if seg.t0 >= t:
                break
            segs.append(Segment(seg.t0, seg.x0, seg.v0, seg.a, min(seg.dur, t - seg.t0)))
        return Motion(self.t0, self.x0, x, segs, self.mech0, self.half_play_m, self.kind)


def trapezoid_segments(t0: float, x0: float, x1: float, v_max: float, a: float) -> list[Segment]:
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
            Segment(t0, x0, 0.0, s * a, ta),
            Segment(t0 + ta, xa, s * v_max, 0.0, tc),
            Segment(t0 + ta + tc, xa + s * v_max * tc, s * v_max, -s * a, ta),
        ]
    ta = math.sqrt(d / a)
    return [Segment(t0, x0, 0.0, s * a, ta), Segment(t0 + ta, x0 + s * d / 2, s * a * ta, -s * a, ta)]


def trapezoid_time_s(distance_m: float, v_max: float, a: float) -> float:
    d = abs(distance_m)
    if d >= v_max * v_max / a:
        return d / v_max + v_max / a
    return 2.0 * math.sqrt(d / a)
