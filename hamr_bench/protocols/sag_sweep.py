"""Blocked leg force vs sag at 250 V (paper Fig. 8b): after finding zero sag, the sensor is raised 0-3 mm in 1 mm
steps into the leg and the actuator driven at each."""

from __future__ import annotations

from dataclasses import dataclass, field

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.contact import ContactParams, find_zero_sag
from hamr_bench.protocols.drive import trapezoid_V
from hamr_bench.protocols.params import DriveParams
from hamr_bench.protocols.plan import Drive, MoveStage, SetVoltages, Step

NAME = "sag-sweep"
FIXTURE = "leg"
SUMMARY = "leg force vs sag at a fixed bias voltage"


@dataclass(frozen=True)
class Params:
    voltage_V: float = 250.0
    sags_m: tuple[float, ...] = (0.0, 1e-3, 2e-3, 3e-3)
    repetitions: int = 3
    drive: DriveParams = field(default_factory=DriveParams)
    contact: ContactParams = field(default_factory=ContactParams)

    def validate(self) -> None:
        if self.voltage_V <= 0:
            raise ConfigError(f"voltage_V: expected a positive bias voltage, got {self.voltage_V}")
        if any(s < 0 for s in self.sags_m):
            raise ConfigError(f"sags_m: expected non-negative sags, got {self.sags_m}")
        if self.repetitions < 1:
            raise ConfigError(f"repetitions: expected at least 1, got {self.repetitions}")
        self.contact.validate()


def step_count(p: Params) -> int:
    return p.repetitions * len(p.sags_m)


def plan(p: Params):
    zero_sag_m = yield from find_zero_sag(p.contact)
    index = 0
    for repetition in range(p.repetitions):
        for sag_m in p.sags_m:
            yield SetVoltages(bias_V=p.voltage_V, drive_V=0.0)
            yield MoveStage(zero_sag_m + sag_m)
            yield Step(index, f"sag {sag_m * 1e3:.1f} mm, rep {repetition + 1}/{p.repetitions}", {
                "voltage_V": p.voltage_V, "sag_m": sag_m, "repetition": repetition, "direction": "up"})
            d = p.drive
            ramp_s = d.ramp_for(repetition, 1)
            yield Drive(tuple(trapezoid_V(p.voltage_V, ramp_s, d.dwell_high_s, d.dwell_low_s, d.cycles,
                                          d.sample_rate_Hz)), d.sample_rate_Hz)
            index += 1
        yield MoveStage(zero_sag_m)
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
