"""The rig file (TOML) as typed tables: `[rig]` (name, kind, the safety limits), one table per device with the
backend that serves it, and `[sim]` for a simulated rig. Each table is a frozen dataclass whose field defaults are
the rig file's defaults; `read_rig_file` checks every table before any device is built, so a mistake anywhere in
the file is one line naming the file, the table and the key (`hamr_bench.config`). The `[sim]` table belongs to
the simulated bench's backend, which checks it the same way. The format is documented in `docs/rig-file.md`.

A new device backend adds its table here (a dataclass, and its name in the role's `*_TABLES` map), its builder in
`drivers/rig_builder.py`, and its keys in `docs/rig-file.md`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from hamr_bench.config import Place, load_table, read_toml, required_table, setting, table_of
from hamr_bench.errors import ConfigError

RIG_TABLES = ("rig", "stage", "force_sensor", "actuator_force_sensor", "amplifier", "camera", "sim")
UNIT_SIGNS = (1.0, -1.0)
T = TypeVar("T")


@dataclass(frozen=True)
class SafetyLimits:
    """Limits the runner enforces across devices (each driver also enforces its own)."""

    max_voltage_V: float = 250.0
    slew_rate_V_per_s: float = 5000.0
    force_limit_N: float = 0.5
    max_stage_step_m: float = 0.25e-3


@dataclass(frozen=True)
class RigTable:
    """`[rig]`: what the rig is called, whether it is real or simulated, and its limits."""

    name: str | None = None  # None: the file's name
    kind: str = setting("real", choices=("real", "sim"))
    max_voltage_V: float = setting(SafetyLimits.max_voltage_V, lo=0.0, hi=350.0, positive=True)
    slew_rate_V_per_s: float = setting(SafetyLimits.slew_rate_V_per_s, positive=True)
    force_limit_N: float = setting(SafetyLimits.force_limit_N, positive=True)
    max_stage_step_m: float = setting(SafetyLimits.max_stage_step_m, positive=True)

    def limits(self) -> SafetyLimits:
        return SafetyLimits(self.max_voltage_V, self.slew_rate_V_per_s, self.force_limit_N, self.max_stage_step_m)


@dataclass(frozen=True)
class Smc100Table:
    """`[stage]`, backend `smc100` (Newport SMC100 controller on a serial port)."""

    backend: str = setting(choices=("smc100",))
    port: str | None = None  # required on a real rig; a simulated rig hands the driver its own
    address: int = setting(1, lo=1, hi=31)
    timeout_s: float = setting(0.5, positive=True)
    poll_interval_s: float = setting(0.05, positive=True)
    command_gap_s: float = setting(0.0, lo=0.0)
    limits_m: tuple[float, float] | None = None  # None: read from the controller's SL/SR
    toward_leg_sign: float = 1.0  # +1 or -1


@dataclass(frozen=True)
class LoadstarTable:
    """`[force_sensor]` / `[actuator_force_sensor]`, backend `loadstar` (a serial load cell)."""

    backend: str = setting(choices=("loadstar",))
    port: str | None = None
    command_set: str = setting("di1000", choices=("di1000", "iload"))
    baudrate: int = setting(9600, lo=1)
    timeout_s: float = setting(0.5, positive=True)
    stream_rate_Hz: float = setting(150.0, positive=True)
    tare_readings: int = setting(16, lo=1)   # single readings a tare averages (the driver keeps the zero)
    daq_device: str | None = None  # accepted for symmetry with nano17; unused


# The ATI Nano17 driver's own default rate (drivers.ati_nano17 takes it from here): one number for both.
NANO17_SAMPLE_RATE_HZ = 5_000.0


@dataclass(frozen=True)
class Nano17Table:
    """`[force_sensor]` / `[actuator_force_sensor]`, backend `nano17` (ATI Nano17 gauges read by the DAQ)."""

    backend: str = setting(choices=("nano17",))
    calibration_file: str = setting()  # relative paths are relative to the rig file
    gauge_channels: str = setting()  # six DAQ inputs, comma-separated
    axis: str = setting("Fz", choices=("Fx", "Fy", "Fz"))
    sign: float = 1.0  # +1 or -1
    sample_rate_Hz: float = setting(NANO17_SAMPLE_RATE_HZ, positive=True)
    daq_device: str = "Dev1"
    port: str | None = None  # accepted for symmetry with loadstar; unused

    def channels(self) -> tuple[str, ...]:
        return tuple(c.strip() for c in self.gauge_channels.split(","))


@dataclass(frozen=True)
class TrekTable:
    """`[amplifier]`, backend `trek`: both HV channels on one DAQ device."""

    backend: str = setting(choices=("trek",))
    gain_V_per_V: float = setting(positive=True)
    monitor_scale_V_per_V: float = setting(positive=True)
    bias_output: str = setting()
    bias_monitor: str = setting()
    drive_output: str = setting()
    drive_monitor: str = setting()
    daq_device: str = "Dev1"


@dataclass(frozen=True)
class CameraTable:
    """`[camera]` (optional): backend `opencv`, `pixelink` or `none`, and the optics."""

    backend: str = setting(choices=("opencv", "pixelink", "none"))
    device: int = 0  # OpenCV index
    device_path: str | None = None  # OpenCV device path or URL, instead of `device`
    frame_rate_Hz: float = setting(60.0, positive=True)
    metres_per_pixel: float = setting(1e-5, positive=True)
    displacement_sign: float = 1.0  # +1 or -1
    marker_sigma_px: float = setting(2.0, positive=True)


ForceSensorTable = LoadstarTable | Nano17Table
STAGE_TABLES: dict[str, type[Smc100Table]] = {"smc100": Smc100Table}
FORCE_SENSOR_TABLES: dict[str, type[ForceSensorTable]] = {"loadstar": LoadstarTable, "nano17": Nano17Table}
AMPLIFIER_TABLES: dict[str, type[TrekTable]] = {"trek": TrekTable}
CAMERA_TABLES: dict[str, type[CameraTable]] = {"opencv": CameraTable, "pixelink": CameraTable, "none": CameraTable}
# Keys whose value must be +1 or -1, per table class.
_SIGN_KEYS: dict[type, tuple[str, ...]] = {Smc100Table: ("toward_leg_sign",), Nano17Table: ("sign",),
                                           CameraTable: ("displacement_sign",)}


@dataclass(frozen=True)
class RigFile:
    """A checked rig file. `sim` is the raw `[sim]` table: the simulated bench's backend checks it."""

    path: Path
    text: str
    rig: RigTable
    stage: Smc100Table
    force_sensor: ForceSensorTable
    actuator_force_sensor: ForceSensorTable | None
    amplifier: TrekTable
    camera: CameraTable | None
    sim: Mapping[str, Any]

    @property
    def source(self) -> str:
        return str(self.path)

    @property
    def name(self) -> str:
        return self.rig.name if self.rig.name is not None else self.path.stem

    def place(self, table: str) -> Place:
        return Place(self.source, table)

    def where(self, table: str, key: str) -> str:
        """`file: [table] key`, for errors found while building a device from a checked table."""
        return self.place(table).key(key)

    def force_sensor_for(self, fixture: str) -> tuple[str, ForceSensorTable]:
        """The sensor a protocol of this fixture uses: `[actuator_force_sensor]` for the actuator when the file has
        one, else `[force_sensor]`; returns (table name, table)."""
        if fixture == "actuator" and self.actuator_force_sensor is not None:
            return "actuator_force_sensor", self.actuator_force_sensor
        return "force_sensor", self.force_sensor


