"""The CANDIDATE unmodelled effects the diagnosis fits, and the engine that predicts the phase-resolved rows of
`features.GapData` from the nominal model plus any of them.

Every candidate has strength 0 = the nominal model exactly (an inactive candidate is never evaluated). The forms
are chosen independently of the simulated bench's generator (`sim_devices.bench_effects`), so finding an effect
is not circular:

| candidate | form fitted here | generator form (bench) | strength (unit) |
|---|---|---|---|
| field_dependent_d31 | d31 linear in |E|, s >= 0: d31 (1 + s |E| / 2 V/um) (hamr_bench.model.FieldDependentD31) | tanh^2 saturating law | gain at 2 V/um |
| hysteresis | play (backlash) operator on the net drive 2 V_drive - V_bias | Bouc-Wen | half-width / 250 V |
| creep | log-time law: each drive increment settles as 1 - s log10(100 s / (t + 10 ms)) | 4-term Prony series | per decade |
| base_compliance | series spring at the base (hamr_bench.model.BaseCompliance) | rotational clamp spring | blocked-force loss |
| sensor_compliance | first-order: F_meas = F / (1 + c k_contact), k_contact from the model's local slope | contact solved by bisection | m/N |
| width_loss | constant edge loss per cut edge on the TAPERED plate (mean width and taper ratio change) | uniform width scaling | fraction of w_nom |
| bias_error | coupler lengthening offset | same (a parameter shift has one form) | m |
| stage_backlash | dead band (play operator) on the stage target sequence | carriage play in the SMC100 emulator | m |
| sensor_drift | baseline per run: 0 at the tare, free offset at the first sample, then linear (fitted linearly) | random walk | wander rate, N/sqrt(s) |

Nuisances fitted with every model (never reported as effects): per leg run the foot height at nominal zero sag
(h0; the contact search stops within a fine step), per actuator run the tip-force offset f0, and per sensor a
timing lag (the serial load cell timestamps lines after they are sampled), estimated once with the nominal model;
the offsets are linearised about each run's contact shift (`Problem.contact_shift`, fitted nonlinearly).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from hamr_bench.errors import ConfigError
from hamr_bench.model import (ActuatorParams, BaseCompliance, DesignParams, Effect, FieldDependentD31, Powertrain,
                              actuator_preset, design_preset)
from hamr_bench.model import actuator as act

FULL_SCALE_V = 250.0
DENSE_DT_S = 2e-3

# name -> (unit, bounds for the fit, one-line form)
CANDIDATES: dict[str, tuple[str, tuple[float, float], str]] = {
    # d31 of soft PZT rises with field under unipolar drive (Rayleigh behaviour; physics notes section 4): the
    # range is the physical one, as for every other candidate. A d31 uniformly off is a parameter (`fit`), not this.
    "field_dependent_d31": ("gain at 2 V/um", (0.0, 1.5), "d31 linear in field"),
    "hysteresis": ("half-width / 250 V", (0.0, 0.4), "play operator on the net drive"),
    "creep": ("per decade", (0.0, 0.1), "log-time settling of each drive increment"),
    "base_compliance": ("blocked-force loss", (0.0, 0.8), "series spring at the actuator base"),
    "sensor_compliance": ("m/N", (0.0, 5e-3), "first-order sensor spring in the contact"),
    "width_loss": ("fraction of w_nom", (0.0, 0.4), "edge loss per cut edge on the tapered plate"),
    "bias_error": ("m", (-150e-6, 150e-6), "coupler lengthening offset"),
    "stage_backlash": ("m", (0.0, 60e-6), "dead band on stage reversals"),
    "sensor_drift": ("N/sqrt(s) (baseline wander rate)", (0.0, math.inf),
                     "force baseline per run: free offset at the first sample, then linear"),
}
# The drift baseline per run: 0 at the tare, free at the run's first force sample (the baseline wandered during
# the contact search, ~15 s between the tare and the first measured step), then straight to the last sample
# (segments of at most DRIFT_KNOT_S; infinite: one). The former form, one straight line through 0 at the tare,
# cannot follow a baseline that wandered before the data start: in development (seeds 7021-7028) it closed 32-60 %
# of the held-out gap of a realistic random-walk drift (3 of 8 not attributed). Finer segments fit the rows in
# sample better but predict held-out conditions worse (each knot rests on fewer rows): on three development seeds,
# held-out RMS 1.8-2.0 noise units with one segment, 1.6-2.4 with 20 s, 1.3-3.2 with 10 s, 2.6-10.6 with 5 s.
DRIFT_KNOT_S = math.inf
LIBRARY = tuple(CANDIDATES)
LINEAR_ONLY = ("sensor_drift",)   # fitted in the linear nuisance solve, not by a strength search


# ------------------------------------------------------------------ model-hook candidates
@dataclass(frozen=True)
class LinearFieldD31(Effect):
    """d31 (1 + s |E| / 2 V/um) per plate: `s` is the gain at 2 V/um (hamr_bench.model.FieldDependentD31 with
    its 1 V/um reference rescaled)."""

    name: str = "field_dependent_d31"

    def plate_voltage(self, v_plate_V, actuator):
        return FieldDependentD31(strength=self.strength / 2.0).plate_voltage(v_plate_V, actuator)


@dataclass(frozen=True)
class SeriesBaseSpring(Effect):
    """Series base spring expressed as the blocked-force loss it causes at the tip (strength s in [0, 1))."""

    name: str = "base_compliance"

    def serial_stiffness(self, k_ser_N_per_m, actuator):
        s = min(max(self.strength, 0.0), 0.95)
        return BaseCompliance(strength=s / (1.0 - s)).serial_stiffness(k_ser_N_per_m, actuator)


@dataclass(frozen=True)
class EdgeLoss(Effect):
    """Laser-cut kerf: each cut edge loses the same depth Delta all along the tapered plate, so the mean width drops
    by 2 Delta and the taper ratio w_base / w_mean grows. Strength = 2 Delta / w_nom."""

    name: str = "width_loss"

    def actuator_params(self, params):
        s = min(max(self.strength, -0.4), 0.4)
        loss = s * params.width_nom_m
        w = params.width_nom_m - loss
        base = params.width_ratio * params.width_nom_m - loss
        return act.with_changes(params, width_nom_m=w, width_ratio=base / w)


@dataclass(frozen=True)
class BiasOffset(Effect):
    name: str = "bias_error"

    def design_params(self, design):
        return dataclasses.replace(design, bias_m=design.bias_m + self.strength)


MODEL_HOOKS = {"field_dependent_d31": LinearFieldD31, "base_compliance": SeriesBaseSpring,
               "width_loss": EdgeLoss, "bias_error": BiasOffset}


# ------------------------------------------------------------------ memory / measurement-side operators
def play(x: np.ndarray, half_width: float, y0: float | None = None) -> np.ndarray:
    """Play (backlash) operator: the output follows the input only when pushed beyond +-half_width.

    Vectorised over monotone runs of the input: on a rising run the output is max(y_start, x - w), on a falling
    run min(y_start, x + w); only the runs are looped over."""
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    if x.size == 0:
        return out
    w = abs(half_width)
    y = float(x[0] if y0 is None else y0)
    d = np.sign(np.diff(x))
    # run boundaries where the direction of motion changes (flat pieces join the run before them)
    nz = np.flatnonzero(d)
    starts = [0]
    if nz.size:
        dn = d[nz]
        change = nz[1:][dn[1:] != dn[:-1]]
        starts += list(change)
    starts.append(x.size - 1)
    out[0] = y = min(max(y, x[0] - w), x[0] + w)
    for a, b in zip(starts[:-1], starts[1:]):
        seg = x[a + 1:b + 1]
        if seg.size == 0:
            continue
        if seg[-1] >= x[a]:
            ys = np.maximum(y, seg - w)
        else:
            ys = np.minimum(y, seg + w)
        out[a + 1:b + 1] = ys
        y = float(ys[-1])
    return out


CREEP_T_MIN_S, CREEP_T_MAX_S = 0.01, 100.0


def log_creep(t: np.ndarray, s: np.ndarray, g: float, t_eval: np.ndarray) -> np.ndarray:
    """Log-time law by superposition: each increment ds_k at t_k contributes ds_k (1 - g L(t - t_k)) with
    L(tau) = log10(T_max / (tau + T_min)) for tau < T_max, 0 after: low by g per decade, settling in log time.
    `t` must be a uniform grid; the superposition is one FFT convolution on it, then interpolated at `t_eval`."""
    from scipy.signal import fftconvolve

    s = np.asarray(s, dtype=float)
    if s.size < 2:
        return np.interp(t_eval, t, s)
    dt = float(t[1] - t[0])
    ds = np.r_[0.0, np.diff(s)]
    tau = np.arange(min(s.size, int(CREEP_T_MAX_S / dt) + 1)) * dt
    kernel = np.log10(CREEP_T_MAX_S / (tau + CREEP_T_MIN_S))
    lag = fftconvolve(ds, kernel)[:s.size]
    return np.interp(t_eval, t, s - g * lag)


# ------------------------------------------------------------------ nominal parameters
def base_params(run: Any, fit_params: dict | None = None) -> tuple[ActuatorParams, DesignParams | None]:
    """The nominal actuator and design of a run: the presets the recording names (layers, design, parameter set),
    then a fit's values if given. The recording's `model_params` are NOT used: on the simulated bench they are
    the bench's truth, effects included, and the diagnosis must not see the answer."""
    a = actuator_preset(run.layers, run.params_set)
    d = design_preset(run.design) if run.fixture == "leg" and run.design else None
    if fit_params:
        a, d = _apply_fit(a, d, run, fit_params)
    return a, d


