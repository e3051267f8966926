"""A rig: the devices a run uses, built from a rig file (TOML) that names a backend and its settings per device.

`load_rig` reads and checks the file (every error names the file, the table, the key and what was expected) and
builds the devices. Real backends live in `drivers`, the simulated bench in `sim_devices`; both are loaded here by
module name only when a rig asks for them, so `hamr_bench` does not depend on either at import time. The file
format is documented in `docs/rig-file.md`; `rigs/` ships the paper's rig and the simulated one.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

from hamr_bench.clock import Clock
from hamr_bench.config import Section, load_toml, section
from hamr_bench.errors import ConfigError, HamrBenchError
from hamr_bench.interfaces import Amplifier, Camera, ForceSensor, Stage

RIGS_DIR = Path(__file__).resolve().parent.parent / "rigs"
RIG_TABLES = {"rig", "stage", "force_sensor", "actuator_force_sensor", "amplifier", "camera", "sim"}


@dataclass(frozen=True)
class SafetyLimits:
    """Limits the runner enforces across devices (each driver also enforces its own)."""

    max_voltage_V: float = 250.0
    slew_rate_V_per_s: float = 5000.0
    force_limit_N: float = 0.5
    max_stage_step_m: float = 0.25e-3


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
    track_px: Callable[[Any], tuple[float, float]] | None = None
    metres_per_pixel: float = 1.0
    displacement_sign: float = 1.0
    stage_toward_leg_sign: float = 1.0
    is_simulated: bool = False
    bench: Any = None
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
        if self.bench is not None and hasattr(self.bench, "close"):
            self.bench.close()
        if errors and not self.faulted:
            raise ConfigError("while closing the rig: " + "; ".join(errors))


def read_limits(rig_section: Section) -> SafetyLimits:
    defaults = SafetyLimits()
    return SafetyLimits(
        max_voltage_V=rig_section.float("max_voltage_V", defaults.max_voltage_V, lo=0.0, hi=350.0, positive=True),
        slew_rate_V_per_s=rig_section.float("slew_rate_V_per_s", defaults.slew_rate_V_per_s, positive=True),
        force_limit_N=rig_section.float("force_limit_N", defaults.force_limit_N, positive=True),
        max_stage_step_m=rig_section.float("max_stage_step_m", defaults.max_stage_step_m, positive=True),
    )


def load_builder(dotted: str) -> Callable[..., Any]:
    module_name, _, attr = dotted.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        raise ConfigError(f"backend module {module_name} is not installed ({exc.name} missing)") from None
    return getattr(module, attr)


def load_rig(
    path: Path,
    *,
    design: int | None = None,
    layers: int | None = None,
    effects: dict[str, float] | None = None,
    seed: int | None = None,
    fixture: str = "leg",
    record_traffic: Callable[..., None] | None = None,
    faults: list[str] | None = None,
    model_overrides: dict[str, dict[str, Any]] | None = None,
    port_overrides: dict[str, Callable[[Clock], Any]] | None = None,
) -> Rig:
    """Build the rig a file describes. `faults` ('device:fault@time_s') are injected on a simulated rig. On a
    simulated rig, `design`, `layers`, `effects` and `seed` override the
    file's [sim] table and the devices are the real drivers talking to the simulated bench's emulators."""
    path = Path(path)
    doc = load_toml(path)
    source = str(path)
    unknown = sorted(set(doc) - RIG_TABLES)
    if unknown:
        raise ConfigError(f"{source}: unknown table [{unknown[0]}] (known: {', '.join(sorted(RIG_TABLES))})")
    rig_section = section(doc, source, "rig")
    kind = rig_section.str("kind", "real", choices=("real", "sim"))
    name = rig_section.str("name", path.stem)
    limits = read_limits(rig_section)
    rig_section.check_no_unknown_keys()
    bench = None
    ports: dict[str, Any] = {}
    if kind == "sim":
        make_bench = load_builder("sim_devices.rig_sim:make_bench")
        bench = make_bench(doc, source, design=design, layers=layers, effects=effects, seed=seed, fixture=fixture,
                           faults=faults, **({"model_overrides": model_overrides} if model_overrides else {}))
        ports, clock = bench.ports(), bench.clock
        # Replay can serve a serial device from recorded traffic instead of its emulator (built on the rig clock).
        ports.update({role: make_port(clock) for role, make_port in (port_overrides or {}).items()})
    else:
        if faults:
            raise ConfigError(f"{source}: [rig] kind is \"real\": --fault is for the simulated bench only "
                              "(use --sim, or a rig file with kind = \"sim\")")
        if model_overrides:
            raise ConfigError(f"{source}: [rig] kind is \"real\": model parameter overrides are for the simulated "
                              "bench only (use --sim)")
        from hamr_bench.clock import RealClock

        clock = RealClock()
    build_devices = load_builder("drivers.rig_builder:build_devices")
    try:
        devices = build_devices(doc, source, clock, ports, fixture, limits, record_traffic)
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
    return Rig(
        name=name, source_path=source, source_text=path.read_text(encoding="utf-8"), clock=clock,
        stage=devices["stage"], force_sensor=devices["force_sensor"], amp_bias=devices["amp_bias"],
        amp_drive=devices["amp_drive"], limits=limits, camera=devices["camera"], track_px=devices["track_px"],
        metres_per_pixel=devices["metres_per_pixel"], displacement_sign=devices["displacement_sign"],
        stage_toward_leg_sign=devices["stage_toward_leg_sign"], is_simulated=bench is not None, bench=bench,
        settings=settings,
    )


def sim_rig_path() -> Path:
    return RIGS_DIR / "sim.toml"
