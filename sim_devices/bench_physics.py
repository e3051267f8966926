"""The simulated bench's physical constants and the assembly of its plant (sim_devices.plant) from the specimen's
powertrain, the effects and the devices: masses, damping, sensor stiffness and resonance, the sensor surface (stage
carriage + mount), the bias's relaxation, the statics adapters.

Constants and their sources are in docs/model.md, "The simulated bench". Values marked estimate there have no
published number for this robot; they set the dynamics' time scales, which the tests check against separate
formulas (the resonance of a tapered cantilever, the step response of a mode), not their exact values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from hamr_bench.model import actuator as act
from hamr_bench.model.powertrain import Powertrain
from sim_devices.contact_statics import (ActuatorStatics, Clamp, FootFriction, LegStatics, LegTables,
                                         make_clamp)
from sim_devices.drive_chain import DriveChain
from sim_devices.plant import BenchPlant, ModeSpec
from sim_devices.sensor_drift import DRIFT_SHAPE, DriftModel, DriftProcess
from sim_devices.stage_carriage import CarriageModel, CarriageState

# --- the actuator: damping from the public HAMR-VI actuator model (HarvardAgileRoboticsLab/drake,
# examples/HAMR-URDF/dev/Actuator/PZTBender2.m: b_act = 0.02 N s/m at the tip)
ACTUATOR_TIP_DAMPING_N_S_PER_M = 0.02
# --- the leg: its own mass seen at the foot (estimate: a ~7 mm carbon-fibre link of ~1.3 mg as a rod about the hip,
# 1/3 of it, plus ~1 mg of foot and transmission links at the tip) and the damping of the loaded leg (estimate)
LEG_MASS_AT_FOOT_KG = 1.5e-6
LEG_DAMPING_RATIO = 0.1
# --- the sensors: transducer stiffness along the contact and the transducer's own resonance (which sets its moving
# mass); Nano17 from ATI's published specifications (Fz), Loadstar RSP2 an estimate (UNVERIFIED)
NANO17_STIFFNESS_N_PER_M = 1.1e7
NANO17_RESONANCE_HZ = 7200.0
LOADSTAR_STIFFNESS_N_PER_M = 4.0e4
LOADSTAR_RESONANCE_HZ = 1000.0
SENSOR_DAMPING_RATIO = 0.05
# the leg's stiffness at the foot never falls below this in the mode (a soft or snapping design still has one)
MIN_LEG_STIFFNESS_N_PER_M = 0.3
GRID_STEP_S = 2.5e-4
SURFACE_SAMPLE_EVERY = 4     # the stage's motor is asked every 4th grid point (1 ms) and interpolated
# the actuator's free deflection the leg's tables cover, in multiples of the nominal at 250 V (d31 gain up to 2.5x,
# hysteresis and creep on top)
U_RANGE_FACTOR = 3.0


# ------------------------------------------------------------------ masses and modes
def actuator_tip_mass_kg(a: act.ActuatorParams, points: int = 4001) -> float:
    """The bimorph's effective mass at its tip by Rayleigh's method: its mass distribution weighted by the square of
    the static deflection shape under a tip load (tapered plate: width and bending rigidity vary along it), plus
    the rigid extension moving with the tip's deflection and slope. A uniform cantilever gives 33/140 of its mass."""
    xi = np.linspace(0.0, 1.0, points)
    length = a.length_m
    w = a.width_nom_m * (a.width_ratio + 2.0 * (1.0 - a.width_ratio) * xi)
    ei = act.bending_rigidity_per_width(a) * w
    moment = length * (1.0 + a.length_ratio) - xi * length          # unit load at the extension's end
    curvature = moment / ei
    dx = length * (xi[1] - xi[0])
    slope = np.concatenate([[0.0], np.cumsum(0.5 * (curvature[1:] + curvature[:-1]) * dx)])
    deflection = np.concatenate([[0.0], np.cumsum(0.5 * (slope[1:] + slope[:-1]) * dx)])
    ext_length = a.length_ratio * length
    tip = deflection[-1] + slope[-1] * ext_length
    phi = deflection / tip
    areal = 2.0 * a.pzt_thickness_m * act.RHO_PZT_KG_PER_M3 + a.cf_thickness_m * act.RHO_CF_KG_PER_M3
    integrand = areal * w * phi ** 2
    beam = float(np.sum(0.5 * (integrand[1:] + integrand[:-1])) * dx)
    m_ext = a.fr4_thickness_m * act.RHO_FR4_KG_PER_M3 * ext_length * (2.0 - a.width_ratio) * a.width_nom_m
    s = np.linspace(0.0, 1.0, 101) * ext_length
    shape_ext = (deflection[-1] + slope[-1] * s) / tip
    ext = m_ext * float(np.mean(shape_ext ** 2))
    return beam + ext


