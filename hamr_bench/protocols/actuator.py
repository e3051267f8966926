"""Bare actuator characterisation (paper Fig. 7): blocked tip force on the force sensor, then free tip
displacement from the camera with the sensor moved clear, vs bias voltage, for the mounted actuator (1, 2 or 3
carbon-fibre layers). Before the driven steps, an undriven stiffness sweep: at 0 V the stage pushes the tip past
contact in small steps and back (loading, then unloading: one reversal), holding at each step. Its slope is the
tip stiffness k_act measured directly (compare with blocked force / free stroke), and the up/down difference at
equal push is the stage's reversal error (backlash) times k_act: the actuator is the stiffest thing the stage
ever pushes, so this is where a lab measures backlash."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hamr_bench.errors import ConfigError
from hamr_bench.protocols.contact import ContactParams, find_zero_sag
from hamr_bench.protocols.drive import trapezoid_V
from hamr_bench.protocols.params import DriveParams
from hamr_bench.protocols.plan import Drive, Dwell, MoveStage, SetVoltages, Step

NAME = "actuator"
FIXTURE = "actuator"
SUMMARY = "bare actuator stiffness (undriven push, load and unload), blocked force and free displacement vs bias"

# The largest push the sweep may ask for. The stiffest actuator the model knows (3 layers, Table I "reported"
# values) is ~9.5 kN/m: 40 um presses ~0.38 N, under the actuator rigs' force limits (0.5-0.6 N); the runner's
# force-limit check between stage increments still stops anything beyond. The default, 30 um, presses 82 mN on
# the 3-layer actuator with the effective values (2.7 kN/m) and 0.28 N with the reported ones. The contact search
# leaves the stage at zero with any play taken up toward the tip (hamr_bench/protocols/contact.py), so the
# loading branch touches from its first push; the unloading branch comes back down through the play.
MAX_PUSH_M = 40e-6


@dataclass(frozen=True)
class StiffnessParams:
    """Undriven stiffness sweep: `steps` equal pushes up to `max_push_m` past contact, then back down (0 steps:
    no sweep). Each step settles `settle_s`, then holds `hold_s` (the recorded window)."""

    steps: int = 6
    max_push_m: float = 30e-6
    settle_s: float = 0.3
    hold_s: float = 0.5

    def validate(self) -> None:
        if self.steps < 0:
            raise ConfigError(f"stiffness steps: expected 0 (no sweep) or more, got {self.steps!r}")
        if self.steps and not 0 < self.max_push_m <= MAX_PUSH_M:
            raise ConfigError(f"stiffness max_push_m: expected 0 < push <= {MAX_PUSH_M:g} m (force-sensor limit "
                              f"with the stiffest actuator), got {self.max_push_m!r}")
        if self.settle_s < 0:
            raise ConfigError(f"stiffness settle_s: expected a non-negative time, got {self.settle_s!r}")
        if not self.hold_s > 0:
            raise ConfigError(f"stiffness hold_s: expected a positive time, got {self.hold_s!r}")

    def pushes_m(self) -> list[tuple[float, str]]:
        """(push past contact, direction) per step: loading to the maximum, then unloading."""
        if self.steps == 0:
            return []
        up = [float(x) for x in np.round(np.linspace(self.max_push_m / self.steps, self.max_push_m, self.steps), 12)]
        return [(x, "up") for x in up] + [(x, "down") for x in reversed(up[:-1])]


@dataclass(frozen=True)
class Params:
    voltages_V: tuple[float, ...] = (100.0, 150.0, 200.0, 250.0)
    repetitions: int = 3
    retract_m: float = 1e-3
    drive: DriveParams = field(default_factory=DriveParams)
    contact: ContactParams = field(default_factory=lambda: ContactParams(
        threshold_N=5e-3, coarse_step_m=5e-6, fine_step_m=0.5e-6, max_travel_m=4e-3))
    stiffness: StiffnessParams = field(default_factory=StiffnessParams)

    def validate(self) -> None:
        if any(v <= 0 for v in self.voltages_V):
            raise ConfigError(f"voltages_V: expected positive bias voltages, got {self.voltages_V}")
        if self.repetitions < 1:
            raise ConfigError(f"repetitions: expected at least 1, got {self.repetitions}")
        if self.retract_m <= 0:
            raise ConfigError(f"retract_m: expected a positive distance, got {self.retract_m}")
        self.contact.validate()
        self.stiffness.validate()


def step_count(p: Params) -> int:
    return len(p.stiffness.pushes_m()) + 2 * p.repetitions * len(p.voltages_V)


def _stiffness_sweep(p: Params, zero_m: float):
    """Undriven: push the tip past contact step by step and back; the stage returns to zero sag afterwards,
    approaching it from below."""
    index = 0
    for push_m, direction in p.stiffness.pushes_m():
        yield MoveStage(zero_m + push_m)
        yield Dwell(p.stiffness.settle_s)
        yield Step(index, f"stiffness push {push_m * 1e6:.1f} um {direction}", {
            "voltage_V": 0.0, "sag_m": push_m, "repetition": 0, "mode": "stiffness", "direction": direction})
        yield Dwell(p.stiffness.hold_s)
        index += 1
    if index:
        # Back to zero from below, as the contact search left it: coming down from the last push would leave a
        # stage's play (backlash) between the tip and the sensor, pressing it by k_act x play in the blocked steps.
        yield MoveStage(zero_m - p.contact.clearance_m)
        yield MoveStage(zero_m)
    return index


def _cycles(p: Params, mode: str, start_index: int, track: bool):
    index = start_index
    for repetition in range(p.repetitions):
        for voltage_V in sorted(p.voltages_V):
            yield Step(index, f"{mode} {voltage_V:.0f} V, rep {repetition + 1}/{p.repetitions}", {
                "voltage_V": voltage_V, "repetition": repetition, "mode": mode, "direction": "up"})
            yield SetVoltages(bias_V=voltage_V, drive_V=0.0)
            d = p.drive
            ramp_s = d.ramp_for(repetition, 1)
            yield Drive(tuple(trapezoid_V(voltage_V, ramp_s, d.dwell_high_s, d.dwell_low_s, d.cycles,
                                          d.sample_rate_Hz)), d.sample_rate_Hz, track=track)
            index += 1
    return index


def plan(p: Params):
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
    zero_m = yield from find_zero_sag(p.contact)
    index = yield from _stiffness_sweep(p, zero_m)
    index = yield from _cycles(p, "blocked", index, track=False)
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
    yield MoveStage(zero_m - p.retract_m)
    yield from _cycles(p, "free", index, track=True)
    yield SetVoltages(bias_V=0.0, drive_V=0.0)
