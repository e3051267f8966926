"""Free leg displacement vs bias voltage (paper Fig. 9): nothing touches the leg; the camera tracks a marker on the
foot through each drive cycle."""

from __future__ import annotations

from dataclasses import dataclass, field

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.drive import trapezoid_V
from hamr_bench.protocols.params import DriveParams
from hamr_bench.protocols.plan import Drive, Home, SetVoltages, Step

NAME = "free-displacement"
FIXTURE = "leg"
SUMMARY = "leg stroke vs bias voltage, from the camera"


@dataclass(frozen=True)
class Params:
    voltages_V: tuple[float, ...] = (100.0, 150.0, 200.0, 250.0)
    repetitions: int = 2
    drive: DriveParams = field(default_factory=DriveParams)

    def validate(self) -> None:
        if any(v <= 0 for v in self.voltages_V):
            raise ConfigError(f"voltages_V: expected positive bias voltages, got {self.voltages_V}")
        if self.repetitions < 1:
            raise ConfigError(f"repetitions: expected at least 1, got {self.repetitions}")


def step_count(p: Params) -> int:
    return p.repetitions * len(p.voltages_V)


def plan(p: Params):
    yield Home()  # the home position keeps the sensor clear of the leg
    index = 0
    for repetition in range(p.repetitions):
        for voltage_V in sorted(p.voltages_V):
            yield Step(index, f"{voltage_V:.0f} V, rep {repetition + 1}/{p.repetitions}", {
                "voltage_V": voltage_V, "repetition": repetition, "direction": "up"})
            yield SetVoltages(bias_V=voltage_V, drive_V=0.0)
            d = p.drive
            ramp_s = d.ramp_for(repetition, 1)
            yield Drive(tuple(trapezoid_V(voltage_V, ramp_s, d.dwell_high_s, d.dwell_low_s, d.cycles,
                                          d.sample_rate_Hz)), d.sample_rate_Hz, track=True)
            index += 1
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
