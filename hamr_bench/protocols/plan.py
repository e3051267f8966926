"""The vocabulary of protocol plans: the messages a protocol yields and the runner carries out, and what a protocol
module is (`ProtocolModule`).

A protocol is a generator of these messages (bluesky-style): it says what to do, never how. The runner owns
timing, sampling, safety and recording. `FindContact`, `ReadForce` and `ReadStage` send a value back into the
generator, so a plan can react to what it measured (the approach to zero sag) without touching a device.
"""

from __future__ import annotations

from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any, Protocol

# A plan: yields messages, receives each one's reply, may return a value (a sub-plan's result).
Plan = Generator[Any, Any, Any]


class ProtocolModule(Protocol):
    """What a protocol module provides (one module per protocol in `hamr_bench.protocols`)."""

    NAME: str  # the command-line name
    FIXTURE: str  # "leg" or "actuator": which sensor table of the rig file the run uses
    SUMMARY: str  # one line for `run --help`
    Params: Callable[[], Any]  # the parameter dataclass; its defaults follow the paper

    def plan(self, p: Any) -> Plan: ...

    def step_count(self, p: Any) -> int: ...


@dataclass(frozen=True)
class Step:
    """Start of a measurement condition. `condition` holds its coordinates with unit suffixes
    (e.g. {"voltage_V": 150.0, "sag_m": 0.0, "repetition": 2}); the runner records it as a `step` event."""

    index: int
    label: str
    condition: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Home:
    """Reference the stage."""


@dataclass(frozen=True)
class MoveStage:
    """Move the stage to an absolute position, in increments no larger than the runner's safe step so the force
    limit is checked between them."""

    position_m: float


@dataclass(frozen=True)
class Tare:
    """Zero the force sensor (nothing touching)."""


@dataclass(frozen=True)
class FindContact:
    """Approach the leg with the stage from the present position in `direction_sign` until the force exceeds
    `threshold_N`; back off by `clearance_m` past the last step that did not touch and approach again in
    `fine_step_m` steps, so that every position the zero is estimated from is reached moving toward the leg (a
    stage's play, taken up the same way, then cannot misplace it). Sends back the stage position of the zero-sag
    (just touching) point, approached from the same side."""

    threshold_N: float
    coarse_step_m: float
    fine_step_m: float
    max_travel_m: float
    direction_sign: float = 1.0
    clearance_m: float = 50e-6


@dataclass(frozen=True)
class SetVoltages:
    """Ramp the bias and drive channels (drive first when lowering, bias first when raising) at the slew limit."""

    bias_V: float
    drive_V: float


@dataclass(frozen=True)
class Drive:
    """Play `waveform_V` on the drive channel at `sample_rate_Hz` (hardware-timed) with the bias held, recording
    every stream; `track` also grabs camera frames and tracks the marker."""

    waveform_V: tuple[float, ...]
    sample_rate_Hz: float
    track: bool = False


@dataclass(frozen=True)
class Dwell:
    """Hold still and record for `duration_s`; `track` as in `Drive`."""

    duration_s: float
    track: bool = False


@dataclass(frozen=True)
class ReadForce:
    """Average the force over `duration_s`; sends back the mean in N."""

    duration_s: float


@dataclass(frozen=True)
class ReadStage:
    """Ask where the stage is (one position query, not recorded); sends back a `StageState`."""


@dataclass(frozen=True)
class StageState:
    position_m: float
    limits_m: tuple[float, float]
    toward_leg_sign: float  # +1 or -1: the rig's direction that moves the sensor toward the leg


@dataclass(frozen=True)
class RecordEvent:
    """Record an `/events` message (a result the plan found, such as `contact_found`) at the present time."""

    kind: str
    message: str = ""
    data: dict[str, Any] = field(default_factory=dict)