def tip_compliance_m_per_N(a: act.ActuatorParams, points: int = 4001) -> float:
    """The same beam's tip deflection per newton by quadrature (a check on the model's closed form 1 / k_act)."""
    xi = np.linspace(0.0, 1.0, points)
    length = a.length_m
    w = a.width_nom_m * (a.width_ratio + 2.0 * (1.0 - a.width_ratio) * xi)
    curvature = (length * (1.0 + a.length_ratio) - xi * length) / (act.bending_rigidity_per_width(a) * w)
    dx = length * (xi[1] - xi[0])
    slope = np.concatenate([[0.0], np.cumsum(0.5 * (curvature[1:] + curvature[:-1]) * dx)])
    deflection = np.concatenate([[0.0], np.cumsum(0.5 * (slope[1:] + slope[:-1]) * dx)])
    return float(deflection[-1] + slope[-1] * a.length_ratio * length)


def sensor_spec(fixture: str, mount_compliance_m_per_N: float) -> tuple[float, float]:
    """(stiffness in series with the mount, moving mass) of the fixture's force sensor."""
    k, f = ((NANO17_STIFFNESS_N_PER_M, NANO17_RESONANCE_HZ) if fixture == "actuator"
            else (LOADSTAR_STIFFNESS_N_PER_M, LOADSTAR_RESONANCE_HZ))
    mass = k / (2.0 * math.pi * f) ** 2
    return 1.0 / (1.0 / k + mount_compliance_m_per_N), mass


def actuator_modes(a: act.ActuatorParams, clamp: Clamp | None, mount_compliance: float) -> ModeSpec:
    m = actuator_tip_mass_kg(a)
    k = act.stiffness_N_per_m(a)
    if clamp is not None:
        k = 1.0 / (1.0 / k + 1.0 / clamp.k0)  # type: ignore[attr-defined]
    ks, ms = sensor_spec("actuator", mount_compliance)
    zeta = ACTUATOR_TIP_DAMPING_N_S_PER_M / (2.0 * math.sqrt(k * m))
    return ModeSpec(m, k, zeta, ms, ks, SENSOR_DAMPING_RATIO)


def leg_modes(p: Powertrain, mount_compliance: float) -> ModeSpec:
    ratio = float(p.transmission_ratio(0.0))
    m = LEG_MASS_AT_FOOT_KG + actuator_tip_mass_kg(p.actuator) / ratio ** 2
    k = max(float(p.leg_stiffness_N_per_m(0.0)), MIN_LEG_STIFFNESS_N_PER_M)
    ks, ms = sensor_spec("leg", mount_compliance)
    return ModeSpec(m, k, LEG_DAMPING_RATIO, ms, ks, SENSOR_DAMPING_RATIO)


# ------------------------------------------------------------------ the bias's relaxation
BIAS_SHAPE = {"run_fraction": 0.3, "tau1_s": 30.0, "tau2_s": 600.0, "weight1": 0.5}
BIAS_WINDOW_S = 300.0


@dataclass(frozen=True)
class BiasRelaxation:
    """b(t) = b_specimen + B0 + D psi(t), psi(t) = w1 (1 - e^(-t/tau1)) + (1 - w1)(1 - e^(-t/tau2)), t from the
    bench's start: the Kapton joints of the pre-compressed transmission keep relaxing on the rig. The strength is
    the mean offset over the first 300 s; `run_fraction` of it accrues during that window (the rest, B0, relaxed
    before the test)."""

    mean_offset_m: float
    run_fraction: float = 0.3
    tau1_s: float = 30.0
    tau2_s: float = 600.0
    weight1: float = 0.5

    def __post_init__(self) -> None:
        if not (0.0 <= self.run_fraction <= 0.9 and self.tau1_s > 0 and self.tau2_s > 0 and
                0.0 <= self.weight1 <= 1.0):
            raise ValueError("bias_error shape: run_fraction in [0, 0.9], tau1_s, tau2_s > 0, weight1 in [0, 1]")

    def psi(self, t_s: np.ndarray) -> np.ndarray:
        t = np.asarray(t_s, dtype=float)
        w = self.weight1
        return w * -np.expm1(-t / self.tau1_s) + (1.0 - w) * -np.expm1(-t / self.tau2_s)

    @property
    def psi_mean(self) -> float:
        w, T = self.weight1, BIAS_WINDOW_S
        tail = sum(wi * tau * -math.expm1(-T / tau) for wi, tau in ((w, self.tau1_s), (1 - w, self.tau2_s)))
        return 1.0 - tail / T

    @property
    def start_offset_m(self) -> float:
        return (1.0 - self.run_fraction) * self.mean_offset_m

    @property
    def total_drift_m(self) -> float:
        return self.run_fraction * self.mean_offset_m / self.psi_mean

    def offset_m(self, t_s: np.ndarray) -> np.ndarray:
        return self.start_offset_m + self.total_drift_m * self.psi(t_s)