def _value(entry: Any) -> float:
    return float(entry["value"] if isinstance(entry, dict) else entry)


def _apply_fit(a, d, run, fit: dict):
    acts = fit.get("actuators", {}) or {}
    entry = acts.get(str(run.layers)) or acts.get(run.layers)
    if entry:
        names = {"E_p": "pzt_modulus_Pa", "d31": "d31_m_per_V", "t_p": "pzt_thickness_m", "length": "length_m",
                 "width": "width_nom_m"}
        a = dataclasses.replace(a, **{f: _value(entry[k]) for k, f in names.items() if k in entry})
    designs = fit.get("designs", {}) or {}
    entry = designs.get(str(run.design)) or designs.get(run.design) if d is not None else None
    if entry:
        changes: dict[str, Any] = {}
        if "k_ser" in entry:
            changes["k_ser_N_per_m"] = _value(entry["k_ser"])
        if "bias" in entry:
            changes["bias_m"] = _value(entry["bias"])
        kap = list(d.kappa_N_m_per_rad)
        for i in range(3):
            if f"kappa_{i + 1}" in entry:
                kap[i] = _value(entry[f"kappa_{i + 1}"])
        changes["kappa_N_m_per_rad"] = tuple(kap)
        d = dataclasses.replace(d, **changes)
    return a, d


