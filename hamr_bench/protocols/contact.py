"""The zero-sag approach shared by the leg and actuator protocols: bring the force sensor up to the leg (or tip)
until a force threshold says it touches, back off clear, and approach again in fine steps; zero sag is where the
line through the fine steps in contact reaches zero force. The runner executes the search (`FindContact`); this
module owns its parameters and the sub-plan.

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
from typing import Generator

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.plan import FindContact, Home, Tare


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


def find_zero_sag(contact: ContactParams) -> Generator:
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