# ------------------------------------------------------------------ adapters for the plant
class ActuatorPlantStatics:
    needs_history = False

    def __init__(self, statics: ActuatorStatics) -> None:
        self.statics = statics

    def free_position_m(self, u, first, stop):
        return self.statics.free_position_m(u)

    def contact_force_N(self, u, x_s, dx_s, first, stop, near):
        return self.statics.contact_force_N(u, x_s)

    def snapshot(self) -> None:
        return None

    def restore(self, state: None) -> None:
        pass


class LegPlantStatics:
    """The leg's statics on the plant's grid: bias tables blended by time, friction in time order."""

    def __init__(self, statics: LegStatics, friction: FootFriction | None, bias: BiasRelaxation | None,
                 h_s: float) -> None:
        self.statics = statics
        self.friction = friction
        self.bias = bias
        self.h = h_s
        self.needs_history = friction is not None

    def weights(self, first: int, stop: int) -> np.ndarray | None:
        if self.bias is None or len(self.statics.tables) == 1:
            return None
        psi = self.bias.psi(self.h * np.arange(first, stop))
        pos = np.clip(psi * (len(self.statics.tables) - 1), 0.0, len(self.statics.tables) - 1 - 1e-12)
        j = pos.astype(int)
        frac = pos - j
        w = np.zeros((len(self.statics.tables), pos.size))
        cols = np.arange(pos.size)
        w[j, cols] = 1.0 - frac
        w[j + 1, cols] = frac
        return w

    def free_position_m(self, u, first, stop):
        return self.statics.free_position_m(u, self.weights(first, stop))

    def contact_force_N(self, u, x_s, dx_s, first, stop, near):
        weights = self.weights(first, stop)
        n0 = np.zeros_like(u)
        sel = np.flatnonzero(near)
        w_sel = None if weights is None else weights[:, sel]
        if sel.size:
            n0[sel] = self.statics.frictionless_force_N(u[sel], x_s[sel], w_sel)
        if self.friction is None:
            return n0
        tan_alpha = self.statics.tan_alpha(x_s, weights)
        factor, offset = self.friction.apply(n0, tan_alpha, -dx_s)
        n = n0.copy()
        if sel.size:
            n[sel] = self.statics.corrected_force_N(u[sel], x_s[sel], factor[sel], offset[sel], n0[sel], w_sel)
        return n

    def snapshot(self):
        return self.friction.snapshot() if self.friction else None

    def restore(self, state) -> None:
        if self.friction is not None:
            self.friction.restore(state)


class SensorSurface:
    """Where the sensor surface sits in the plant's coordinate, x_s = -(carriage - touch) x sign - drift t: the
    stage's motor through the carriage model (when the stage has play) and the mount's thermal creep."""

    def __init__(self, stage: Any, touch_stage_m: float, toward_sign: float, carriage: CarriageModel | None,
                 mount_rate_m_per_s: float, t0_s: float) -> None:
        self.stage = stage
        self.touch = touch_stage_m
        self.sign = toward_sign
        self.model = carriage
        self.rate = mount_rate_m_per_s
        self.t0 = t0_s
        self.state: CarriageState | None = None

    def run(self, times_s: np.ndarray) -> np.ndarray:
        motor = self._motor(np.asarray(times_s, dtype=float))
        position = motor
        if self.model is not None:
            if self.state is None:
                self.state = CarriageState.at_rest(float(motor[0]))
            position = self.model.run(motor, self.state)
        x_s = -(position - self.touch) * self.sign
        if self.rate:
            x_s = x_s - self.rate * (np.asarray(times_s) - self.t0)
        return x_s

    def _motor(self, times: np.ndarray) -> np.ndarray:
        """The motor's position at each time: the emulator asked at every 4th time (1 ms apart on the grid) and
        at the last, linear between (the stage's trapezoid profile departs from a chord of 1 ms by at most
        a / 8 x (1 ms)^2, 2.5 nm at its 20 mm/s^2)."""
        if times.size <= 8:
            return np.array(self.stage.positions_m(times.tolist()), dtype=float)
        picks = np.unique(np.concatenate([np.arange(0, times.size, SURFACE_SAMPLE_EVERY), [times.size - 1]]))
        sampled = np.array(self.stage.positions_m(times[picks].tolist()), dtype=float)
        if sampled[0] == sampled[-1] and np.all(sampled == sampled[0]):
            return np.full(times.size, sampled[0])
        return np.interp(times, times[picks], sampled)

    def snapshot(self) -> CarriageState | None:
        return self.state.copy() if self.state is not None else None

    def restore(self, state: CarriageState | None) -> None:
        self.state = state.copy() if state is not None else None


