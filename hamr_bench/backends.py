"""Backends by name: what `hamr_bench` asks of the packages that build devices (`drivers`), simulate a bench
(`sim_devices`) or serve recorded serial traffic, and the one registry that finds them without importing them.

A backend is declared under the entry-point group `hamr_bench.backends` (pyproject.toml:
`[project.entry-points."hamr_bench.backends"]`), so `hamr_bench` names it and never imports the package that
provides it; another installed package can add one the same way. `register_backend` adds one at run time (tests,
plug-ins under development). A name nobody declared, or whose module fails to import, is one `ConfigError` line
naming the backend and why.

The factory protocols below are the whole contract: a device factory turns a checked rig file into `Devices`; a
bench factory turns one into a `SimulatedBench` whose ports the device factory then uses instead of real ports.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol, cast, runtime_checkable

from hamr_bench import entry_points
from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError
from hamr_bench.interfaces import Amplifier, Camera, ForceSensor, Stage
from hamr_bench.rig_file import RigFile

ENTRY_POINT_GROUP = "hamr_bench.backends"
DRIVERS = "drivers"
SIMULATED_BENCH = "simulated-bench"
RECORDED_TRAFFIC = "recorded-traffic"
TRAFFIC_TEST_EXPORT = "traffic-test-export"

# (topic /traffic/<device>, rig-clock time, direction "tx"/"rx", bytes): where a serial port's traffic goes.
TrafficSink = Callable[[str, float, str, bytes], None]


class MarkerTracker(Protocol):
    """Where the marker is in a camera image: (x, y) in pixels."""

    def __call__(self, image: Any) -> tuple[float, float]: ...


@dataclass
class Devices:
    """The devices a device factory built for one run."""

    stage: Stage
    force_sensor: ForceSensor
    amp_bias: Amplifier
    amp_drive: Amplifier
    camera: Camera | None = None
    track_px: MarkerTracker | None = None


class DeviceFactory(Protocol):
    """Builds the drivers of a rig. `ports` replaces a role's port or vendor backend (`stage`, `force_sensor`:
    a serial URL; `daq`, `camera`: an object with the vendor surface), which is how a simulated bench plugs in."""

    def __call__(self, rig_file: RigFile, clock: Clock, ports: Mapping[str, Any], fixture: str,
                 traffic: TrafficSink | None) -> Devices: ...


@dataclass(frozen=True)
class BenchOptions:
    """What the command line sets on a simulated bench, over the rig file's `[sim]` table (None: the file's)."""

    fixture: str = "leg"
    design: int | None = None
    layers: int | None = None
    effects: Mapping[str, float] = field(default_factory=dict)
    seed: int | None = None
    faults: tuple[str, ...] = ()
    model_overrides: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)


class BenchIdentity(Protocol):
    """What a run's metadata records about the simulated bench it ran on."""

    @property
    def params_set(self) -> str: ...

    @property
    def design(self) -> int: ...

    @property
    def layers(self) -> int: ...

    @property
    def seed(self) -> int: ...


class SimulatedBench(Protocol):
    """A simulated bench: the clock the run uses, the ports its emulators serve, and what it simulates."""

    @property
    def clock(self) -> Clock: ...

    @property
    def settings(self) -> BenchIdentity: ...

    def ports(self) -> dict[str, Any]: ...

    def truth(self) -> dict[str, Any]:
        """The model parameters the bench simulates (recorded in the run's metadata)."""

    def close(self) -> None: ...


class BenchFactory(Protocol):
    def __call__(self, rig_file: RigFile, options: BenchOptions) -> SimulatedBench: ...


@runtime_checkable
class TrafficServer(Protocol):
    """Serves a recording's `/traffic/<device>` streams to the drivers as serial ports (replay --serve-traffic)."""

    def traffic_topics(self, path: Path | str) -> list[str]: ...

    def role_of(self, topic: str) -> str | None: ...

    def serve_traffic(self, path: Path | str, topic: str, clock: Any) -> tuple[str, Any]: ...

    def close_served(self, url: str) -> None: ...


class TrafficTestExport(Protocol):
    """Writes one device's recorded conversation as a byte-exact driver test file; returns the number of calls."""

    def __call__(self, items: Sequence[Any], driver: str, device: str, source: str, out: Path) -> int: ...


_registered: dict[str, object] = {}


def register_backend(name: str, backend: object) -> None:
    """Make `backend` the one found under `name` in this process (before any declared one)."""
    _registered[name] = backend


def declared_backends() -> dict[str, str]:
    """name -> "module:attribute" of every declared backend (the source tree's own first: `entry_points`)."""
    return entry_points.declared(ENTRY_POINT_GROUP)


def load_backend(name: str) -> object:
    """The backend declared (or registered) under `name`, imported now."""
    if name in _registered:
        return _registered[name]
    declared = declared_backends()
    if name not in declared:
        known = ", ".join(sorted(declared)) or "none"
        raise ConfigError(f"backend {name!r} is not installed (entry-point group {ENTRY_POINT_GROUP}; declared: "
                          f"{known}): reinstall hamr-bench (pip install -e .)")
    try:
        return entry_points.resolve(declared[name])
    except ImportError as exc:
        raise ConfigError(f"backend {name!r} cannot be loaded: {exc}") from None
    except AttributeError:
        raise ConfigError(f"backend {name!r}: {declared[name]} names nothing") from None


def device_factory(name: str = DRIVERS) -> DeviceFactory:
    factory = load_backend(name)
    if not callable(factory):
        raise ConfigError(f"backend {name!r} is not a device factory")
    return cast(DeviceFactory, factory)  # a callable; its signature is DeviceFactory's by declaration


def bench_factory(name: str = SIMULATED_BENCH) -> BenchFactory:
    factory = load_backend(name)
    if not callable(factory):
        raise ConfigError(f"backend {name!r} is not a bench factory")
    return cast(BenchFactory, factory)


def traffic_server(name: str = RECORDED_TRAFFIC) -> TrafficServer:
    server = load_backend(name)
    if not isinstance(server, TrafficServer):
        raise ConfigError(f"backend {name!r} does not serve recorded traffic")
    return server


def traffic_test_export(name: str = TRAFFIC_TEST_EXPORT) -> TrafficTestExport:
    export = load_backend(name)
    if not callable(export):
        raise ConfigError(f"backend {name!r} does not export driver tests")
    return cast(TrafficTestExport, export)
