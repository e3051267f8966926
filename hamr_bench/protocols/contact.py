"""The zero-sag approach shared by the leg protocols: bring the force sensor up to the leg until a force threshold
says it touches, then back off until contact is released. The runner executes the search (`FindContact`); this
module owns its parameters and the sub-plan."""

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

    def validate(self) -> None:
        for name in ("threshold_N", "coarse_step_m", "fine_step_m", "max_travel_m"):
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
    )
    return zero_sag_m
