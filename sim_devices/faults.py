"""Fault names and the small injector every emulator shares: a fault is switched on by name, now or at a
simulated time, and the emulator asks `is_active(name, time_s)` (state faults) or `take_due(name, time_s)`
(one-shot events) where it matters.

The names are data so other emulators (DAQ, amplifier, camera) and the command line use one vocabulary."""

from __future__ import annotations

from dataclasses import dataclass

from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError

# Wire-level faults every serial emulator supports.
SERIAL_FAULTS: tuple[str, ...] = ("no_reply", "garbage_bytes", "dropped_bytes", "disconnect")
# Device-state faults of the serial devices (added to SERIAL_FAULTS by their emulators).
STAGE_FAULTS: tuple[str, ...] = ("following_error", "end_of_run")
FORCE_SENSOR_FAULTS: tuple[str, ...] = ("overload",)
# What the vendor-API emulators model (sim_devices/daq_sim.py, sim_devices/camera_sim.py).
AMPLIFIER_FAULTS: tuple[str, ...] = ("amp_trip", "disconnect", "no_reply")
CAMERA_FAULTS: tuple[str, ...] = ("dropped_frames", "disconnect", "no_reply")

FAULT_DESCRIPTIONS: dict[str, str] = {
    "no_reply": "the device stops answering (every reply is lost)",
    "garbage_bytes": "every reply is replaced by line noise (non-ASCII bytes, still terminated)",
    "dropped_bytes": "every reply loses its final LF and one other byte",
    "disconnect": "the port goes away (USB unplugged / cable pulled): reads and writes fail",
    "following_error": "SMC100: motion stops, DISABLE (3D) with the following-error bit",
    "end_of_run": "SMC100: an end-of-run switch trips: motion stops, NOT REFERENCED with the end-of-run bit",
    "overload": "Loadstar: the reading saturates beyond capacity",
    "amp_trip": "an HV amplifier's output collapses to 0 V until cleared",
    "dropped_frames": "camera frames go missing (index gaps)",
}

FAULT_NAMES: tuple[str, ...] = tuple(FAULT_DESCRIPTIONS)


@dataclass(frozen=True)
class Fault:
    name: str
    at_s: float


class FaultInjector:
    """The faults switched on for one emulator. `allowed` limits the names to what that emulator models."""

    def __init__(
        self, allowed: tuple[str, ...], device: str = "emulator", clock: Clock | None = None
    ) -> None:
        self.allowed = tuple(allowed)
        self.clock = clock
        self.device = device
        self._faults: list[Fault] = []
        self._taken: set[int] = set()

    def inject(self, name: str, at_s: float | None = None) -> None:
        """Switch `name` on from `at_s` (default: now on the emulator's clock, or from the start if none)."""
        if at_s is None:
            at_s = self.clock.now_s() if self.clock is not None else float("-inf")
        if name not in self.allowed:
            known = ", ".join(self.allowed)
            raise ConfigError(f"{self.device}: unknown fault {name!r}; this emulator models: {known}")
        self._faults.append(Fault(name, float(at_s)))

    def clear(self, name: str | None = None) -> None:
        self._faults = [f for f in self._faults if name is not None and f.name != name]

    def is_active(self, name: str, time_s: float) -> bool:
        if not self._faults:  # the usual case, asked several times per exchange: skip building the generator
            return False
        return any(f.name == name and f.at_s <= time_s for f in self._faults)

    def any_scheduled(self, name: str) -> bool:
        return any(f.name == name for f in self._faults)

    def take_due(self, name: str, time_s: float) -> list[Fault]:
        """One-shot faults of `name` due by `time_s` not handed out before, earliest first."""
        due = []
        for fault in self._faults:
            if fault.name == name and fault.at_s <= time_s and id(fault) not in self._taken:
                self._taken.add(id(fault))
                due.append(fault)
        return sorted(due, key=lambda f: f.at_s)

    def next_at_s(self, names: tuple[str, ...], after_s: float) -> float | None:
        times = [f.at_s for f in self._faults if f.name in names and f.at_s > after_s]
        return min(times) if times else None


def parse_fault_spec(spec: str) -> tuple[str, float]:
    """`NAME` or `NAME@TIME_S` (command line) -> (name, at_s)."""
    name, _, at = spec.partition("@")
    if not at:
        return name.strip(), float("-inf")
    try:
        return name.strip(), float(at)
    except ValueError as exc:
        message = f"--fault {spec!r}: the time after '@' must be seconds, e.g. following_error@2.5"
        raise ConfigError(message) from exc