# ------------------------------------------------------------------ the prediction engine
def _zoh(t_cmd: np.ndarray, v_cmd: np.ndarray, t: np.ndarray, before: float = 0.0) -> np.ndarray:
    if t_cmd.size == 0:
        return np.full(t.shape, before)
    i = np.searchsorted(t_cmd, t, "right") - 1
    return np.where(i >= 0, v_cmd[np.clip(i, 0, None)], before)


class RunEngine:
    """Predictions for one run's rows under any set of candidate strengths."""

    def __init__(self, run: Any, fit_params: dict | None = None) -> None:
        self.run = run
        self.rows = run.rows
        self.actuator, self.design = base_params(run, fit_params)
        times, row_of, cyc = [], [], []
        rtimes, rrow, rcyc = [], [], []
        for i, r in enumerate(self.rows):
            times.append(r.eval_times_s)
            row_of.append(np.full(r.eval_times_s.size, i))
            cyc.append(r.eval_cycle)
            if r.ref_times_s is not None:
                rtimes.append(r.ref_times_s)
                rrow.append(np.full(r.ref_times_s.size, i))
                rcyc.append(r.ref_cycle)
        self.t = np.concatenate(times) if times else np.empty(0)
        self.row_of = np.concatenate(row_of) if row_of else np.empty(0, int)
        self.cyc = np.concatenate(cyc) if cyc else np.empty(0, int)
        self.rt = np.concatenate(rtimes) if rtimes else np.empty(0)
        self.rrow = np.concatenate(rrow) if rrow else np.empty(0, int)
        self.rcyc = np.concatenate(rcyc) if rcyc else np.empty(0, int)
        self.is_force_row = np.array([r.quantity == "force_N" for r in self.rows], dtype=bool)
        self.eval_is_force = self.is_force_row[self.row_of] if self.row_of.size else np.empty(0, bool)
        self.n_rows = len(self.rows)
        # dense command grid for memory effects (from the first command to the last time asked)
        tb, vb = run.bias_cmd
        td, vd = run.drive_cmd
        t_all = np.concatenate([self.t, self.rt]) if self.rt.size else self.t
        t_first = min([x[0] for x in (tb, td) if x.size] + [float(t_all.min()) if t_all.size else 0.0])
        t_last = float(t_all.max()) if t_all.size else t_first
        self.dense_t = np.arange(t_first - DENSE_DT_S, t_last + 0.1, DENSE_DT_S)
        self.dense_vb = _zoh(tb, vb, self.dense_t)
        self.dense_vd = _zoh(td, vd, self.dense_t)
        # row means of cycle means: weights per eval time
        self._w = self._weights(self.row_of, self.cyc)
        self._rw = self._weights(self.rrow, self.rcyc) if self.rt.size else None
        self._cache: dict = {}

    def _weights(self, row_of: np.ndarray, cyc: np.ndarray) -> np.ndarray:
        w = np.zeros(row_of.size)
        key = row_of * 1000 + cyc
        uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
        n_cyc = np.zeros(self.n_rows)
        np.add.at(n_cyc, uniq // 1000, 1)
        w = 1.0 / counts[inv] / n_cyc[row_of]
        return w

    def _row_mean(self, values: np.ndarray, row_of: np.ndarray, w: np.ndarray) -> np.ndarray:
        out = np.zeros(self.n_rows)
        np.add.at(out, row_of, np.nan_to_num(values) * w)
        return out

    # --- time-dependent inputs ---------------------------------------------------------------------------
    def drive_at(self, t: np.ndarray, hysteresis: float, creep: float) -> tuple[np.ndarray, np.ndarray]:
        """(V_bias, V_drive) effective at times t after the memory candidates."""
        run = self.run
        vb = _zoh(run.bias_cmd[0], run.bias_cmd[1], t)
        if hysteresis == 0 and creep == 0:
            return vb, _zoh(run.drive_cmd[0], run.drive_cmd[1], t)
        key = ("memory", float(hysteresis))
        cached = self._cache.get(key)
        if cached is None:
            s = 2 * self.dense_vd - self.dense_vb
            if hysteresis != 0:
                s = play(s, abs(hysteresis) * FULL_SCALE_V)
            # the creep term is linear in its strength: keep the unit-strength lag and scale it
            lag = s - log_creep(self.dense_t, s, 1.0, self.dense_t) if creep != 0 else None
            cached = (s, lag)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = cached
        s, lag = cached
        if creep != 0:
            if lag is None:
                lag = s - log_creep(self.dense_t, s, 1.0, self.dense_t)
                self._cache[key] = (s, lag)
            s_t = np.interp(t, self.dense_t, s - creep * lag)
        else:
            s_t = np.interp(t, self.dense_t, s)
        vd = (s_t + vb) / 2.0
        return vb, vd

    def surface_at(self, t: np.ndarray, backlash_m: float) -> np.ndarray:
        """Stage carriage position relative to the contact position, at times t (play on the target sequence)."""
        ts, xs = self.run.stage_cmd
        if ts.size == 0:
            return np.zeros(t.shape)
        x = xs
        # start state: the contact search's last move backed off (away), so the carriage sits half the play in
        if backlash_m != 0:
            x = play(np.r_[xs[0] + backlash_m, xs], backlash_m / 2.0)[1:]
        pos = _zoh(ts, x, t, before=x[0])
        tc = self.run.t_contact_s
        ref = float(_zoh(ts, x, np.array([tc]), before=x[0])[0]) if tc is not None else float(x[0])
        return pos - ref

    # --- the prediction ----------------------------------------------------------------------------------
    def _powertrain(self, effects: list) -> Powertrain:
        key = tuple((type(e).__name__, e.strength) for e in effects)
        p = self._cache.get(key)
        if p is None:
            p = Powertrain(self.actuator, self.design, effects)
            if len(self._cache) > 64:
                self._cache.clear()
            self._cache[key] = p
        return p

    def _values(self, t: np.ndarray, is_force: np.ndarray, strengths: dict[str, float], lag: dict[str, float],
                offset: float, shift_m: float = 0.0) -> np.ndarray:
        """Model quantity at each time (force where `is_force`, displacement elsewhere). `shift_m`: how much further
        in the sensor surface sits than the contact search's reference says (the nonlinear base of the offset)."""
        te = t - np.where(is_force, lag.get("force_N", 0.0), lag.get("displacement_m", 0.0))
        vb, vd = self.drive_at(te, strengths.get("hysteresis", 0.0), strengths.get("creep", 0.0))
        vb, vd = np.clip(vb, -FULL_SCALE_V, FULL_SCALE_V), np.clip(vd, -FULL_SCALE_V, FULL_SCALE_V)
        effects = [MODEL_HOOKS[n](strength=s) for n, s in strengths.items() if n in MODEL_HOOKS and s != 0]
        c = strengths.get("sensor_compliance", 0.0)
        out = np.zeros(t.shape)
        f_m, d_m = is_force, ~is_force
        if self.run.fixture == "actuator":
            a = self.actuator
            for e in effects:
                if type(e).actuator_params is not Effect.actuator_params:
                    a = e.actuator_params(a)
            plates = [e for e in effects if type(e).plate_voltage is not Effect.plate_voltage]
            extra = (lambda v: plates[0].plate_voltage(v, a),) if plates else ()
            if d_m.any():
                out[d_m] = act.free_tip_deflection_m(a, vb[d_m], vd[d_m], *extra)
            if f_m.any():
                q = -(self.surface_at(te[f_m], strengths.get("stage_backlash", 0.0)) + shift_m)
                f = act.tip_force_N(a, vb[f_m], vd[f_m], q, *extra) + offset
                if c:
                    f = f / (1.0 + c * act.stiffness_N_per_m(a))
                out[f_m] = np.maximum(f, 0.0)
            return out
        p = self._powertrain(effects)
        if d_m.any():
            out[d_m] = -p.free_foot_height_m(vb[d_m], vd[d_m])
        if f_m.any():
            h = self.surface_at(te[f_m], strengths.get("stage_backlash", 0.0)) + shift_m + offset
            f = p.foot_force_N(vb[f_m], vd[f_m], h)
            if c:
                dh = 2e-6
                k = (p.foot_force_N(vb[f_m], vd[f_m], h - dh) - p.foot_force_N(vb[f_m], vd[f_m], h + dh)) / (2 * dh)
                f = f / (1.0 + c * np.maximum(np.nan_to_num(k), 0.0))
            out[f_m] = np.maximum(np.nan_to_num(f), 0.0)
        return out

    def predict(self, strengths: dict[str, float], lag: dict[str, float] | None = None,
                offset: float = 0.0, shift_m: float = 0.0) -> np.ndarray:
        """Model value per row (mean of cycle means over the row's sample times, minus the camera reference).
        `offset`: the run's linear nuisance, h0 (leg, m) or f0 (actuator, N); `shift_m`: the run's contact shift
        (`Problem.contact_shift`), the nonlinear base the offset is linearised about."""
        lag = lag or {}
        v = self._values(self.t, self.eval_is_force, strengths, lag, offset, shift_m)
        out = self._row_mean(v, self.row_of, self._w)
        if self._rw is not None:
            r = self._values(self.rt, np.zeros(self.rt.size, bool), strengths, lag, offset, shift_m)
            out -= self._row_mean(r, self.rrow, self._rw)
        return out

    def drift_knots_s(self) -> np.ndarray:
        """Knot times of the sensor_drift baseline: the tare (baseline 0 there), the run's first force sample
        asked, then equal segments of at most DRIFT_KNOT_S to its last (empty when the run has no drift
        candidate)."""
        if self.run.fixture != "leg" or not self.eval_is_force.any():
            return np.empty(0)
        t = self.t[self.eval_is_force]
        t_first, t_last = float(t.min()), float(t.max())
        n = max(1, int(math.ceil((t_last - t_first) / DRIFT_KNOT_S - 1e-9)))
        # equal segments from the first sample to the last (a knot past the data would rest on extrapolation)
        return np.r_[min(self.run.t_tare_s, t_first - 1e-3), np.linspace(t_first, max(t_last, t_first + 1e-3), n + 1)]

    def drift_columns(self) -> np.ndarray:
        """d(row)/d(baseline at each knot after the tare) for a piecewise-linear force baseline (sensor_drift):
        shape (rows, knots - 1); zero on camera rows."""
        knots = self.drift_knots_s()
        if knots.size < 2:
            return np.zeros((self.n_rows, 0))
        cols = []
        for j in range(1, knots.size):
            hat = np.interp(self.t, knots, np.eye(knots.size)[j])
            cols.append(np.where(self.is_force_row, self._row_mean(hat, self.row_of, self._w), 0.0))
        return np.array(cols).T

    def has_offset(self) -> bool:
        return bool(self.is_force_row.any()) and self.run.t_contact_s is not None


def check_names(names: Sequence[str]) -> list[str]:
    out = []
    for n in names:
        n = n.strip()
        if not n:
            continue
        if n not in CANDIDATES:
            raise ConfigError(f"--effects: unknown candidate effect {n!r} (known: {', '.join(CANDIDATES)})")
        out.append(n)
    return out
