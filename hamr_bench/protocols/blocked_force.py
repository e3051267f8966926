"""Blocked leg force at zero sag (paper Fig. 8a): the leg's undriven neutral just touching the sensor, the bias
swept 100-250 V in 50 V steps, 5 repetitions. Alternate repetitions sweep down, so up and down sweeps can be
compared (hysteresis shows there)."""

from __future__ import annotations

from dataclasses import dataclass, field

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.contact import ContactParams, find_zero_sag
from hamr_bench.protocols.drive import trapezoid_V
from hamr_bench.protocols.params import DriveParams
from hamr_bench.protocols.plan import Drive, SetVoltages, Step

NAME = "blocked-force"
FIXTURE = "leg"
SUMMARY = "leg force at zero sag vs bias voltage, repeated"


@dataclass(frozen=True)
class Params:
    voltages_V: tuple[float, ...] = (100.0, 150.0, 200.0, 250.0)
    repetitions: int = 5
    alternate_direction: bool = True
    drive: DriveParams = field(default_factory=DriveParams)
    contact: ContactParams = field(default_factory=ContactParams)

    def validate(self) -> None:
        if self.repetitions < 1:
            raise ConfigError(f"repetitions: expected at least 1, got {self.repetitions}")
        if any(v <= 0 for v in self.voltages_V):
            raise ConfigError(f"voltages_V: expected positive bias voltages, got {self.voltages_V}")
        self.contact.validate()


def step_count(p: Params) -> int:
    return p.repetitions * len(p.voltages_V)


def sweep_order(voltages_V: tuple[float, ...], repetition: int, alternate: bool) -> tuple[list[float], str]:
    if alternate and repetition % 2 == 1:
        return sorted(voltages_V, reverse=True), "down"
    return sorted(voltages_V), "up"


def plan(p: Params):
    yield from find_zero_sag(p.contact)
    index = 0
    for repetition in range(p.repetitions):
        voltages, direction = sweep_order(p.voltages_V, repetition, p.alternate_direction)
        for voltage_V in voltages:
            yield Step(index, f"{voltage_V:.0f} V, rep {repetition + 1}/{p.repetitions}", {
                "voltage_V": voltage_V, "sag_m": 0.0, "repetition": repetition, "direction": direction})
            yield SetVoltages(bias_V=voltage_V, drive_V=0.0)
            d = p.drive
            ramp_s = d.ramp_for(repetition, 2 if p.alternate_direction else 1)
            yield Drive(tuple(trapezoid_V(voltage_V, ramp_s, d.dwell_high_s, d.dwell_low_s, d.cycles,
                                          d.sample_rate_Hz)), d.sample_rate_Hz)
            index += 1
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
