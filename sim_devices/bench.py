"""The simulated bench: one object that owns the physics (the specimen's powertrain, the realistic-bench effects and
the bench's dynamics), the clock and the random generators, with the device emulators as its ports.

Geometry. The stage carries the force sensor along one axis. At stage position `touch_stage_m` the sensor surface
just meets the undriven foot (leg fixture) or actuator tip (actuator fixture); moving the stage by +d in
`toward_sign` pushes the surface d further in. The physics in time (sim_devices.plant) works in one coordinate x
along that axis, positive toward the sensor: the foot's downward travel from the neutral the bench started with, or
the actuator tip's deflection; the surface sits at x_s = -(stage - touch) x sign.

What is simulated (docs/model.md, "The simulated bench"): the drive chain per PZT plate (sim_devices.drive_chain),
the plant's dynamics (a free mode: the bare actuator's tip or the loaded leg; a contact mode with the sensor's
stiffness and moving mass), the contact statics from the powertrain model (sim_devices.contact_statics), the
sensor's element and conditioning (the Loadstar averages over its conversion period; the Nano17's gauges are
sampled by the DAQ as they are), and the effects switched on by name (sim_devices.bench_effects). A specimen seed
draws this specimen's parameters within fabrication tolerances (sim_devices.specimens).

Ports: an SMC100 emulator (stage), a Loadstar emulator (leg force sensor) or a Nano17 on the simulated DAQ
(actuator force sensor), HV amplifiers on the simulated DAQ, and a camera that renders the marker where the plant
is. `ports()` gives what a rig builder hands the real drivers.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.clock import Clock, VirtualClock
from hamr_bench.errors import ConfigError
from hamr_bench.model import actuator_preset, design_preset
from hamr_bench.model.powertrain import Powertrain
from sim_devices.bench_effects import check_effects, check_shapes, model_effects
from sim_devices.bench_physics import GRID_STEP_S, PlantInputs, build_plant
from sim_devices.camera_sim import SimCamera, SimCameraSpec
from sim_devices.daq_sim import SimAmplifierSpec, SimDaq, SimNano17Spec, load_calibration_SI
from sim_devices.loadstar_emulator import LoadstarEmulator, LoadstarParams
from sim_devices.serial_link import register_endpoint, unregister_endpoint
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol
from sim_devices.specimens import draw_specimen

DATA_DIR = Path(__file__).resolve().parent / "data"
NANO17_CAL = DATA_DIR / "nano17_sim.cal"
_bench_ids = itertools.count(1)


@dataclass(frozen=True)
class BenchSettings:
    """What the simulated bench is: fixture, design, actuator, effects, seed, and where things sit."""

    fixture: str = "leg"  # leg | actuator
    design: int = 4
    layers: int = 2
    params_set: str = "effective"
    effects: dict[str, float] = field(default_factory=dict)
    # shape parameters of the effects' generator forms ({effect: {parameter: value}}; defaults per effect)
    effect_shapes: dict[str, dict[str, float]] = field(default_factory=dict)
    seed: int = 0
    # draw this specimen's parameters within fabrication tolerances (None: the presets exactly)
    specimen_seed: int | None = None
    # the plant's dynamics (False: every position and force the quasi-static solution at once)
    dynamics: bool = True
    touch_stage_m: float = 2.0e-3
    toward_sign: float = 1.0
    stage_limits_m: tuple[float, float] = (-5e-3, 12e-3)
    stage_velocity_m_per_s: float = 5e-3
    # Loadstar (leg rig): a small-capacity sensor in kgf (RSP2 range and resolution UNVERIFIED)
    loadstar_capacity_kg: float = 0.1
    loadstar_resolution_kg: float = 1e-5
    loadstar_command_set: str = "di1000"
    # amplifiers
    amp_gain_V_per_V: float = 35.0
    amp_monitor_scale_V_per_V: float = 100.0
    amp_bandwidth_Hz: float = 2000.0
    # camera: a marker on the foot / tip
    camera_width_px: int = 320
    camera_height_px: int = 240
    camera_frame_rate_Hz: float = 60.0
    metres_per_pixel: float = 25e-6
    marker_origin_px: tuple[float, float] = (160.0, 120.0)
    noise: bool = True
    # (device, fault name, time on the bench clock) - see FAULT_TARGETS
    faults: tuple[tuple[str, str, float], ...] = ()
    # Model parameters replacing the presets' (replay with a fit's values): {"actuator": {ActuatorParams field:
    # value}, "design": {DesignParams field: value}}; an unknown field is a ConfigError.
    model_overrides: dict[str, dict[str, Any]] = field(default_factory=dict)


FAULT_TARGETS = ("stage", "force_sensor", "daq", "camera")


def parse_fault(text: str) -> tuple[str, str, float]:
    """'stage:following_error@12.5' -> ('stage', 'following_error', 12.5); '@t' may be left out (t = 0)."""
    target, sep, rest = text.partition(":")
    name, _, at = rest.partition("@")
    if not sep or target not in FAULT_TARGETS or not name:
        raise ConfigError(f"--fault {text!r}: expected DEVICE:FAULT[@TIME_S] with DEVICE one of "
                          f"{', '.join(FAULT_TARGETS)}")
    try:
        at_s = float(at) if at else 0.0
    except ValueError:
        raise ConfigError(f"--fault {text!r}: time {at!r} is not a number of seconds") from None
    return target, name, at_s


def apply_model_overrides(actuator: Any, design: Any, overrides: dict[str, dict[str, Any]]) -> tuple[Any, Any]:
    """The presets with the fields `overrides` names replaced (dataclasses.replace, so the model re-validates)."""
    from dataclasses import fields, replace

    out = []
    for name, params in (("actuator", actuator), ("design", design)):
        values = dict((overrides or {}).get(name, {}))
        known = {f.name for f in fields(params)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ConfigError(f"model override {name}.{unknown[0]}: not a {type(params).__name__} field "
                              f"(known: {', '.join(sorted(known))})")
        if "kappa_N_m_per_rad" in values:
            values["kappa_N_m_per_rad"] = tuple(float(k) for k in values["kappa_N_m_per_rad"])
        out.append(replace(params, **values) if values else params)
    unknown_groups = sorted(set(overrides or {}) - {"actuator", "design"})
    if unknown_groups:
        raise ConfigError(f"model override {unknown_groups[0]!r}: expected 'actuator' or 'design'")
    return out[0], out[1]


class SimBench:
    """The physics and the clock of one simulated rig; emulators are its ports."""

    def __init__(self, settings: BenchSettings, clock: Clock | None = None) -> None:
        if settings.fixture not in ("leg", "actuator"):
            raise ConfigError(f"sim fixture: expected 'leg' or 'actuator', got {settings.fixture!r}")
        self.settings = s = settings
        self.clock = clock or VirtualClock()
        # One independent stream per device, so the noise a device draws does not depend on how often the others
        # were asked (a replay that polls in a different order still sees the same force noise).
        streams = np.random.SeedSequence(s.seed).spawn(5)
        self.rng = {name: np.random.default_rng(seq) for name, seq in zip(("daq", "stage", "force", "camera"),
                                                                             streams[:4], strict=True)}
        physics_seed = int(streams[4].generate_state(1)[0])
        self.effects = check_effects(dict(s.effects), "sim effects")
        self.effect_shapes = check_shapes(dict(s.effect_shapes), "sim effect_shapes")
        actuator, design = actuator_preset(s.layers, s.params_set), design_preset(s.design)
        if s.specimen_seed is not None:
            drawn = draw_specimen(s.specimen_seed, actuator.__dict__, design.__dict__)
            actuator, design = apply_model_overrides(actuator, design, drawn)
        actuator, design = apply_model_overrides(actuator, design, s.model_overrides)
        self.powertrain = Powertrain(actuator, design, model_effects(self.effects))
        self.actuator = self.powertrain.actuator
        self._name = f"bench{next(_bench_ids)}"
        self._endpoints: list[str] = []
        self._build_daq()
        self._build_stage()
        try:
            self.plant = build_plant(
                PlantInputs(s.fixture, self.effects, self.effect_shapes, physics_seed, s.dynamics, GRID_STEP_S,
                            s.touch_stage_m, s.toward_sign),
                self.powertrain, self.daq, self.stage, self.powertrain.voltage_limit_V, self.clock.now_s())
        except ValueError as exc:   # an effect strength or shape the generator form cannot realise
            self.close()
            raise ConfigError(f"sim effects: {exc}") from None
        self.daq.output_listeners.append(self.plant.invalidate)
        self.stage.motion_listeners.append(self.plant.invalidate)
        if s.fixture == "leg":
            self._build_loadstar()
        self._build_camera()
        for target, name, at_s in s.faults:
            self.inject_fault(target, name, at_s)

    # ------------------------------------------------------------------ ports
    def _build_daq(self) -> None:
        s = self.settings
        amps = [SimAmplifierSpec(ao_channel=ch, monitor_channel=mon, gain_V_per_V=s.amp_gain_V_per_V,
                                 bandwidth_Hz=s.amp_bandwidth_Hz,
                                 monitor_scale_V_per_V=s.amp_monitor_scale_V_per_V,
                                 monitor_noise_V=1e-3 if s.noise else 0.0)
                for ch, mon in (("ao0", "ai6"), ("ao1", "ai7"))]
        nano17 = None
        if s.fixture == "actuator":
            # A PCI-6052E in differential mode has ai0-ai7: gauges on ai0-ai5, amplifier monitors on ai6, ai7.
            nano17 = SimNano17Spec(gauge_channels=tuple(f"ai{i}" for i in range(6)),
                                   calibration_SI=load_calibration_SI(NANO17_CAL),
                                   noise_V=1e-3 if s.noise else 0.0)
        self.daq = SimDaq(self.clock, self.rng["daq"], amplifiers=amps, nano17=nano17,
                          force_z_source=self.contact_forces_N if nano17 else None,  # the tip presses along z
                          ai_noise_V=1e-3 if s.noise else 0.0)

    def _build_stage(self) -> None:
        s = self.settings
        # The stage's play and drive compliance (effect stage_backlash) are the bench's carriage model, not the
        # controller's: the emulator's carriage follows its motor exactly.
        params = Smc100Params(soft_limit_low_m=s.stage_limits_m[0], soft_limit_high_m=s.stage_limits_m[1],
                              velocity_m_per_s=s.stage_velocity_m_per_s)
        self.stage = Smc100Emulator(self.clock, params)
        self.stage_protocol = Smc100Protocol(self.stage, self.rng["stage"])
        self.stage_url = self._register("stage", self.stage_protocol)

    def _build_loadstar(self) -> None:
        s = self.settings
        params = LoadstarParams(command_set=s.loadstar_command_set, units="KG", capacity=s.loadstar_capacity_kg,
                                resolution=s.loadstar_resolution_kg, noise_counts=1.0 if s.noise else 0.0)
        self.loadstar = LoadstarEmulator(self.clock, self.contact_force_N, self.rng["force"], params)
        self.conversion_s = 1.0 / params.stream_rate_Hz
        self.force_sensor_url = self._register("force", self.loadstar)

    def _build_camera(self) -> None:
        s = self.settings
        spec = SimCameraSpec(width_px=s.camera_width_px, height_px=s.camera_height_px,
                             frame_rate_Hz=s.camera_frame_rate_Hz,
                             modes=((s.camera_width_px, s.camera_height_px, max(s.camera_frame_rate_Hz, 1.0)),),
                             read_noise_e=5.0 if s.noise else 0.0)
        self.camera = SimCamera(self.clock, self.rng["camera"], self.marker_px_many, spec)

    def _register(self, role: str, endpoint: Any) -> str:
        name = f"{self._name}-{role}"
        self._endpoints.append(name)
        return register_endpoint(name, endpoint, replace=True)

    def inject_fault(self, target: str, name: str, at_s: float | None = None) -> None:
        """Switch a fault on in one emulator (names: sim_devices.faults), now or at `at_s` on the bench clock."""
        if target == "stage":
            self.stage.faults.inject(name, at_s)
        elif target == "force_sensor" and self.settings.fixture == "leg":
            self.loadstar.faults.inject(name, at_s)
        elif target in ("daq", "force_sensor"):  # the actuator rig's force sensor is read through the DAQ
            self.daq.inject_fault(name, at_s=at_s)
        elif target == "camera":
            self.camera.inject_fault(name, at_s=at_s)
        else:
            raise ConfigError(f"fault target {target!r}: expected one of {', '.join(FAULT_TARGETS)}")

    def ports(self) -> dict[str, Any]:
        """What the rig builder gives the real drivers in place of the rig file's ports."""
        ports: dict[str, Any] = {"stage": self.stage_url, "daq": self.daq, "camera": self.camera}
        if self.settings.fixture == "leg":
            ports["force_sensor"] = self.force_sensor_url
        return ports

    def close(self) -> None:
        for name in self._endpoints:
            unregister_endpoint(name)
        self._endpoints.clear()

    # ------------------------------------------------------------------ what the sensors and the camera see
    def contact_forces_N(self, times_s: np.ndarray) -> np.ndarray:
        """The force the sensor's element carries at each time (the Nano17's gauges, sampled as they are)."""
        return self.plant.forces_N(np.atleast_1d(np.asarray(times_s, dtype=float)))

    def contact_force_N(self, time_s: float) -> float:
        """The Loadstar's reading before its own noise and quantisation: the force averaged over the conversion
        period that ends at `time_s`."""
        return self.plant.mean_force_N(float(time_s), self.conversion_s)

    def marker_position_m(self, time_s: float) -> float:
        """Displacement of the marker (foot down / tip toward the sensor positive) from its undriven rest."""
        return float(self.plant.positions_m(np.array([float(time_s)]))[0])

    def marker_px(self, time_s: float) -> tuple[float, float]:
        """Image position of the marker: displacement runs down the image (+y)."""
        x0, y0 = self.settings.marker_origin_px
        return x0, y0 + self.marker_position_m(time_s) / self.settings.metres_per_pixel

    def marker_px_many(self, times_s: np.ndarray) -> np.ndarray:
        """`marker_px` at every time of `times_s` in one vectorised pass, shape (n, 2): the camera asks for all the
        motion samples of an exposure at once."""
        t = np.atleast_1d(np.asarray(times_s, dtype=float))
        position_m = self.plant.positions_m(t)
        x0, y0 = self.settings.marker_origin_px
        return np.column_stack([np.full(t.shape, float(x0)), y0 + position_m / self.settings.metres_per_pixel])

    marker_px_many.vectorised = True  # type: ignore[attr-defined]

    def truth(self) -> dict[str, Any]:
        """The parameters this bench simulates with, for the recording's metadata (fit-back tests read it)."""
        a, d = self.actuator, self.powertrain.design
        spec = self.plant.spec
        return {
            "actuator": {k: getattr(a, k) for k in a.__dataclass_fields__ if isinstance(getattr(a, k), float)},
            "design": {"k_ser_N_per_m": d.k_ser_N_per_m, "kappa_N_m_per_rad": list(map(float, d.kappa_N_m_per_rad)),
                       "bias_m": d.bias_m, "kappa_units": d.kappa_units},
            "effects": dict(self.effects),
            "effect_shapes": {k: dict(v) for k, v in self.effect_shapes.items()},
            "specimen_seed": self.settings.specimen_seed,
            "dynamics": {"enabled": self.settings.dynamics, "free_frequency_Hz": spec.free_frequency_Hz,
                         "free_damping_ratio": spec.damping_ratio,
                         "contact_frequency_Hz": spec.contact_frequency_Hz,
                         "sensor_stiffness_N_per_m": spec.sensor_stiffness_N_per_m},
        }