# ------------------------------------------------------------------ assembly
@dataclass(frozen=True)
class PlantInputs:
    """What the bench hands the assembly (besides the devices)."""

    fixture: str
    effects: dict[str, float]
    shapes: dict[str, dict[str, float]]
    seed: int
    dynamics: bool
    grid_step_s: float
    touch_stage_m: float
    toward_sign: float


def build_plant(inputs: PlantInputs, powertrain: Powertrain, daq: Any, stage: Any, clip_V: float,
                t0_s: float) -> BenchPlant:
    """The plant for a bench whose specimen powertrain is `powertrain` (model-parameter effects applied)."""
    e, shapes, h = inputs.effects, inputs.shapes, inputs.grid_step_s
    a = powertrain.actuator
    mount = e.get("sensor_compliance", 0.0)
    clamp = make_clamp(e["base_compliance"], a, shapes.get("base_compliance", {})) if e.get("base_compliance") \
        else None
    drive = DriveChain(h, act.displacement_per_volt(a), a.pzt_thickness_m, e, shapes)

    def amplifier_outputs(times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        vb = np.asarray(daq.output_voltage_V("ao0", times), dtype=float)
        vd = np.asarray(daq.output_voltage_V("ao1", times), dtype=float)
        return np.clip(vb, -clip_V, clip_V), np.clip(vd, -clip_V, clip_V)

    backlash = e.get("stage_backlash", 0.0)
    carriage = CarriageModel(backlash, **_carriage_shape(shapes.get("stage_backlash", {}))) if backlash else None
    surface = SensorSurface(stage, inputs.touch_stage_m, inputs.toward_sign, carriage,
                            e.get("mount_thermal_drift", 0.0), t0_s)
    drift = None
    if e.get("sensor_drift"):
        drift = DriftProcess(DriftModel(e["sensor_drift"], **{**DRIFT_SHAPE, **shapes.get("sensor_drift", {})}), h,
                             inputs.seed)
    statics: Any
    if inputs.fixture == "actuator":
        ks, _ = sensor_spec("actuator", mount)
        statics = ActuatorPlantStatics(ActuatorStatics(act.stiffness_N_per_m(a), ks, clamp))
        modes = actuator_modes(a, clamp, mount)
    else:
        ks, _ = sensor_spec("leg", mount)
        bias = BiasRelaxation(e["bias_error"], **{**BIAS_SHAPE, **shapes.get("bias_error", {})}) \
            if e.get("bias_error") else None
        tables = leg_tables(powertrain, bias, clip_V)
        friction = FootFriction(e["foot_friction"]) if e.get("foot_friction") else None
        statics = LegPlantStatics(LegStatics(tables, ks, clamp), friction, bias, h)
        modes = leg_modes(tables[0].p, mount)
    return BenchPlant(h_s=h, t0_s=t0_s, modes=modes, drive=drive, statics=statics,
                      amplifier_outputs=amplifier_outputs, surface=surface, drift=drift,
                      dynamics=inputs.dynamics)


def leg_tables(powertrain: Powertrain, bias: BiasRelaxation | None, clip_V: float) -> list[LegTables]:
    """The leg's tables at the bias values the run passes through (one when the bias holds still)."""
    internal = _unlimited(powertrain)
    u_max = U_RANGE_FACTOR * act.displacement_per_volt(powertrain.actuator) * clip_V
    if bias is None:
        return [LegTables(internal, internal, u_max)]
    base = powertrain.design.bias_m
    fractions = (0.0, 0.5, 1.0) if bias.total_drift_m else (0.0,)
    trains = [_unlimited(powertrain, base + bias.start_offset_m + f * bias.total_drift_m) for f in fractions]
    return [LegTables(p, trains[0], u_max) for p in trains]


def _unlimited(p: Powertrain, bias_m: float | None = None) -> Powertrain:
    """The same powertrain (effects already applied to its parameters) without plate effects and with a voltage
    limit no drive reaches: the tables reach any deflection through an equivalent drive."""
    design = p.design if bias_m is None else replace(p.design, bias_m=bias_m)
    return Powertrain(p.actuator, design, (), voltage_limit_V=1e7)


def _carriage_shape(shape: dict[str, float]) -> dict[str, float]:
    known = {"lag_m": 0.5e-6, "stick_ratio": 1.3}
    extra = sorted(set(shape) - set(known))
    if extra:
        raise ValueError(f"stage_backlash shape: unknown parameter {extra[0]!r} (known: lag_m, stick_ratio)")
    return {**known, **shape}
