"""The simulated bench: one object that owns the physics (the powertrain model plus realistic-bench effects), the
clock and the random generator, with the device emulators as its ports.

Geometry. The stage carries the force sensor along one axis. At stage position `touch_stage_m` the sensor surface
just meets the undriven foot (leg fixture) or actuator tip (actuator fixture); moving the stage by +d in
`toward_sign` pushes the surface d further in. In the model's terms the surface holds the foot at height
h = (stage - touch) x toward_sign (the sag), and the foot, when it reaches it, presses with
`Powertrain.foot_force_N(V_bias, V_drive, h)`. For the actuator the surface sits at tip deflection
q = (touch - stage) x toward_sign and the tip presses with `tip_force_N`. With `sensor_compliance` the surface
gives way by F / k_sensor (solved by a few fixed-point steps: the sensor is far stiffer than a leg).

Ports: an SMC100 emulator (stage), a Loadstar emulator (leg force sensor) or a Nano17 on the simulated DAQ
(actuator force sensor), HV amplifiers on the simulated DAQ, and a camera that renders the marker where the model
puts the foot or tip. `ports()` gives what a rig builder hands the real drivers.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.clock import Clock, VirtualClock
from hamr_bench.errors import ConfigError
from hamr_bench.model import actuator as act
from hamr_bench.model import actuator_preset, design_preset
from hamr_bench.model.powertrain import Powertrain
from sim_devices.bench_effects import DriveMemory, check_effects, model_effects
from sim_devices.camera_sim import SimCamera, SimCameraSpec
from sim_devices.daq_sim import SimAmplifierSpec, SimDaq, SimNano17Spec, load_calibration_SI
from sim_devices.loadstar_emulator import LoadstarEmulator, LoadstarParams
from sim_devices.serial_link import register_endpoint, unregister_endpoint
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol

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
    seed: int = 0
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
        streams = np.random.SeedSequence(s.seed).spawn(4)
        self.rng = {name: np.random.default_rng(seq) for name, seq in zip(("daq", "stage", "force", "camera"),
                                                                             streams)}
        effects = check_effects(dict(s.effects), "sim effects")
        self.effects = effects
        actuator, design = apply_model_overrides(actuator_preset(s.layers, s.params_set), design_preset(s.design),
                                                 s.model_overrides)
        self.powertrain = Powertrain(actuator, design, model_effects(effects))
        self.actuator = self.powertrain.actuator
        self.sensor_compliance_m_per_N = effects.get("sensor_compliance", 0.0)
        self._free_height_table = self._tabulate_free_height() if s.fixture == "leg" else None
        self._force_cache: dict[tuple[float, float, float], float] = {}
        self._name = f"bench{next(_bench_ids)}"
        self._endpoints: list[str] = []
        self._build_daq()
        self.memory = DriveMemory(self._commanded_outputs, effects.get("hysteresis", 0.0),
                                  effects.get("creep", 0.0))
        self._build_stage()
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
        low, high = s.stage_limits_m
        params = Smc100Params(soft_limit_low_m=low, soft_limit_high_m=high,
                              velocity_m_per_s=s.stage_velocity_m_per_s,
                              backlash_m=self.effects.get("stage_backlash", 0.0))
        self.stage = Smc100Emulator(self.clock, params)
        self.stage_protocol = Smc100Protocol(self.stage, self.rng["stage"])
        self.stage_url = self._register("stage", self.stage_protocol)

    def _build_loadstar(self) -> None:
        s = self.settings
        drift = self.effects.get("sensor_drift", 0.0)
        params = LoadstarParams(command_set=s.loadstar_command_set, units="KG", capacity=s.loadstar_capacity_kg,
                                resolution=s.loadstar_resolution_kg, noise_counts=1.0 if s.noise else 0.0,
                                drift="random_walk" if drift else "none", drift_strength=drift)
        self.loadstar = LoadstarEmulator(self.clock, self.contact_force_N, self.rng["force"], params)
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

    # ------------------------------------------------------------------ physics
    def _commanded_outputs(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        vb = np.asarray(self.daq.output_voltage_V("ao0", times_s), dtype=float)
        vd = np.asarray(self.daq.output_voltage_V("ao1", times_s), dtype=float)
        # The model refuses voltages beyond its limit; the amplifier's own lag can overshoot by a hair.
        return self._clip_to_limit(vb), self._clip_to_limit(vd)

    def _clip_to_limit(self, volts: np.ndarray) -> np.ndarray:
        """`np.clip(volts, -limit, limit)` (the same values) without its wrapper's cost, asked per sensor read."""
        limit = self.powertrain.voltage_limit_V
        return np.minimum(np.maximum(volts, -limit), limit)

    def _tabulate_free_height(self) -> tuple[np.ndarray, np.ndarray]:
        """Free foot height as a function of the actuator's free deflection u, which is all it depends on. The
        quasi-static solve costs ~1 ms a call; the bench asks thousands of times per simulated second, so it
        interpolates this table (error below 0.1 um, checked in tests) instead."""
        limit = self.powertrain.voltage_limit_V
        v_drive = np.linspace(0.0, limit, 2001)
        u = self.powertrain.free_actuator_deflection_m(limit, v_drive)
        h = self.powertrain.free_foot_height_m(limit, v_drive)
        order = np.argsort(u)
        return u[order], h[order]

    def free_foot_height_m(self, vb, vd) -> np.ndarray:
        u_tab, h_tab = self._free_height_table
        return np.interp(self.powertrain.free_actuator_deflection_m(vb, vd), u_tab, h_tab)

    def drive_many(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Effective (V_bias, V_drive) the actuator acts on at each time, after drive-memory effects."""
        times_s = np.asarray(times_s, dtype=float)
        if not self.memory.active:  # the commanded outputs, clipped already
            return self._commanded_outputs(times_s)
        vb, vd = self.memory.many(times_s)
        return self._clip_to_limit(vb), self._clip_to_limit(vd)

    def _drive_scalar(self, time_s: float) -> tuple[float, float]:
        """`drive_many` for one time in plain floats (the same values; asked once per force-sensor sample)."""
        if self.memory.active:
            vb, vd = self.drive_many(np.array([time_s]))
            return float(vb[0]), float(vd[0])
        limit = self.powertrain.voltage_limit_V
        vb = self.daq.output_voltage_V("ao0", time_s)
        vd = self.daq.output_voltage_V("ao1", time_s)
        return min(max(vb, -limit), limit), min(max(vd, -limit), limit)

    def surface_m(self, times_s: np.ndarray) -> np.ndarray:
        """How far the sensor surface is pushed in past first touch (the sag, for the leg), at each time."""
        s = self.settings
        positions = np.array(self.stage.positions_m(np.atleast_1d(times_s).tolist()))
        return (positions - s.touch_stage_m) * s.toward_sign

    def _pressing_force(self, vb: np.ndarray, vd: np.ndarray, surface_m: np.ndarray,
                        free_height_m: np.ndarray | None = None) -> np.ndarray:
        """Force on a rigid surface `surface_m` in past first touch; 0 out of contact (vectorised). The model is
        only asked where there is contact: a surface far from the foot may lie outside the linkage's reach.
        `free_height_m` (leg only): the free foot height at (vb, vd), when the caller has it already."""
        vb, vd, surface_m = (np.asarray(a, dtype=float) for a in (vb, vd, surface_m))
        if not vb.shape == vd.shape == surface_m.shape:
            vb, vd, surface_m = np.broadcast_arrays(vb, vd, surface_m)
        force = np.zeros(surface_m.shape)
        vmap = self.powertrain.plate_voltage_map
        if self.settings.fixture == "leg":
            if free_height_m is None:
                free_height_m = self.free_foot_height_m(vb, vd)
            touching = free_height_m < surface_m
            if touching.any():
                force[touching] = self.powertrain.foot_force_N(vb[touching], vd[touching], surface_m[touching])
        else:
            q = -surface_m  # tip deflection (positive toward the sensor) where the surface sits
            touching = act.free_tip_deflection_m(self.actuator, vb, vd, vmap) > q
            if touching.any():
                force[touching] = act.tip_force_N(self.actuator, vb[touching], vd[touching], q[touching], vmap)
        force[~np.isfinite(force)] = 0.0
        return np.maximum(force, 0.0)

    def contact_forces_N(self, times_s: np.ndarray) -> np.ndarray:
        """True force between foot (or tip) and sensor at each time."""
        times_s = np.atleast_1d(np.asarray(times_s, dtype=float))
        vb, vd = self.drive_many(times_s)
        return self._contact_from_state(vb, vd, self.surface_m(times_s))

    def _contact_from_state(self, vb: np.ndarray, vd: np.ndarray, surface: np.ndarray) -> np.ndarray:
        force = self._pressing_force(vb, vd, surface)
        c = self.sensor_compliance_m_per_N
        if c > 0 and np.any(force > 0):
            force = self._compliant_contact(vb, vd, surface, force, c)
        return force

    def _compliant_contact(self, vb, vd, surface, rigid_force, c: float) -> np.ndarray:
        """Force when the sensor itself gives way by F c: the root of g(F) = F - P(surface - F c) on
        [0, P(surface)], P the rigid pressing force. g rises monotonically (P falls as the surface retreats), so
        bisection always converges, whether the sensor is much stiffer than the leg or, as against a bare
        actuator, softer (where a plain fixed-point iteration oscillates)."""
        lo = np.zeros_like(rigid_force)
        hi = np.array(rigid_force, dtype=float)
        for _ in range(48):  # 2^-48 of the rigid force: far below any sensor's resolution
            mid = 0.5 * (lo + hi)
            above = mid - self._pressing_force(vb, vd, surface - mid * c) > 0
            hi = np.where(above, mid, hi)
            lo = np.where(above, lo, mid)
        return 0.5 * (lo + hi)

    def contact_force_N(self, time_s: float) -> float:
        """Scalar form for the serial sensor emulator, which asks once per sample. During dwells the drive and
        the stage hold still, so the same state recurs for hundreds of samples: remember the last answers."""
        time_s = float(time_s)
        vb, vd = self._drive_scalar(time_s)
        s = self.settings
        surface = (self.stage.position_m(time_s) - s.touch_stage_m) * s.toward_sign
        key = (vb, vd, surface)
        force = self._force_cache.get(key)
        if force is None:
            force = float(self._contact_from_state(np.array([vb]), np.array([vd]), np.array([surface]))[0])
            if len(self._force_cache) > 4096:
                self._force_cache.clear()
            self._force_cache[key] = force
        return force

    def marker_position_m(self, time_s: float) -> float:
        """Displacement of the marker (foot down / tip toward the sensor positive) from its undriven rest."""
        t = np.array([time_s])
        vb, vd = self.drive_many(t)
        surface = self.surface_m(t)
        force = self._pressing_force(vb, vd, surface) if not self.sensor_compliance_m_per_N else \
            self.contact_forces_N(t)
        if force[0] > 0:
            return float(-(surface[0] - force[0] * self.sensor_compliance_m_per_N))
        if self.settings.fixture == "leg":
            return float(-self.free_foot_height_m(vb, vd)[0])
        return float(act.free_tip_deflection_m(self.actuator, vb, vd, self.powertrain.plate_voltage_map)[0])

    def marker_px(self, time_s: float) -> tuple[float, float]:
        """Image position of the marker: displacement runs down the image (+y)."""
        x0, y0 = self.settings.marker_origin_px
        return x0, y0 + self.marker_position_m(time_s) / self.settings.metres_per_pixel

    def marker_px_many(self, times_s: np.ndarray) -> np.ndarray:
        """`marker_px` at every time of `times_s` in one vectorised pass, shape (n, 2): the camera asks for all the
        motion samples of an exposure at once (per-sample calls dominated the camera protocol's cost)."""
        t = np.atleast_1d(np.asarray(times_s, dtype=float))
        vb, vd = self.drive_many(t)
        surface = self.surface_m(t)
        c = self.sensor_compliance_m_per_N
        if self.settings.fixture == "leg":
            height = self.free_foot_height_m(vb, vd)
            free = -height
        else:
            height = None
            free = act.free_tip_deflection_m(self.actuator, vb, vd, self.powertrain.plate_voltage_map)
        force = self._pressing_force(vb, vd, surface, height) if not c else self.contact_forces_N(t)
        position_m = np.where(force > 0, -(surface - force * c), free)
        x0, y0 = self.settings.marker_origin_px
        return np.column_stack([np.full(t.shape, float(x0)), y0 + position_m / self.settings.metres_per_pixel])

    marker_px_many.vectorised = True  # type: ignore[attr-defined]

    def truth(self) -> dict[str, Any]:
        """The parameters this bench simulates with, for the recording's metadata (fit-back tests read it)."""
        a, d = self.actuator, self.powertrain.design
        return {
            "actuator": {k: getattr(a, k) for k in a.__dataclass_fields__ if isinstance(getattr(a, k), float)},
            "design": {"k_ser_N_per_m": d.k_ser_N_per_m, "kappa_N_m_per_rad": list(map(float, d.kappa_N_m_per_rad)),
                       "bias_m": d.bias_m},
            "effects": dict(self.effects),
        }
