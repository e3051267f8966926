"""Another lab's actuator data, generated independently of the code under test, for the end-to-end import tests.

Nothing here comes from `analysis` or `hamr_bench`: the bimorph's closed form (Wood, Steltz & Fearing 2005, as the
paper uses it) is written out again, with the tapered-cantilever force factor G_F by numerical quadrature of its
defining integral (the project uses a closed form); the drive is built here (the lab's own timings, not the
project's defaults); the amplifier monitor lags and overshoots (a second-order filter), the force sensor may only
read push (0 off the tip) and lags; specimens scatter in d31 and width. The effects use forms the diagnosis does
not fit (Duhem-type hysteresis, a two-term Prony creep) so finding them is not circular. Independent of
analysis/, NOT of the physics: the same paper's model.

Bias-drive-ground: the top plate sees V_bias - V_drive, the bottom plate V_drive, so the net drive is
u = 2 V_drive - V_bias: -V_bias in the low dwell (the tip pulled back, off a push-only sensor), +V_bias in the
high dwell (blocked force F_b, free stroke delta; the stroke from low to high is 2 delta).
"""

from __future__ import annotations

import csv
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.signal import cont2discrete, lfilter, lfilter_zi

# Table I "effective" values (paper), per actuator
T_P, L, W_NOM, L_R, W_R, D31, E_P, E_C, T_CF_LAYER = 155e-6, 9.6e-3, 3.4e-3, 0.0063, 1.5, 0.36e-9, 34e9, 340e9, 30e-6


def force_factor(w_r: float, l_r: float) -> float:
    """G_F = (2/3) int_0^1 (L' - x) dx / int_0^1 (L' - x)^2 / w(x) dx, L' = 1 + l_r, w = w_r + 2 (1 - w_r) x,
    by the trapezoid rule on a fine grid."""
    x = np.linspace(0.0, 1.0, 20001)
    lp = 1.0 + l_r
    num = np.trapezoid(lp - x, x)
    den = np.trapezoid((lp - x) ** 2 / (w_r + 2.0 * (1.0 - w_r) * x), x)
    return float(2.0 / 3.0 * num / den)


@dataclass(frozen=True)
class Specimen:
    label: str
    d31_scale: float = 1.0      # fabrication scatter of the effective d31
    width_scale: float = 1.0


def per_volt(layers: int, sp: Specimen) -> tuple[float, float]:
    """(blocked force per volt c, free deflection per volt s) of one specimen: F_b = c V, delta = s V."""
    t_c = layers * T_CF_LAYER
    d31, w = D31 * sp.d31_scale, W_NOM * sp.width_scale
    rigidity = E_P * T_P / 3.0 * (1.5 * t_c**2 + 3.0 * t_c * T_P + 2.0 * T_P**2) + E_C * t_c**3 / 12.0
    c = 0.75 * d31 * E_P * w * (T_P + t_c) * force_factor(W_R, L_R) / L
    s = 0.25 * d31 * E_P * (T_P + t_c) * L**2 * (1.0 + 2.0 * L_R) / rigidity
    return c, s


@dataclass(frozen=True)
class Lab:
    """How the lab drives and measures."""

    dwell_low_s: float = 0.3
    ramp_s: float = 0.12
    dwell_high_s: float = 0.55
    cycles: int = 4
    rate_Hz: float = 500.0
    lead_s: float = 0.25              # ground before the first cycle
    tail_s: float = 0.2               # negative: the data end inside the last cycle
    monitor_noise_V: float = 0.6
    monitor_lag_s: float = 0.004      # second-order monitor: natural period ~ this, damping below
    monitor_damping: float = 0.45     # < 1: overshoots at each corner
    force_noise_N: float = 0.25e-3
    push_only: bool = True            # the sensor reads 0 when the tip is off it (low dwell)
    sensor_lag_s: float = 0.0
    camera_noise_m: float = 0.15e-6


@dataclass(frozen=True)
class Effects:
    hysteresis: float = 0.0           # Duhem-type: loop half-width ~ hysteresis x V_bias
    creep: float = 0.0                # Prony creep: fraction of a step that arrives late (two time constants)


