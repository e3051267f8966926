"""A Loadstar Sensors load cell with its DI-1000 or iLoad interface, at the byte level: the sensor model (true
force from a callback -> drift -> tare -> noise from the resolution -> ADC saturation -> quantisation to the
resolution) and the interface's command set as Loadstar publishes it
(`hamr_bench.instruments.loadstar_reference`:
every spelling a family accepts, case-insensitive; CR -> `A`, identity, units, capacity, tare -> `Tared` on a
DI-1000 and `A` on an iLoad, single reading, streaming at the interface's rate until a CR arrives).

The bench passes `force_source(time_s) -> force_N` (the true contact force) and a numpy Generator, so readings
are reproducible under one seed. Streamed lines are produced lazily at the stream rate, each computed at the
moment it is produced. Which family the paper's RSP2 sensor speaks is UNVERIFIED (docs/hardware.md)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from hamr_bench.clock import Clock
from hamr_bench.instruments.loadstar_reference import FAMILIES, NEWTONS_PER_UNIT, OPTIONAL_SPELLINGS
from sim_devices.faults import FORCE_SENSOR_FAULTS, SERIAL_FAULTS, FaultInjector
from sim_devices.serial_link import LineEndpoint

@dataclass(frozen=True)
class LoadstarParams:
    """Sensor and interface settings (defaults: a 10 lb sensor on a DI-1000U; UNVERIFIED for the RSP2)."""

    command_set: str = "di1000"
    # what MODEL (DI-1000) or SS0 (iLoad) answers; None: the family's published reply
    model: str | None = None
    serial_number: str = "LS-HAMRSIM-0001"
    # Spellings this firmware does not accept (Loadstar: W "is not supported in all firmware versions" of
    # iLoad).
    refused_spellings: tuple[str, ...] = ()
    units: str = "LB"  # what UNITS reports and W/WC readings are in (iLoad readings are always millipounds)
    capacity: float = 10.0  # in `units` (in lb on iLoad)
    resolution: float = 0.001  # one count, in `units`
    noise_counts: float = 1.0  # standard deviation of the reading noise, in counts
    saturation_factor: float = 1.5  # the ADC clips at this multiple of capacity
    stream_rate_Hz: float = 150.0  # ~150 Hz standard, ~575 Hz high-speed interfaces
    reply_latency_s: float = 0.003
    tare_time_s: float = 0.3
    baudrate: int = 9600
    drift: str = "none"  # none | linear | random_walk (effect `sensor_drift`)
    drift_strength: float = 0.0  # N/s (linear) or N/sqrt(s) (random walk)

    def __post_init__(self) -> None:
        if self.command_set not in FAMILIES:
            raise ValueError(f"command_set {self.command_set!r} not in {sorted(FAMILIES)}")
        optional = OPTIONAL_SPELLINGS.get(self.command_set, ())
        if any(spelling not in optional for spelling in self.refused_spellings):
            lacking = ", ".join(optional) or "nothing"
            message = f"refused_spellings {self.refused_spellings}: a {self.command_set} firmware lacks {lacking}"
            raise ValueError(message)
        if self.units.upper() not in NEWTONS_PER_UNIT:
            raise ValueError(f"units {self.units!r} not in {sorted(NEWTONS_PER_UNIT)}")
        if self.drift not in ("none", "linear", "random_walk"):
            raise ValueError(f"drift {self.drift!r} not one of none, linear, random_walk")
        if not (self.capacity > 0 and self.resolution > 0 and self.stream_rate_Hz > 0):
            raise ValueError("capacity, resolution and stream_rate_Hz must be > 0")


class LoadstarEmulator(LineEndpoint):
    """One sensor + interface, reachable in-process (`register_endpoint`) or on a pty (`PtyServer`)."""

    FAULTS = SERIAL_FAULTS + FORCE_SENSOR_FAULTS

    def __init__(
        self,
        clock: Clock,
        force_source: Callable[[float], float],
        rng: np.random.Generator,
        params: LoadstarParams | None = None,
    ) -> None:
        self.params = params or LoadstarParams()
        p = self.params
        super().__init__(
            clock,
            FaultInjector(self.FAULTS, device="loadstar emulator", clock=clock),
            device="loadstar",
            baudrate=p.baudrate,
            reply_latency_s=p.reply_latency_s,
            input_terminator=b"\r",
            rng=rng,
        )
        self.force_source = force_source
        self.family = FAMILIES[p.command_set]
        self._by_text = {
            spelling: role
            for role, entry in self.family.roles.items()
            for spelling in entry.spellings
            if spelling not in p.refused_spellings
        }
        self.reading_unit = (self.family.reading_unit or p.units).upper()
        capacity_unit = (self.family.capacity_unit or p.units).upper()
        self.capacity_N = p.capacity * NEWTONS_PER_UNIT[capacity_unit]
        unit_ratio = NEWTONS_PER_UNIT[p.units.upper()] / NEWTONS_PER_UNIT[self.reading_unit]
        self.resolution = p.resolution * unit_ratio
        self.decimals = max(0, -math.floor(math.log10(self.resolution) + 1e-9))
        self.tare_N = 0.0
        self.streaming = False
        self._next_sample_s = 0.0
        self._drift_t_s = clock.now_s()
        self._drift_N = 0.0

    # -- the sensor ----------------------------------------------------------------------------------------
    def drift_N(self, time_s: float) -> float:
        p = self.params
        if p.drift == "linear":
            return p.drift_strength * time_s
        if p.drift == "random_walk" and time_s > self._drift_t_s:
            dt = time_s - self._drift_t_s
            self._drift_N += p.drift_strength * math.sqrt(dt) * float(self.rng.standard_normal())
            self._drift_t_s = time_s
        return self._drift_N if p.drift == "random_walk" else 0.0

    def _loaded_N(self, time_s: float) -> float:
        if self.faults.is_active("overload", time_s):
            return self.params.saturation_factor * self.capacity_N * 2.0
        return float(self.force_source(time_s)) + self.drift_N(time_s)

    def reading(self, time_s: float) -> float:
        """One reading in the reading unit, as the interface would print it."""
        p = self.params
        unit_N = NEWTONS_PER_UNIT[self.reading_unit]
        value = (self._loaded_N(time_s) - self.tare_N) / unit_N
        value += p.noise_counts * self.resolution * float(self.rng.standard_normal())
        limit = p.saturation_factor * self.capacity_N / unit_N
        value = min(max(value, -limit), limit)
        return round(value / self.resolution) * self.resolution

    def _format(self, value: float) -> str:
        return f"{value:.{self.decimals}f}"

    # -- the interface -------------------------------------------------------------------------------------
    def produce_until(self, time_s: float) -> None:
        period_s = 1.0 / self.params.stream_rate_Hz
        while self.streaming and self._next_sample_s <= time_s:
            t = self._next_sample_s
            self.send_stream_line(self._format(self.reading(t)), t)
            # the next sample comes a period later, or once this line has left if the baud rate is the limit
            self._next_sample_s = max(t + period_s, self.wire_free_s)

    def next_produced_s(self) -> float | None:
        return self._next_sample_s if self.streaming else None

    def handle_line(self, line: str, time_s: float) -> None:
        if self.streaming:
            self.streaming = False  # a CR (with anything before it) stops the stream; no reply
            return
        role = self._by_text.get(line.strip().upper())
        p = self.params
        if role == "ready":
            self.send("A", time_s)
        elif role == "model":
            self.send(p.model or self.family.model_reply, time_s)
        elif role == "identify":
            self.send(p.serial_number, time_s)
        elif role == "units":
            self.send(p.units.upper(), time_s)
        elif role == "capacity":
            self.send(f"{p.capacity:.3f}", time_s)
        elif role == "tare":
            self.tare_N = self._loaded_N(time_s)
            self.send(self.family.tare_replies[0], time_s, extra_delay_s=p.tare_time_s)
        elif role == "read":
            self.send(self._format(self.reading(time_s)), time_s)
        elif role == "stream":
            self.streaming = True
            self._next_sample_s = time_s + p.reply_latency_s
        # anything else: silent (UNVERIFIED: what real firmware answers to an unknown command is not
        # published)
