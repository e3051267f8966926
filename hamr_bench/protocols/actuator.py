"""Bare actuator characterisation (paper Fig. 7): blocked tip force on the force sensor, then free tip
displacement from the camera with the sensor moved clear, vs bias voltage, for the mounted actuator (1, 2 or 3
carbon-fibre layers)."""

from __future__ import annotations

from dataclasses import dataclass, field

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.contact import ContactParams, find_zero_sag
from hamr_bench.protocols.drive import trapezoid_V
from hamr_bench.protocols.params import DriveParams
from hamr_bench.protocols.plan import Drive, MoveStage, SetVoltages, Step

NAME = "actuator"
FIXTURE = "actuator"
SUMMARY = "bare actuator blocked force and free displacement vs bias voltage"


@dataclass(frozen=True)
class Params:
    voltages_V: tuple[float, ...] = (100.0, 150.0, 200.0, 250.0)
    repetitions: int = 3
    retract_m: float = 1e-3
    drive: DriveParams = field(default_factory=DriveParams)
    contact: ContactParams = field(default_factory=lambda: ContactParams(
        threshold_N=5e-3, coarse_step_m=5e-6, fine_step_m=0.5e-6, max_travel_m=4e-3))

    def validate(self) -> None:
        if any(v <= 0 for v in self.voltages_V):
            raise ConfigError(f"voltages_V: expected positive bias voltages, got {self.voltages_V}")
        if self.repetitions < 1:
            raise ConfigError(f"repetitions: expected at least 1, got {self.repetitions}")
        if self.retract_m <= 0:
            raise ConfigError(f"retract_m: expected a positive distance, got {self.retract_m}")
        self.contact.validate()


def step_count(p: Params) -> int:
    return 2 * p.repetitions * len(p.voltages_V)


def _cycles(p: Params, mode: str, start_index: int, track: bool):
    index = start_index
    for repetition in range(p.repetitions):
        for voltage_V in sorted(p.voltages_V):
            yield Step(index, f"{mode} {voltage_V:.0f} V, rep {repetition + 1}/{p.repetitions}", {
                "voltage_V": voltage_V, "repetition": repetition, "mode": mode, "direction": "up"})
            yield SetVoltages(bias_V=voltage_V, drive_V=0.0)
            d = p.drive
            yield Drive(tuple(trapezoid_V(voltage_V, d.ramp_s, d.dwell_high_s, d.dwell_low_s, d.cycles,
                                          d.sample_rate_Hz)), d.sample_rate_Hz, track=track)
            index += 1
    return index


def plan(p: Params):
    zero_m = yield from find_zero_sag(p.contact)
    index = yield from _cycles(p, "blocked", 0, track=False)
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
    yield MoveStage(zero_m - p.retract_m)
    yield from _cycles(p, "free", index, track=True)
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
