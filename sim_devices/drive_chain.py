"""From the amplifier outputs to the actuator's free tip deflection u, per PZT plate and in time order: the
bench-side forms of the drive effects (issue 16's generator column, coordinator's notes/forms.md).

Bias-drive-ground: the bottom plate sees V_drive, the top plate V_bias - V_drive. Each plate's voltage p passes,
in this order, through

1. `amplifier_gain_error` (decoy): the voltage reaching the plate is (1 - s) p;
2. hysteresis: a Preisach operator (sim_devices.preisach) on p / 250 V, mixed with its reversible part:
   q = 250 V [(1 - eta) x + eta P[x]];
3. creep: a Kelvin-Voigt chain (a discrete Prony series, 2-4 time constants between 10 ms and 100 s):
   q_c = (q + sum a_i z_i) / (1 + sum a_i), dz_i/dt = (q - z_i) / tau_i, so a step settles to itself;
4. the field-dependent d31: the plate's strain scales with G(E), E = |p| / t_p, a monotone smooth curve through
   drawn knots (monotone cubic, Fritsch-Carlson) or a logistic law in field, normalised G(1.13 V/um) = 1 (the
   middle of the paper's 100-250 V range on 155 um plates); its strength is G at 250 V / G at 100 V - 1 (either
   sign, "up to ~2x").

u = (delta / V) (p_eff,bottom - p_eff,top), delta / V the specimen actuator's free deflection per volt. Strength 0
of an effect skips its stage, so a bench without drive effects computes u = (delta / V)(2 V_drive - V_bias).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sim_devices.linear_dynamics import FirstOrderLag
from sim_devices.preisach import EverettTable, PreisachDensity, PreisachOperator, PreisachState

FULL_SCALE_V = 250.0
# reference fields (V/m) of the d31 curve: 100, 175 and 250 V across the effective 155 um plate (Table I)
FIELD_LOW_V_PER_M = 100.0 / 155e-6
FIELD_REF_V_PER_M = 175.0 / 155e-6
FIELD_HIGH_V_PER_M = 250.0 / 155e-6
FIELD_MAX_V_PER_M = 2.0e6
# the creep strength is the mean growth per decade between these times after a step
CREEP_SPAN_S = (0.01, 100.0)


# ------------------------------------------------------------------ field-dependent d31
def pchip_slopes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Fritsch-Carlson slopes of a monotone piecewise-cubic Hermite interpolant through (x, y)."""
    h = np.diff(x)
    delta = np.diff(y) / h
    d = np.zeros_like(y)
    for k in range(1, len(x) - 1):
        if delta[k - 1] * delta[k] > 0:
            w1 = 2 * h[k] + h[k - 1]
            w2 = h[k] + 2 * h[k - 1]
            d[k] = (w1 + w2) / (w1 / delta[k - 1] + w2 / delta[k])
    # end slopes: the one-sided three-point formula, kept monotone
    for k, h0, h1, d0, d1 in ((0, h[0], h[1], delta[0], delta[1]), (-1, h[-1], h[-2], delta[-1], delta[-2])):
        slope = ((2 * h0 + h1) * d0 - h0 * d1) / (h0 + h1)
        if np.sign(slope) != np.sign(d0):
            slope = 0.0
        elif np.sign(d0) != np.sign(d1) and abs(slope) > abs(3 * d0):
            slope = 3 * d0
        d[k] = slope
    return d