def read_rig_file(path: Path) -> RigFile:
    """Read and check a rig file: every table, every key, before anything is built."""
    path = Path(path)
    text, doc = read_toml(path)
    source = str(path)
    unknown = sorted(set(doc) - set(RIG_TABLES))
    if unknown:
        raise ConfigError(f"{source}: unknown table [{unknown[0]}] (known: {', '.join(sorted(RIG_TABLES))})")
    rig = load_table(RigTable, required_table(doc, source, "rig"), Place(source, "rig"))
    stage = _device_table(doc, source, "stage", STAGE_TABLES)
    force_sensor = _device_table(doc, source, "force_sensor", FORCE_SENSOR_TABLES)
    actuator_sensor = (_device_table(doc, source, "actuator_force_sensor", FORCE_SENSOR_TABLES)
                       if "actuator_force_sensor" in doc else None)
    amplifier = _device_table(doc, source, "amplifier", AMPLIFIER_TABLES)
    camera = _device_table(doc, source, "camera", CAMERA_TABLES) if "camera" in doc else None
    return RigFile(path=path, text=text, rig=rig, stage=stage, force_sensor=force_sensor,
                   actuator_force_sensor=actuator_sensor, amplifier=amplifier, camera=camera,
                   sim=table_of(doc, source, "sim") or {})


def _device_table(doc: Mapping[str, Any], source: str, table: str, classes: Mapping[str, type[T]]) -> T:
    """A device table, checked with the dataclass of the backend it names."""
    data = required_table(doc, source, table)
    place = Place(source, table)
    backend = data.get("backend")
    if backend is None:
        raise ConfigError(f"{place.key('backend')} is missing")
    if not isinstance(backend, str) or backend not in classes:
        raise ConfigError(f"{place.key('backend')}: expected one of {', '.join(classes)}, got {backend!r}")
    cls = classes[backend]
    loaded = load_table(cls, data, place)
    for key in _SIGN_KEYS.get(cls, ()):
        if getattr(loaded, key) not in UNIT_SIGNS:
            raise ConfigError(f"{place.key(key)}: expected 1 or -1, got {data[key]!r}")
    return loaded
