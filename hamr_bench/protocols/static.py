"""Static leg stiffness (paper Fig. 10): actuator undriven (0 V), the stage pushes the leg up in steps and back
down, force recorded at each sag once it settles."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.contact import ContactParams, find_zero_sag
from hamr_bench.protocols.plan import Dwell, MoveStage, SetVoltages, Step

NAME = "static"
FIXTURE = "leg"
SUMMARY = "undriven leg force vs sag, loading then unloading"


@dataclass(frozen=True)
class Params:
    max_sag_m: float = 3e-3
    step_m: float = 0.25e-3
    settle_s: float = 0.3
    hold_s: float = 0.5
    unload: bool = True
    contact: ContactParams = field(default_factory=ContactParams)

    def validate(self) -> None:
        if not 0 < self.step_m <= self.max_sag_m:
            raise ConfigError(f"step_m: expected 0 < step_m <= max_sag_m, got {self.step_m}")
        if self.settle_s < 0 or self.hold_s <= 0:
            raise ConfigError("settle_s must be >= 0 and hold_s > 0")
        self.contact.validate()

    def sags_m(self) -> list[tuple[float, str]]:
        up = list(np.round(np.arange(0.0, self.max_sag_m + self.step_m / 2, self.step_m), 9))
        path = [(s, "up") for s in up]
        if self.unload:
            path += [(s, "down") for s in reversed(up[:-1])]
        return path


def step_count(p: Params) -> int:
    return len(p.sags_m())


def plan(p: Params):
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
    zero_sag_m = yield from find_zero_sag(p.contact)
    for index, (sag_m, direction) in enumerate(p.sags_m()):
        yield MoveStage(zero_sag_m + sag_m)
        yield Dwell(p.settle_s)
        yield Step(index, f"sag {sag_m * 1e3:.2f} mm {direction}", {
            "voltage_V": 0.0, "sag_m": float(sag_m), "repetition": 0, "direction": direction})
        yield Dwell(p.hold_s)
    yield MoveStage(zero_sag_m)