def pchip_eval(x: np.ndarray, y: np.ndarray, d: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The Hermite cubic through (x, y) with slopes d at t (held constant beyond the ends)."""
    t = np.clip(np.asarray(t, dtype=float), x[0], x[-1])
    k = np.clip(np.searchsorted(x, t, side="right") - 1, 0, len(x) - 2)
    h = x[k + 1] - x[k]
    s = (t - x[k]) / h
    h00 = (1 + 2 * s) * (1 - s) ** 2
    h10 = s * (1 - s) ** 2
    h01 = s * s * (3 - 2 * s)
    h11 = s * s * (s - 1)
    return h00 * y[k] + h10 * h * d[k] + h01 * y[k + 1] + h11 * h * d[k + 1]


@dataclass(frozen=True)
class FieldGain:
    """G(E) for one form: 'logistic' (shape: switch_field_V_per_um, width_V_per_um) or 'knots' (shape: split,
    low_tail, high_tail: where between 100 and 250 V the change happens and how much continues beyond)."""

    strength: float
    form: str = "logistic"
    switch_field_V_per_um: float = 0.8
    width_V_per_um: float = 0.3
    split: float = 0.5
    low_tail: float = 0.15
    high_tail: float = 0.1
    _knots: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not (-0.6 <= self.strength <= 1.5):
            raise ValueError(f"field_dependent_d31 strength must be in [-0.6, 1.5], got {self.strength!r}")
        if self.form not in ("logistic", "knots"):
            raise ValueError(f"field_dependent_d31 form must be 'logistic' or 'knots', got {self.form!r}")
        if self.form == "knots":
            r = 1.0 + self.strength
            e = np.array([0.0, FIELD_LOW_V_PER_M, FIELD_REF_V_PER_M, FIELD_HIGH_V_PER_M, FIELD_MAX_V_PER_M])
            g_lo = r ** (-self.split)
            g_hi = r ** (1.0 - self.split)
            g = np.array([g_lo * r ** (-self.low_tail), g_lo, 1.0, g_hi, g_hi * r ** self.high_tail])
            object.__setattr__(self, "_knots", (e, g, pchip_slopes(e, g)))
        else:
            sig = self._sigmoid
            d_hi = sig(FIELD_HIGH_V_PER_M) - sig(FIELD_REF_V_PER_M)
            d_lo = sig(FIELD_LOW_V_PER_M) - sig(FIELD_REF_V_PER_M)
            amplitude = self.strength / (d_hi - (1.0 + self.strength) * d_lo)
            object.__setattr__(self, "_knots", None)
            object.__setattr__(self, "_amplitude", amplitude)
            if 1.0 + amplitude * (sig(0.0) - sig(FIELD_REF_V_PER_M)) <= 0.05 or \
                    1.0 + amplitude * (sig(FIELD_MAX_V_PER_M) - sig(FIELD_REF_V_PER_M)) <= 0.05:
                raise ValueError(f"field_dependent_d31: strength {self.strength} with this logistic shape makes "
                                 "d31 vanish somewhere in 0-2 V/um")

    def _sigmoid(self, e):
        z = (np.asarray(e, dtype=float) - self.switch_field_V_per_um * 1e6) / (self.width_V_per_um * 1e6)
        return 0.5 * (1.0 + np.tanh(0.5 * z))

    def __call__(self, field_V_per_m: np.ndarray | float) -> np.ndarray:
        e = np.abs(np.asarray(field_V_per_m, dtype=float))
        if self._knots is not None:
            x, y, d = self._knots
            return pchip_eval(x, y, d, e)
        return 1.0 + self._amplitude * (self._sigmoid(e) - self._sigmoid(FIELD_REF_V_PER_M))  # type: ignore


# ------------------------------------------------------------------ creep
@dataclass(frozen=True)
class PronyCreep:
    """Creep weights a_i and time constants tau_i from a strength (mean growth per decade over 10 ms - 100 s)."""

    strength: float
    taus_s: tuple[float, ...] = (0.05, 1.0, 20.0)
    weights: tuple[float, ...] = (0.3, 0.35, 0.35)

    def __post_init__(self) -> None:
        if len(self.taus_s) != len(self.weights) or not 1 <= len(self.taus_s) <= 6:
            raise ValueError("creep needs 1-6 time constants with one weight each")
        if any(t <= 0 for t in self.taus_s) or any(w < 0 for w in self.weights) or sum(self.weights) <= 0:
            raise ValueError("creep time constants must be > 0 and weights >= 0 (not all 0)")
        w = np.asarray(self.weights, float) / float(np.sum(self.weights))
        t0, t1 = CREEP_SPAN_S
        reach = float(np.sum(w * (np.exp(-t0 / np.asarray(self.taus_s)) - np.exp(-t1 / np.asarray(self.taus_s)))))
        growth = self.strength * math.log10(t1 / t0)
        if not (0 <= growth < reach):
            raise ValueError(f"creep strength {self.strength} is beyond what these time constants can give "
                             f"(at most {reach / math.log10(t1 / t0):.3g} per decade)")
        total = growth / (reach - growth)
        object.__setattr__(self, "_a", total * w)

    @property
    def amplitudes(self) -> np.ndarray:
        return self._a  # type: ignore[attr-defined]

    def step_response(self, t_s: np.ndarray) -> np.ndarray:
        """Output after a unit step at t = 0 (1 as t -> infinity)."""
        t = np.asarray(t_s, dtype=float)[..., None]
        a = self.amplitudes
        return (1.0 + np.sum(a * (1.0 - np.exp(-t / np.asarray(self.taus_s))), axis=-1)) / (1.0 + np.sum(a))


# ------------------------------------------------------------------ one plate, the two plates
@dataclass
class PlateState:
    preisach: PreisachState
    creep_z: np.ndarray
    last_q: float

    def copy(self) -> PlateState:
        return PlateState(self.preisach.copy(), self.creep_z.copy(), self.last_q)


class PlateChain:
    """One plate's voltage -> its effective (strain-producing) voltage, in time order on a grid of step h."""

    def __init__(self, h_s: float, pzt_thickness_m: float, hysteresis: HysteresisMap | None,
                 creep: PronyCreep | None, gain: FieldGain | None, supply_factor: float) -> None:
        self.thickness = pzt_thickness_m
        self.supply = supply_factor
        self.hyst = hysteresis
        self.gain = gain
        self.creep = creep
        self.lags = [FirstOrderLag(t, h_s) for t in creep.taus_s] if creep else []
        self.state = PlateState(PreisachState(), np.zeros(len(self.lags)), 0.0)
        self._op = PreisachOperator(hysteresis.table, self.state.preisach) if hysteresis else None

    def snapshot(self) -> PlateState:
        return self.state.copy()

    def restore(self, state: PlateState) -> None:
        self.state = state.copy()
        if self._op is not None:
            self._op.state = self.state.preisach

    def run(self, volts: np.ndarray) -> np.ndarray:
        p = np.asarray(volts, dtype=float)
        if self.supply != 1.0:
            p = p * self.supply
        q = p
        if self._op is not None:
            x = np.clip(p / FULL_SCALE_V, 0.0, 1.0)
            q = FULL_SCALE_V * self.hyst.effective(x, self._op.run(x) / self._op.everett.total)  # type: ignore
            # beyond the Preisach range (a negative transient, above full scale) the plate is linear
            q = q + (p - FULL_SCALE_V * x)
        if self.creep is not None:
            a = self.creep.amplitudes
            acc = q.copy()
            for i, lag in enumerate(self.lags):
                z = lag.run(self.state.last_q, q, float(self.state.creep_z[i]))
                acc += a[i] * z
                self.state.creep_z[i] = z[-1] if z.size else self.state.creep_z[i]
            if q.size:
                self.state.last_q = float(q[-1])
            q = acc / (1.0 + float(np.sum(a)))
        if self.gain is not None:
            q = q * self.gain(p / self.thickness)
        return q


class DriveChain:
    """(V_bias, V_drive) on the grid -> the actuator's free tip deflection u (m), stateful in time order."""

    def __init__(self, h_s: float, displacement_per_volt_m: float, pzt_thickness_m: float,
                 effects: dict[str, float], shapes: dict[str, dict[str, float]]) -> None:
        self.delta_per_volt = displacement_per_volt_m
        supply = 1.0 - min(effects.get("amplifier_gain_error", 0.0), 0.9)
        hyst = creep = gain = None
        if effects.get("hysteresis", 0.0):
            hyst = hysteresis_setup(effects["hysteresis"], shapes.get("hysteresis", {}))
        if effects.get("creep", 0.0):
            creep = PronyCreep(effects["creep"], **creep_shape(shapes.get("creep", {})))
        if effects.get("field_dependent_d31", 0.0):
            gain = FieldGain(effects["field_dependent_d31"], **gain_shape(shapes.get("field_dependent_d31", {})))
        self.plates = [PlateChain(h_s, pzt_thickness_m, hyst, creep, gain, supply) for _ in range(2)]
        self.linear = hyst is None and creep is None and gain is None and supply == 1.0

    def snapshot(self) -> list[PlateState]:
        return [p.snapshot() for p in self.plates]

    def restore(self, states: list[PlateState]) -> None:
        for p, s in zip(self.plates, states, strict=True):
            p.restore(s)

    def run(self, v_bias_V: np.ndarray, v_drive_V: np.ndarray) -> np.ndarray:
        vb = np.asarray(v_bias_V, dtype=float)
        vd = np.asarray(v_drive_V, dtype=float)
        if self.linear:
            return self.delta_per_volt * (2.0 * vd - vb)
        bottom = self.plates[0].run(vd)
        top = self.plates[1].run(vb - vd)
        return self.delta_per_volt * (bottom - top)


# ------------------------------------------------------------------ shapes and their defaults
HYSTERESIS_SHAPE = {"r0": 1.0, "kappa": 0.3}   # kappa != 0: the density is not a function of alpha - beta alone
CREEP_SHAPE = {"tau1_s": 0.05, "tau2_s": 1.0, "tau3_s": 20.0, "weight1": 0.3, "weight2": 0.35, "weight3": 0.35}
D31_SHAPE = {"form": 0.0, "switch_field_V_per_um": 0.8, "width_V_per_um": 0.3, "split": 0.5, "low_tail": 0.15,
             "high_tail": 0.1}


def _unknown(shape: dict[str, float], known: dict[str, float], name: str) -> None:
    extra = sorted(set(shape) - set(known))
    if extra:
        raise ValueError(f"{name} shape: unknown parameter {extra[0]!r} (known: {', '.join(known)})")


@dataclass(frozen=True)
class HysteresisMap:
    """A plate's hysteresis: the Preisach output mixed with the reversible part, S = (1 - eta) x + eta P[x], then
    read back through the inverse of S's first rise from 0 V (a static map): every cycle from 0 V peaks on the
    nominal line, so the dwell levels stay where the nominal model puts them and the loop shows on the ramps (an
    amplitude-dependent gain is the field_dependent_d31 effect's). The inverse is tabulated."""

    table: EverettTable
    eta: float
    grid: np.ndarray
    rise: np.ndarray

    @classmethod
    def build(cls, table: EverettTable, eta: float, points: int = 2049) -> HysteresisMap:
        x = np.linspace(0.0, 1.0, points)
        rise = (1.0 - eta) * x + eta * table(x, np.zeros_like(x)) / table.total
        return cls(table, eta, x, rise)

    def effective(self, x: np.ndarray, preisach_01: np.ndarray) -> np.ndarray:
        s = (1.0 - self.eta) * x + self.eta * preisach_01
        return np.interp(s, self.rise, self.grid)


def hysteresis_setup(strength: float, shape: dict[str, float]) -> HysteresisMap:
    """The plate map for a strength (largest gap between the rising and falling net drive of full 250 V cycles at a
    250 V bias, over the net span 2 x 250 V): eta found by bisection (the gap grows with eta)."""
    _unknown(shape, HYSTERESIS_SHAPE, "hysteresis")
    s = {**HYSTERESIS_SHAPE, **shape}
    table = EverettTable(PreisachDensity(s["r0"], s["kappa"]))
    top = full_cycle_gap(HysteresisMap.build(table, 0.999))
    if not 0 < strength <= top:
        raise ValueError(f"hysteresis strength {strength} must be in (0, {top:.3g}] for this shape")
    # Illinois (regula falsi) on gap(eta) - strength: the gap grows smoothly with eta
    lo, hi, g_lo, g_hi = 0.0, 0.999, -strength, top - strength
    side = 0
    mid = hi
    for _ in range(60):
        mid = (lo * g_hi - hi * g_lo) / (g_hi - g_lo)
        g = full_cycle_gap(HysteresisMap.build(table, mid), points=801) - strength
        if abs(g) < 1e-7 * strength:
            break
        if g < 0:
            lo, g_lo = mid, g
            g_hi = g_hi / 2 if side == -1 else g_hi
            side = -1
        else:
            hi, g_hi = mid, g
            g_lo = g_lo / 2 if side == 1 else g_lo
            side = 1
    return HysteresisMap.build(table, mid)


def full_cycle_gap(hmap: HysteresisMap, points: int = 2001) -> float:
    """Largest gap between the rising and falling net drive over a 0 -> 250 -> 0 V drive cycle at a 250 V bias
    (the bias charged first, then the cycle), over the net span, as a fraction."""
    bottom, top = PreisachOperator(hmap.table), PreisachOperator(hmap.table)
    x = np.linspace(0.0, 1.0, points)
    total = hmap.table.total
    top.run(x)                                                  # the bias comes up with the drive at 0
    up = hmap.effective(x, bottom.run(x) / total) - hmap.effective(1.0 - x, top.run(1.0 - x) / total)
    down = (hmap.effective(x[::-1], bottom.run(x[::-1]) / total)
            - hmap.effective(x, top.run(x) / total))[::-1]
    return float(np.max(np.abs(down - up)) / 2.0)


def creep_shape(shape: dict[str, float]) -> dict[str, tuple[float, ...]]:
    _unknown(shape, {**CREEP_SHAPE, "tau4_s": 0, "weight4": 0}, "creep")
    s = {**CREEP_SHAPE, **shape} if shape else dict(CREEP_SHAPE)
    if shape:   # a drawn shape names its own terms; only those count
        s = dict(shape)
    taus = tuple(float(s[f"tau{i}_s"]) for i in range(1, 5) if f"tau{i}_s" in s)
    weights = tuple(float(s[f"weight{i}"]) for i in range(1, 5) if f"tau{i}_s" in s)
    return {"taus_s": taus, "weights": weights}


def gain_shape(shape: dict[str, float]) -> dict[str, Any]:
    _unknown(shape, D31_SHAPE, "field_dependent_d31")
    s = {**D31_SHAPE, **shape}
    out: dict[str, Any] = {k: float(v) for k, v in s.items() if k != "form"}
    out["form"] = "knots" if s["form"] >= 0.5 else "logistic"
    return out