def drive(v_bias: float, lab: Lab, start_phase_s: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(t, V_drive): lead at ground, `cycles` trapezoids (low dwell first), tail at ground."""
    period = lab.dwell_low_s + 2 * lab.ramp_s + lab.dwell_high_s
    total = lab.lead_s + lab.cycles * period + lab.tail_s
    t = np.arange(0.0, total, 1.0 / lab.rate_Hz)
    ph = t - lab.lead_s + start_phase_s
    k = np.floor(ph / period)
    x = ph - k * period
    knots_t = [0.0, lab.dwell_low_s, lab.dwell_low_s + lab.ramp_s, lab.dwell_low_s + lab.ramp_s + lab.dwell_high_s,
               period]
    level = np.interp(x, knots_t, [0.0, 0.0, 1.0, 1.0, 0.0])
    level[(ph < 0) | (k >= lab.cycles)] = 0.0
    return t, v_bias * level


def _duhem(u: np.ndarray, width_V: float) -> np.ndarray:
    """Rate-independent Duhem-type hysteresis: dy = g du + a |du| (u - y), a loop of half-width ~ (1 - g) / a."""
    if width_V <= 0:
        return u.copy()
    g = 0.7
    a = (1.0 - g) / width_V
    y = np.empty_like(u)
    y[0] = u[0]
    du = np.diff(u)
    for i, d in enumerate(du):
        y[i + 1] = y[i] + g * d + a * abs(d) * (u[i] - y[i])
    return y


def _creep(t: np.ndarray, u: np.ndarray, fraction: float) -> np.ndarray:
    """Two Kelvin-Voigt terms (0.08 s and 1.5 s, equal shares): a step's `fraction` arrives late."""
    if fraction <= 0:
        return u.copy()
    dt = float(t[1] - t[0])
    out = (1.0 - fraction) * u
    for tau in (0.08, 1.5):
        a = np.exp(-dt / tau)
        x = lfilter([1.0 - a], [1.0, -a], u, zi=[a * u[0]])[0]
        out += 0.5 * fraction * x
    return out


def _monitor(v: np.ndarray, lab: Lab, rng: np.random.Generator) -> np.ndarray:
    """A second-order amplifier monitor, w^2 / (s^2 + 2 z w s + w^2) (lags, overshoots at corners when z < 1),
    discretised with a zero-order hold, plus white noise."""
    w = 2 * np.pi / max(lab.monitor_lag_s, 1e-9)
    num_d, den_d, _dt = cont2discrete(([w * w], [1.0, 2 * lab.monitor_damping * w, w * w]), 1.0 / lab.rate_Hz,
                                      method="zoh")
    b = np.ravel(num_d)
    out = lfilter(b, den_d, v, zi=lfilter_zi(b, den_d) * v[0])[0]   # settled at the first sample's value
    return out + rng.normal(0.0, lab.monitor_noise_V, v.size)


def specimen_rows(sp: Specimen, layers: int, test: str, v_bias: float, lab: Lab, effects: Effects,
                  rng: np.random.Generator, t0: float = 0.0, force_offset_N: float = 0.0,
                  start_phase_s: float = 0.0,
                  baseline_N: Callable[[np.ndarray], np.ndarray] | None = None) -> list[dict[str, object]]:
    """One specimen's rows of one test ('blocked' or 'free') at one V_bias. `baseline_N`: the force sensor's own
    baseline at the logger's times (t0 + t), read under every sample: then the sensor reads the push of the tip
    (none off it), its baseline and its noise, where without one its noisy reading is clipped at 0."""
    t, vd = drive(v_bias, lab, start_phase_s)
    u = 2.0 * vd - v_bias                      # net drive: -V_bias at rest, +V_bias in the high dwell
    y = _creep(t, _duhem(u, effects.hysteresis * v_bias), effects.creep)
    c, s = per_volt(layers, sp)
    rows: list[dict[str, object]] = []
    mon = _monitor(vd, lab, rng)
    if test == "blocked":
        ts = t - lab.sensor_lag_s
        f = np.interp(ts, t, c * y) + force_offset_N
        if baseline_N is not None:
            f = np.maximum(f, 0.0) if lab.push_only else f
            f = f + baseline_N(t0 + t) + rng.normal(0.0, lab.force_noise_N, t.size)
        else:
            f = f + rng.normal(0.0, lab.force_noise_N, t.size)
            if lab.push_only:
                f = np.maximum(f, 0.0)
        for ti, vi, fi in zip(t, mon, f, strict=True):
            rows.append({"time_s": t0 + ti, "voltage_V": vi, "force_N": fi, "displacement_m": "",
                         "stage_position_m": "", "specimen": sp.label})
    else:
        d = s * y + 37e-6 + rng.normal(0.0, lab.camera_noise_m, t.size)
        for ti, vi, di in zip(t, mon, d, strict=True):
            rows.append({"time_s": t0 + ti, "voltage_V": vi, "force_N": "", "displacement_m": di,
                         "stage_position_m": "", "specimen": sp.label})
    return rows


@dataclass
class LabFile:
    rows: list[dict[str, object]] = field(default_factory=list)

    def write(self, path, delimiter: str = ",", decimal_comma: bool = False, bom: bool = False,
              crlf: bool = False, columns: tuple[str, ...] = ("specimen", "time_s", "voltage_V", "stage_position_m",
                                                             "force_N", "displacement_m")) -> None:
        def cell(x: object) -> str:
            if isinstance(x, float):
                text = f"{x:.9g}"
                return text.replace(".", ",") if decimal_comma else text
            return str(x)

        with open(path, "w", newline="", encoding="utf-8-sig" if bom else "utf-8") as fh:
            w = csv.writer(fh, delimiter=delimiter, lineterminator="\r\n" if crlf else "\n")
            w.writerow(columns)
            for r in self.rows:
                w.writerow([cell(r.get(c, "")) for c in columns])
