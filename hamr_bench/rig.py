"""A rig: the devices a run uses, built from a rig file (TOML) that names a backend and its settings per device.

`load_rig` checks the whole file (`rig_file`: every error names the file, the table, the key and what was expected)
and has the backends build the devices. The backends are found by name (`hamr_bench.backends`): the real drivers
(`drivers`) and, for a simulated rig, the simulated bench (`sim_devices`) whose emulators the same drivers then
talk to; `hamr_bench` never imports either. The file format is documented in `docs/rig-file.md`; `rigs/` ships the
paper's rig and the simulated one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hamr_bench import backends
from hamr_bench.backends import BenchOptions, MarkerTracker, SimulatedBench, TrafficSink
from hamr_bench.clock import Clock, RealClock
from hamr_bench.errors import ConfigError, HamrBenchError
from hamr_bench.interfaces import Amplifier, Camera, ForceSensor, Stage
from hamr_bench.rig_file import RIG_TABLES, SafetyLimits, read_rig_file

__all__ = ["RIG_TABLES", "Rig", "SafetyLimits", "load_rig", "sim_rig_path"]

RIGS_DIR = Path(__file__).resolve().parent.parent / "rigs"


@dataclass
class Rig:
    """Built devices plus what the runner needs to know about them. `close()` releases everything."""

    name: str
    source_path: str
    source_text: str
    clock: Clock
    stage: Stage
    force_sensor: ForceSensor
    amp_bias: Amplifier
    amp_drive: Amplifier
    limits: SafetyLimits
    camera: Camera | None = None
    track_px: MarkerTracker | None = None
    metres_per_pixel: float = 1.0
    displacement_sign: float = 1.0
    stage_toward_leg_sign: float = 1.0
    is_simulated: bool = False
    bench: SimulatedBench | None = None
    settings: dict[str, Any] = field(default_factory=dict)
    # Set by the runner when a run ended by a fault or abort: closing the devices then fails for the same cause
    # (a DAQ that is gone cannot be written), and that must not replace the run's own one-line reason.
    faulted: bool = False

    def devices(self) -> list[Any]:
        return [d for d in (self.camera, self.force_sensor, self.amp_drive, self.amp_bias, self.stage) if d]

    def close(self) -> None:
        errors = []
        for device in self.devices():
            try:
                device.close()
            except HamrBenchError as exc:  # keep closing the others
                errors.append(str(exc))
        if self.bench is not None:
            self.bench.close()
        if errors and not self.faulted:
            raise ConfigError("while closing the rig: " + "; ".join(errors))


def load_rig(
    path: Path,
    *,
    design: int | None = None,
    layers: int | None = None,
    effects: dict[str, float] | None = None,
    seed: int | None = None,
    fixture: str = "leg",
    record_traffic: TrafficSink | None = None,
    faults: list[str] | None = None,
    model_overrides: dict[str, dict[str, Any]] | None = None,
    port_overrides: dict[str, Callable[[Clock], Any]] | None = None,
) -> Rig:
    """Build the rig a file describes. `faults` ('device:fault@time_s') are injected on a simulated rig. On a
    simulated rig, `design`, `layers`, `effects` and `seed` override the
    file's [sim] table and the devices are the real drivers talking to the simulated bench's emulators."""
    rig_file = read_rig_file(Path(path))
    bench: SimulatedBench | None = None
    ports: dict[str, Any] = {}
    clock: Clock
    if rig_file.rig.kind == "sim":
        make_bench = backends.bench_factory()
        bench = make_bench(rig_file, BenchOptions(
            fixture=fixture, design=design, layers=layers, effects=dict(effects or {}), seed=seed,
            faults=tuple(faults or ()), model_overrides=dict(model_overrides or {})))
        ports, clock = bench.ports(), bench.clock
        # Replay can serve a serial device from recorded traffic instead of its emulator (built on the rig clock).
        ports.update({role: make_port(clock) for role, make_port in (port_overrides or {}).items()})
    else:
        source = rig_file.source
        if faults:
            raise ConfigError(f"{source}: [rig] kind is \"real\": --fault is for the simulated bench only "
                              "(use --sim, or a rig file with kind = \"sim\")")
        if model_overrides:
            raise ConfigError(f"{source}: [rig] kind is \"real\": model parameter overrides are for the simulated "
                              "bench only (use --sim)")
        clock = RealClock()
    try:
        build_devices = backends.device_factory()
        devices = build_devices(rig_file, clock, ports, fixture, record_traffic)
    except BaseException:
        if bench is not None:
            bench.close()
        raise
    settings: dict[str, Any] = {}
    if bench is not None:
        settings["model_params"] = bench.truth()
        settings["params_set"] = bench.settings.params_set
        settings["run_metadata"] = {"sim_design": bench.settings.design, "sim_layers": bench.settings.layers,
                                    "sim_seed": bench.settings.seed}
    camera = rig_file.camera
    return Rig(
        name=rig_file.name, source_path=rig_file.source, source_text=rig_file.text, clock=clock,
        stage=devices.stage, force_sensor=devices.force_sensor, amp_bias=devices.amp_bias,
        amp_drive=devices.amp_drive, limits=rig_file.rig.limits(), camera=devices.camera, track_px=devices.track_px,
        metres_per_pixel=camera.metres_per_pixel if camera else 1.0,
        displacement_sign=camera.displacement_sign if camera else 1.0,
        stage_toward_leg_sign=rig_file.stage.toward_leg_sign, is_simulated=bench is not None, bench=bench,
        settings=settings,
    )


def sim_rig_path() -> Path:
    return RIGS_DIR / "sim.toml"
