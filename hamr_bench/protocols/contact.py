"""The zero-sag approach shared by the leg and actuator protocols: bring the force sensor up to the leg (or tip)
until a force threshold says it touches, back off clear, and approach again in fine steps; zero sag is where the
line through the fine steps in contact reaches zero force. This module owns its parameters and both plans: the
protocols yield `FindContact` (after homing and taring, `find_zero_sag`), and the runner carries that message out
as the sub-plan `search`, built from primitive messages (stage moves, force averages), so the search runs under
the runner's safety checks without living inside it.

Every position the zero comes from is reached moving toward the leg, and so is the zero itself at the end: a
lead-screw stage's play (backlash, ~3-30 um) is then taken up the same way as in the loading moves that follow, and
does not shift the zero. `clearance_m` is how far the search backs off before approaching again: more than the
play the stage may have.

A load cell's baseline drifts (~0.1 mN a minute) and the search takes tens of seconds, so when backing off the
reading may stay above the release level with nothing touching. Contact force falls as the search backs off; a
baseline does not: two back-off steps past the stage's play that leave the force flat (within an eighth of the
threshold) say the leg is clear, and the rest of the search measures force from that reading (the `contact_found`
event then carries it as `baseline_N`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hamr_bench.errors import ConfigError, DeviceError
from hamr_bench.protocols.plan import (
    FindContact,
    Home,
    MoveStage,
    Plan,
    ReadForce,
    ReadStage,
    RecordEvent,
    StageState,
    Tare,
)
from hamr_bench.recording.contract import EventKind

FORCE_WINDOW_S = 0.1  # averaging window of a force reading during the search
# A back-off step that changes the mean force by less than this fraction of the threshold is flat
FLAT_FRACTION = 0.125


@dataclass(frozen=True)
class ContactParams:
    threshold_N: float = 0.4e-3
    coarse_step_m: float = 50e-6
    fine_step_m: float = 5e-6
    max_travel_m: float = 8e-3
    clearance_m: float = 50e-6

    def validate(self) -> None:
        for name in ("threshold_N", "coarse_step_m", "fine_step_m", "max_travel_m", "clearance_m"):
            if not getattr(self, name) > 0:
                raise ConfigError(f"contact {name}: expected a positive value, got {getattr(self, name)!r}")
        if self.fine_step_m > self.coarse_step_m:
            raise ConfigError("contact fine_step_m: must not exceed coarse_step_m")


def find_zero_sag(contact: ContactParams) -> Plan:
    """Home, tare with nothing touching, approach; returns the stage position of zero sag."""
    yield Home()
    yield Tare()
    zero_sag_m = yield FindContact(
        threshold_N=contact.threshold_N,
        coarse_step_m=contact.coarse_step_m,
        fine_step_m=contact.fine_step_m,
        max_travel_m=contact.max_travel_m,
        clearance_m=contact.clearance_m,
    )
    return zero_sag_m


def search(msg: FindContact) -> Plan:
    """The search `msg` asks for, as a sub-plan: returns the stage position of zero sag, approached toward the leg.
    A sensor that reads force where the search starts, no contact within `max_travel_m`, or a contact that moved
    between the coarse and the fine approach stop the run (DeviceError): a wrong zero is worse than none."""
    stage: StageState = yield ReadStage()
    sign = msg.direction_sign * stage.toward_leg_sign
    start = position = stage.position_m
    force = yield ReadForce(FORCE_WINDOW_S)
    if force >= msg.threshold_N / 2:
        # The tare just before assumed nothing touches here. A sensor that reads half the threshold anyway (a
        # tare that did not take, a sensor already pressed) would see contact everywhere and put the zero
        # anywhere: refuse rather than record a wrong zero.
        raise DeviceError(
            f"the force sensor reads {force * 1e3:.3f} mN where the contact search starts, right after its tare "
            f"(expected ~0, out of contact; the threshold is {msg.threshold_N * 1e3:.2f} mN): check that nothing "
            "touches the sensor and that its tare takes", device="force_sensor")
    while force < msg.threshold_N:
        if abs(position - start) >= msg.max_travel_m:
            raise DeviceError(
                f"no contact within {msg.max_travel_m * 1e3:.2f} mm of travel (force stayed below "
                f"{msg.threshold_N * 1e3:.2f} mN): check that the leg is above the sensor", device="force_sensor")
        position += sign * msg.coarse_step_m
        yield MoveStage(position)
        force = yield ReadForce(FORCE_WINDOW_S)
    released, backed, baseline_N = yield from _back_off(msg, sign, position, force)
    zero_sag_m = yield from _approach(msg, sign, stage.limits_m, released, backed, baseline_N)
    message, data = f"zero sag at stage {zero_sag_m * 1e3:.4f} mm", {"stage_position_m": zero_sag_m}
    if baseline_N:
        message += (f" (force measured from a baseline of {baseline_N * 1e3:.3f} mN: the sensor drifted since "
                    "its tare)")
        data["baseline_N"] = baseline_N
    yield RecordEvent(EventKind.CONTACT_FOUND, message, data)
    return zero_sag_m


def _back_off(msg: FindContact, sign: float, position: float, force: float) -> Plan:
    """Back off until contact is released; returns (released position, distance backed off, baseline force).

    Every pair the zero comes from is then taken moving toward the leg, with the play taken up as in the loading
    moves that follow; pairs taken while backing off through the contact left the carriage still for the first
    `play` of the back-off, a force plateau that tilted the line and moved the zero by up to the play.

    The force with nothing touching is the tare's zero, unless the sensor's baseline drifts during the search (a
    load cell's does, ~0.1 mN in a minute). Contact force falls as the search backs off, a baseline does not: two
    back-off steps in a row that leave the reading within FLAT_FRACTION of the threshold mean the leg is clear and
    the reading is the baseline, and the rest of the search measures from it. (Without this, a baseline above the
    release level kept the search backing off to the end of the stage's travel.) A leg in contact loses k x coarse
    step a step once the stage's play is taken up: 0.12 mN for the softest design, against a flat band of 0.05 mN.
    """
    release_N = msg.threshold_N / 4
    backed = 0.0
    baseline_N = 0.0
    flat_steps = 0
    while force - baseline_N > release_N and backed < 2 * msg.coarse_step_m + msg.max_travel_m:
        position -= sign * msg.coarse_step_m
        backed += msg.coarse_step_m
        yield MoveStage(position)
        previous_N, force = force, (yield ReadForce(FORCE_WINDOW_S))
        # Within the stage's play (at most `clearance_m`) the carriage has not moved yet: no telling from there.
        flat = backed > msg.clearance_m and abs(force - previous_N) < FLAT_FRACTION * msg.threshold_N
        flat_steps = flat_steps + 1 if flat else 0
        if flat_steps >= 2 and force - baseline_N > release_N:
            baseline_N = force
    return position, backed, baseline_N


def _approach(msg: FindContact, sign: float, limits_m: tuple[float, float], released: float, backed: float,
              baseline_N: float) -> Plan:
    """From past the play below `released`, approach in fine steps keeping the (position, force) pairs in contact;
    the zero-sag point is where a straight line through them reaches zero force (the leg is linear over a few
    steps): finer than the step, and not biased by the release threshold. Ends at the zero, reached toward the
    leg; returns it."""
    release_N = msg.threshold_N / 4
    position = released
    yield MoveStage(_clamp(released - sign * msg.clearance_m, limits_m))
    yield MoveStage(released)
    force = (yield ReadForce(FORCE_WINDOW_S)) - baseline_N
    touching = [(position, force)] if force > release_N else []
    travelled = 0.0
    while force < msg.threshold_N:
        if travelled >= backed + 2 * msg.coarse_step_m:
            raise DeviceError(
                f"contact moved between the coarse and the fine approach (force stayed below "
                f"{msg.threshold_N * 1e3:.2f} mN over {travelled * 1e3:.3f} mm, past where it had touched): is "
                "the force sensor drifting, or the leg loose?", device="force_sensor")
        position += sign * msg.fine_step_m
        travelled += msg.fine_step_m
        yield MoveStage(position)
        force = (yield ReadForce(FORCE_WINDOW_S)) - baseline_N
        if force > release_N:
            touching.append((position, force))
    # With fewer than three pairs (a very stiff tip) the zero is taken half a step before the first touch.
    first_touch = touching[0][0] if touching else position
    zero_sag_m = _clamp(extrapolate_zero_force(touching[::-1], fallback_m=first_touch - sign * msg.fine_step_m / 2,
                                               window_m=2 * msg.coarse_step_m), limits_m)
    # The approach ended past the zero: reach the zero from the same side too.
    yield MoveStage(_clamp(zero_sag_m - sign * msg.clearance_m, limits_m))
    yield MoveStage(zero_sag_m)
    return zero_sag_m


def _clamp(position_m: float, limits_m: tuple[float, float]) -> float:
    low, high = limits_m
    return min(max(position_m, low), high)


def extrapolate_zero_force(points: list[tuple[float, float]], fallback_m: float, window_m: float) -> float:
    """Where the straight line through (position, force) `points` reaches zero force; `fallback_m` with fewer than
    three points, a degenerate line, or an estimate further than `window_m` from the last point (noise can tilt a
    short line badly)."""
    positions = np.array([p for p, _ in points])
    forces = np.array([f for _, f in points])
    if len(points) < 3 or np.ptp(positions) == 0:
        return fallback_m
    slope, intercept = np.polyfit(positions, forces, 1)
    if slope == 0 or not np.isfinite(slope):
        return fallback_m
    estimate = -intercept / slope
    return float(estimate) if abs(estimate - positions[-1]) <= window_m else fallback_m
