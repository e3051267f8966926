"""Predictions of one run's phase rows (`features.RunTrace`) from the nominal model, a specimen's gains, the
session's nuisances and any set of candidate effects (`families.py`), evaluated on exactly the drive the run
had (its commanded or inferred timelines).

The drive path, on a uniform grid of DENSE_DT_S:

    plate voltages V_drive, V_bias - V_drive -> each plate's hysteresis -> x its d31(E) gain -> net drive -> creep

(hysteresis and the gain once per drive segment, the stretch of grid cells over which every plate's voltage holds;
creep on the grid itself), read at the sensor's sample times (minus the sensor chain's lag) as the drive was played:
the command's staircase itself (`timebase.Staircase`, averaged over the amplifier's settling, or over one step ahead
for an inferred drive), plus what the drive effects change on the grid. Then the quasi-static model: the bare
actuator's closed form (free stroke (c/k) p; blocked force c p + k x pushing through the series springs, clipped at
0 for a sensor that reads only push) or the powertrain (leg). The force baseline (drift) is added linearly by
`Problem`. Strength 0 of every candidate is the nominal model exactly (the same path, the operators skipped)."""

from __future__ import annotations

import dataclasses
import math
from collections import OrderedDict
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from analysis.gap import operators as op
from analysis.gap import tolerances as tol
from analysis.gap.families import FAMILIES
from analysis.gap.timebase import GridPlaces, Staircase, WindowMean, zoh
from hamr_bench.errors import HamrBenchError
from hamr_bench.model import ActuatorParams, DesignParams, Powertrain, actuator_preset, design_preset
from hamr_bench.model import actuator as act
from hamr_bench.model.effects import Effect
from hamr_bench.model.powertrain import HeldFoot
from hamr_bench.recording.steps import INFERRED, INFERRED_RAMP_DT_S

FULL_SCALE_V = 250.0
# The free foot's height is a smooth function of the half drive alone: tabulated per powertrain and interpolated
# (513 nodes: within 7 nm of the solved height for every design, far below a camera's noise) instead of solving
# the linkage at every sample
FREE_HEIGHT_NODES = 513
FREE_HEIGHT_GRID_V = np.linspace(-FULL_SCALE_V, FULL_SCALE_V, FREE_HEIGHT_NODES)
DENSE_DT_S = 1e-3
MEMO_ARRAYS = 10
REFERENCE_ACTUATOR = actuator_preset(2, "effective")
MEMO_ITEMS = 400
SETTLE_S = 2.5e-4  # a sample reads the staircase averaged over this long before it (the amplifier's settling)
AT_CACHE = 8  # drives at the sample times kept per run (RunEngine._drive_at)


@dataclass(frozen=True)
class EffectValue:
    """One active candidate: its strength and shape parameters (defaults where not given)."""

    strength: float
    shapes: dict[str, float] = field(default_factory=dict)

    def shape(self, name: str, family_name: str) -> float:
        return float(self.shapes.get(name, FAMILIES[family_name].shapes[name].default))


Effects = dict[str, EffectValue]


@dataclass(frozen=True)
class RunNuisance:
    """What one run's prediction needs besides the effects: its specimen gains (log d31, log width), its
    session's contact shift (m; how much further in the sensor surface sits than the run's zero says), the
    lag of each sensor chain (s) and, where a field-dependent effect is fitted, its plates' log thickness (the
    gains absorb what thickness does to stroke and stiffness, not where along the field a voltage lands)."""

    gains: tuple[float, float] = (0.0, 0.0)
    shift_m: float = 0.0
    lag_s: dict[str, float] = field(default_factory=dict)
    log_plate_thickness: float = 0.0   # the specimen's plates against the nominal: the field a voltage makes


def _keep(cache: dict, key: Any, value: Any) -> None:
    """Add to a small least-recently-used cache of AT_CACHE entries (`_recall` marks a hit as used)."""
    if len(cache) >= AT_CACHE:
        cache.pop(next(iter(cache)))
    cache[key] = value


def _recall(cache: dict, key: Any) -> Any:
    """A `_keep` cache's entry (None if absent), moved to the back: a Jacobian comes back to the unperturbed
    point's entry between its columns, and first-in-first-out would drop it while it is still in use."""
    value = cache.pop(key, None)
    if value is not None:
        cache[key] = value
    return value


@dataclass(frozen=True)
class _PlateDrive:
    """One plate's drive (full scale 1) at the dense grid's samples where it changes: split at 0 V (`above` =
    max(x, 0), `below` = x - above), its play memory there, and per drive segment the change it holds
    (`change_of_segment`)."""

    above: np.ndarray
    below: np.ndarray
    memory: np.ndarray
    change_of_segment: np.ndarray


@dataclass(frozen=True)
class _DriveSegments:
    """The dense grid cut where any plate's voltage (or the bias) changes: a staircase repeats itself in ~3 of 4
    cells, and hysteresis and the d31 gain, functions of the plates' voltages and memories, then hold too, so they
    are evaluated once per segment. `start`: each segment's first dense sample; `of`: per dense sample, its
    segment."""

    start: np.ndarray
    of: np.ndarray


def _creeps(effects: Effects) -> bool:
    cr = effects.get("creep")
    return cr is not None and cr.strength != 0


def base_params(run: Any, fit_params: dict | None = None) -> tuple[ActuatorParams, DesignParams | None]:
    """The nominal actuator and design of a run: the presets the recording names (layers, design, parameter set),
    then a fit's values if given. The recording's `model_params` are NOT used: on the simulated bench they are
    the bench's truth, and the diagnosis must not see the answer."""
    a = actuator_preset(run.layers, run.params_set if run.params_set in ("reported", "effective") else "effective")
    d = design_preset(run.design) if run.fixture == "leg" and run.design else None
    if fit_params:
        a, d = _apply_fit(a, d, run, fit_params)
    return a, d


def _value(entry: Any) -> float:
    return float(entry["value"] if isinstance(entry, dict) else entry)


def _apply_fit(a: ActuatorParams, d: DesignParams | None, run: Any, fit: dict
               ) -> tuple[ActuatorParams, DesignParams | None]:
    acts = fit.get("actuators", {}) or {}
    entry = acts.get(str(run.layers)) or acts.get(run.layers)
    if entry:
        names = {"E_p": "pzt_modulus_Pa", "d31": "d31_m_per_V", "t_p": "pzt_thickness_m", "length": "length_m",
                 "width": "width_nom_m", "t_c": "cf_thickness_m"}
        fitted: dict[str, Any] = {f: _value(entry[k]) for k, f in names.items() if k in entry}
        a = dataclasses.replace(a, **fitted)
    designs = fit.get("designs", {}) or {}
    entry = (designs.get(str(run.design)) or designs.get(run.design)) if d is not None else None
    if entry and d is not None:
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


@dataclass(frozen=True)
class _SerialSpring(Effect):
    """A linear base spring of compliance `strength` (m/N) in series with the leg's transmission."""

    name: str = "base_compliance"

    def serial_stiffness(self, k_ser_N_per_m: float, actuator: ActuatorParams) -> float:
        return 1.0 / (1.0 / k_ser_N_per_m + self.strength)


class RunEngine:
    """Predictions for one run's rows under any effects and nuisances."""

    def __init__(self, run: Any, fit_params: dict | None = None) -> None:
        self.run = run
        self.rows = run.rows
        self.actuator, self.design = base_params(run, fit_params)
        self.n_rows = len(self.rows)
        self.is_force_row = np.array([r.quantity == "force_N" for r in self.rows], dtype=bool)
        self.reads_pull = bool(getattr(run, "force_reads_pull", False))
        t, row_of, cyc, rt, rrow, rcyc = [], [], [], [], [], []
        for i, r in enumerate(self.rows):
            t.append(r.eval_times_s)
            row_of.append(np.full(r.eval_times_s.size, i))
            cyc.append(r.eval_cycle if r.eval_cycle is not None else np.zeros(r.eval_times_s.size, int))
            if r.ref_times_s is not None:
                rt.append(r.ref_times_s)
                rrow.append(np.full(r.ref_times_s.size, i))
                rcyc.append(r.ref_cycle if r.ref_cycle is not None else np.zeros(r.ref_times_s.size, int))
        self.t = np.concatenate(t) if t else np.empty(0)
        self.row_of = np.concatenate(row_of) if row_of else np.empty(0, int)
        cyc_all = np.concatenate(cyc) if cyc else np.empty(0, int)
        self.rt = np.concatenate(rt) if rt else np.empty(0)
        self.rrow = np.concatenate(rrow) if rrow else np.empty(0, int)
        rcyc_all = np.concatenate(rcyc) if rcyc else np.empty(0, int)
        self.eval_is_force = self.is_force_row[self.row_of] if self.row_of.size else np.empty(0, bool)
        self._w = self._weights(self.row_of, cyc_all)
        self._rw = self._weights(self.rrow, rcyc_all) if self.rt.size else None
        tb, _ = run.bias_cmd
        td, _ = run.drive_cmd
        t_all = np.concatenate([self.t, self.rt]) if self.rt.size else self.t
        starts = [float(x[0]) for x in (tb, td) if x.size] + ([float(t_all.min())] if t_all.size else [0.0])
        t_first = min(starts)
        t_last = float(t_all.max()) if t_all.size else t_first
        self.dense_t = np.arange(t_first - DENSE_DT_S, t_last + 0.1, DENSE_DT_S)
        # The drive as played: a staircase at the command's own sample times. The dense grid (for the memory of
        # hysteresis and creep) holds each cell's mean; a sample's drive is read from the staircase itself (a
        # staircase step falls anywhere in a cell, and on a fast ramp a cell is several noise widths of force).
        self._bias = Staircase(*run.bias_cmd)
        self._drive = Staircase(*run.drive_cmd)
        # A sample reads the staircase averaged over [t - settle, t + ahead]. A commanded drive is played as the
        # staircase: the amplifier settles on each step (SETTLE_S). An inferred drive is a smooth ramp written as a
        # staircase of INFERRED_RAMP_DT_S steps, each at the ramp's value at its start: averaged over the step
        # ahead it reads as the ramp again (linear between the steps, no delay).
        inferred = getattr(run, "timelines", {}).get("drive") == INFERRED
        self._settle_s, self._ahead_s = (0.0, INFERRED_RAMP_DT_S) if inferred else (SETTLE_S, 0.0)
        # A camera frame is exposed over an interval around its time, longer than a command step: it sees the
        # played steps averaged, not the step in force at its mid-time as a sampled sensor does. A played
        # staircase is read for a frame over one command step centred on it (the smooth ramp through the
        # steps); an inferred drive is that ramp already.
        self._frame_s = 0.0 if inferred else command_step_s(td)
        # Each dense cell holds the drive's mean over the cell. A commanded staircase is what was played, so its
        # cell means are. An inferred one trails its ramp by half a step: read half a step ahead, as the samples
        # are, or the loops and the gain would run that much behind the drive they correct.
        cell_start = self.dense_t - DENSE_DT_S / 2 + self._ahead_s / 2
        self.dense_vb = self._bias.mean(cell_start, DENSE_DT_S)
        self.dense_vd = self._drive.mean(cell_start, DENSE_DT_S)
        self._dense_net = 2.0 * self.dense_vd - self.dense_vb     # bottom plate - top plate, no effect
        self._cache: OrderedDict[Any, Any] = OrderedDict()
        self._big_keys: list[Any] = []
        self._plate_voltages: np.ndarray | None = None
        self._plate_drive: list[_PlateDrive] | None = None
        self._plate_levels: list[tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        self._at: dict[tuple, np.ndarray] = {}
        self._played: dict[tuple, np.ndarray] = {}
        self._played_net: WindowMean | None = None
        self._played_frames: WindowMean | None = None
        self._places: dict[tuple, GridPlaces] = {}
        self._stage_at: dict[tuple, np.ndarray] = {}
        self._used_levels: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}
        self._held: dict[tuple, HeldFoot] = {}
        self._spline_rows: dict[tuple, np.ndarray] = {}  # drift spline columns' row means, per knots and span

    def _weights(self, row_of: np.ndarray, cyc: np.ndarray) -> np.ndarray:
        """Per sample time, its weight in the row's mean of cycle means."""
        if row_of.size == 0:
            return np.empty(0)
        key = row_of * 10000 + cyc
        uniq, inv, counts = np.unique(key, return_inverse=True, return_counts=True)
        n_cyc = np.zeros(self.n_rows)
        np.add.at(n_cyc, uniq // 10000, 1)
        return 1.0 / counts[inv] / n_cyc[row_of]

    def _row_mean(self, values: np.ndarray, row_of: np.ndarray, w: np.ndarray) -> np.ndarray:
        return np.bincount(row_of, weights=values * w, minlength=self.n_rows)

    def row_means(self, values: np.ndarray) -> np.ndarray:
        """Mean of cycle means per row of any per-sample quantity at `self.t`."""
        return self._row_mean(values, self.row_of, self._w)

    # --- the drive path -----------------------------------------------------------------------------------
    def _memo(self, key: Any, make: Any) -> Any:
        """Least-recently-used memo: arrays on the dense grid (up to MEMO_ARRAYS of them: a native run's grid is
        ~10^5 samples) and small values (parameters, Powertrains) apart."""
        v = self._cache.get(key)
        if v is not None:
            self._cache.move_to_end(key)
            return v
        v = self._cache[key] = make()
        big = isinstance(v, np.ndarray) and v.size > 1000
        if big:
            self._big_keys.append(key)
        while len(self._big_keys) > MEMO_ARRAYS:
            self._cache.pop(self._big_keys.pop(0), None)
        while len(self._cache) > MEMO_ITEMS:
            old, _ = self._cache.popitem(last=False)
            if old in self._big_keys:
                self._big_keys.remove(old)
        return v

    def _plate_gains(self, d31: EffectValue, t_p: float) -> np.ndarray:
        """[G(V_drive), G(V_bias - V_drive)] per drive segment (shape (2, segments)): each plate's d31 relative to
        the nominal one at its voltage."""
        knee = 10.0 ** d31.shape("log10_knee_V_per_um", "field_dependent_d31")
        p = d31.shape("steepness", "field_dependent_d31")
        ref = self.actuator.pzt_thickness_m
        if self._plate_levels is None:
            # a staircase holds few distinct voltages: the gain is computed on those (with their logs, once) and
            # spread back to the segments
            self._plate_levels = []
            for v in self._segment_plates:
                levels, where = np.unique(v, return_inverse=True)
                self._plate_levels.append((levels, op.log_magnitude(levels), where))
        out = np.empty((2, self._segments.start.size))
        for row, (levels, log_v, where) in zip(out, self._plate_levels, strict=True):
            np.take(op.plate_gain(levels, t_p, d31.strength, knee, p, ref, log_v), where, out=row)
        return out

    def _plates(self) -> np.ndarray:
        """Each plate's voltage on the dense grid, [V_drive, V_bias - V_drive] (shape (2, n), read-only)."""
        if self._plate_voltages is None:
            self._plate_voltages = np.stack([self.dense_vd, self.dense_vb - self.dense_vd])
            self._plate_voltages.flags.writeable = False
        return self._plate_voltages

    @cached_property
    def _segments(self) -> _DriveSegments:
        """The dense grid's drive segments (`_DriveSegments`)."""
        v = self._plates()
        changes = np.r_[True, (v[:, 1:] != v[:, :-1]).any(axis=0) | (self.dense_vb[1:] != self.dense_vb[:-1])]
        return _DriveSegments(np.flatnonzero(changes), np.cumsum(changes) - 1)

    @cached_property
    def _segment_plates(self) -> np.ndarray:
        """Each plate's voltage per drive segment (shape (2, segments), read-only)."""
        out = self._plates()[:, self._segments.start]
        out.flags.writeable = False
        return out

    @cached_property
    def _segment_net(self) -> np.ndarray:
        """The net drive as played on the dense grid (no effect), per drive segment."""
        return self._dense_net[self._segments.start]

    def _plate_drives(self) -> list[_PlateDrive]:
        """Each plate's drive on the dense grid, at its changes only, with its play memory there
        (`operators.plate_memory`): it depends on the drive alone, so it is built once per run and kept outside the
        size-limited memo. A play is rate-independent: a sample that repeats the one before it changes nothing, and
        a staircase drive repeats itself in ~3 of 4 samples, which the loops are then not evaluated on."""
        if self._plate_drive is None:
            self._plate_drive = []
            for v in self._plates():
                x = v / FULL_SCALE_V
                changes = np.r_[True, x[1:] != x[:-1]]
                xs = x[changes]
                above = np.maximum(xs, 0.0)
                self._plate_drive.append(_PlateDrive(above, xs - above, op.plate_memory(xs),
                                                     (np.cumsum(changes) - 1)[self._segments.start]))
        return self._plate_drive

    @staticmethod
    def _drive_key(effects: Effects, t_p: float) -> tuple:
        return ("y", t_p) + tuple((n, v.strength, tuple(sorted(v.shapes.items()))) for n, v in sorted(effects.items())
                                  if FAMILIES[n].kind == "drive")

    def _effective(self, effects: Effects, t_p: float) -> np.ndarray:
        """The effective net drive after the drive effects, per drive segment, or on the dense grid where creep
        acts (its response moves within a segment); memoised."""
        return self._memo(self._drive_key(effects, t_p), lambda: self._effective_drive(effects, t_p))

    def effective_drive(self, effects: Effects, t_p: float) -> np.ndarray:
        """The effective net drive on the dense grid after hysteresis, d31(E) and creep (V)."""
        y = self._effective(effects, t_p)
        return y if _creeps(effects) else y[self._segments.of]

    def _drive_at(self, times: str, te: np.ndarray, lags: tuple[float, float], effects: Effects,
                  t_p: float) -> np.ndarray:
        """The effective drive at the lagged sample times `te` of `times` ("t": the rows' samples, "rt": the camera
        reference's): the played staircase itself, plus what the drive effects change, read from the dense grid
        (from its segments where the change is constant on each). Both are kept for the last few keys: a
        Jacobian's columns for gains, contact shifts and drift coefficients leave the lags and the drive alone, and
        those for the drive effects leave the lags alone."""
        key = (times, lags) + self._drive_key(effects, t_p)
        y = _recall(self._at, key)
        if y is None:
            y = self._played_at(times, te, lags)
            if any(FAMILIES[n].kind == "drive" for n in effects):
                dense = _creeps(effects)
                places = _recall(self._places, (times, lags, dense))
                if places is None:
                    places = GridPlaces.of(te, float(self.dense_t[0]), DENSE_DT_S, self.dense_t.size)
                    if not dense:
                        places = places.through(self._segments.of)
                    _keep(self._places, (times, lags, dense), places)
                net = self._dense_net if dense else self._segment_net
                y = y + places.interp(self._effective(effects, t_p) - net)
            _keep(self._at, key, y)
        return y

    def _net_window(self, width_s: float) -> WindowMean:
        """The net drive (2 x drive - bias: bottom plate - top plate) averaged over windows of `width_s`."""
        return WindowMean([(2.0, self._drive), (-1.0, self._bias)], width_s)

    def _played_at(self, times: str, te: np.ndarray, lags: tuple[float, float]) -> np.ndarray:
        """The net drive as played (bottom plate - top plate, no effect) at the lagged sample times (a camera
        frame's over the command step around it)."""
        y = _recall(self._played, (times, lags))
        if y is None:
            if self._played_net is None:
                self._played_net = self._net_window(self._settle_s + self._ahead_s)
            y = self._played_net(te - self._settle_s)
            frames = {"t": ~self.eval_is_force, "rt": np.ones(te.size, bool)}.get(times, np.zeros(te.size, bool))
            if self._frame_s > 0.0 and frames.any():
                if self._played_frames is None:
                    self._played_frames = self._net_window(self._frame_s)
                y[frames] = self._played_frames(te[frames] - self._frame_s / 2)
            _keep(self._played, (times, lags), y)
        return y

    def _plate_loops(self, strength: float, gamma: float, tip: float) -> np.ndarray:
        """Each plate's voltage through its hysteresis per drive segment (shape (2, segments), V)."""
        w = op.plate_weights(strength, gamma, tip)
        out = np.empty((2, self._segments.start.size))
        for row, d in zip(out, self._plate_drives(), strict=True):
            np.take(op.plate_hysteresis_split(d.above, d.below, d.memory, w, tip), d.change_of_segment, out=row)
        out *= FULL_SCALE_V
        return out

    def _effective_drive(self, effects: Effects, t_p: float) -> np.ndarray:
        """Per plate: its voltage, through its hysteresis (the switching thresholds are fields: the plate's own
        voltage, not a d31-scaled one, so a plate's memory is computed once), times its d31(E) gain; the net drive
        bottom - top; then creep. Per drive segment (every plate's voltage holds within one), on the dense grid
        where creep acts."""
        d31 = effects.get("field_dependent_d31")
        hy = effects.get("hysteresis")
        cr = effects.get("creep")
        plates = self._segment_plates
        h_key = None
        if hy is not None and hy.strength != 0:
            gamma = hy.shape("density_exponent", "hysteresis")
            tip = hy.shape("tip_share", "hysteresis")
            loops = (hy.strength, gamma, tip)
            h_key = loops
            # kept apart from the net drive: a Jacobian's d31 and creep columns change the drive, not the loops
            plates = self._memo(("hysteresis",) + loops, lambda: self._plate_loops(*loops))
        d_key = None
        if d31 is not None and d31.strength != 0:
            d_key = (d31.strength, d31.shape("log10_knee_V_per_um", "field_dependent_d31"),
                     d31.shape("steepness", "field_dependent_d31"), t_p)
            plates = plates * self._memo(("gain",) + d_key, lambda: self._plate_gains(d31, t_p))
        y = plates[0] - plates[1]
        if cr is not None and cr.strength != 0:
            n, q, r = (cr.shape(k, "creep") for k in ("exponent", "curvature", "skew"))
            base = y = y[self._segments.of]
            resp = self._memo(("creep", n, q, r, h_key, d_key),
                              lambda: op.creep_response(base, DENSE_DT_S, n, q, r))
            y = y + cr.strength * resp
        return y

    # --- parameters ---------------------------------------------------------------------------------------
    def actuator_for(self, effects: Effects, gains: tuple[float, float]) -> ActuatorParams:
        key = ("a", gains) + tuple((n, v.strength) for n, v in sorted(effects.items()) if FAMILIES[n].kind == "params")
        return self._memo(key, lambda: self._actuator_for(effects, gains))

    def _actuator_for(self, effects: Effects, gains: tuple[float, float]) -> ActuatorParams:
        a = self.actuator
        for name, value in effects.items():
            if FAMILIES[name].kind == "params" and value.strength != 0:
                a = tol.scaled(a, name, value.strength)
        return tol.with_gains(a, gains[0], gains[1])

    def _stage_index_at(self, times_key: tuple, t: np.ndarray) -> np.ndarray:
        """Per (lagged) force sample time of a row set, which of `surface_levels` the carriage holds (0: before
        the first command); kept per (times, lags)."""
        index = _recall(self._stage_at, times_key)
        if index is None:
            ts, _ = self.run.stage_cmd
            index = np.searchsorted(ts, t, "right") if ts.size else np.zeros(t.shape, np.intp)
            _keep(self._stage_at, times_key, index)
        return index

    def _held_levels(self, times_key: tuple, t: np.ndarray, backlash_m: float) -> tuple[np.ndarray, np.ndarray]:
        """The carriage levels the force samples at `t` see (only those: a level the foot never meets, such as the
        start of the contact search, can lie beyond the leg's reach) and, per sample, which of them."""
        used = _recall(self._used_levels, times_key)
        if used is None:
            used = np.unique(self._stage_index_at(times_key, t), return_inverse=True)
            _keep(self._used_levels, times_key, used)
        return self.surface_levels(backlash_m)[used[0]], used[1]

    def surface_levels(self, backlash_m: float) -> np.ndarray:
        """The carriage's positions relative to the run's contact position: before the first command, then after
        each (the stage holds each target until the next: a step's force samples see one of a few levels)."""
        ts, xs = self.run.stage_cmd
        if ts.size == 0:
            return np.zeros(1)
        x = xs
        if backlash_m != 0:
            # the contact search's last move backed off (away), so the carriage sits half the play in
            x = op.play(np.r_[xs[0] + backlash_m, xs], backlash_m / 2.0)[1:]
        tc = self.run.t_contact_s
        ref = float(zoh(ts, x, np.array([tc]), before=x[0])[0]) if tc is not None else float(x[0])
        return np.r_[x[0], x] - ref

    def _springs(self, effects: Effects) -> list[tuple[float, float, float]]:
        """(C, beta, rho) of the active series springs: the sensor's strength is its compliance, the base's the
        blocked-force loss it causes on the reference actuator at 250 V (`base_compliance_m_per_N`)."""
        out = []
        for name in ("base_compliance", "sensor_compliance"):
            e = effects.get(name)
            if e is not None and e.strength != 0:
                beta = e.shape("exponent", name)
                c = base_compliance_m_per_N(e.strength, beta) if name == "base_compliance" else e.strength
                out.append((c, beta, e.shape("pull_ratio", name)))
        return out

    # --- the prediction -----------------------------------------------------------------------------------
    def _values(self, times: str, t: np.ndarray, is_force: np.ndarray, effects: Effects,
                nuis: RunNuisance) -> np.ndarray:
        a = self.actuator_for(effects, nuis.gains)
        lags = (nuis.lag_s.get("force_N", 0.0), nuis.lag_s.get("displacement_m", 0.0))
        te = t - np.where(is_force, *lags)
        y = self._drive_at(times, te, lags, effects, a.pzt_thickness_m * math.exp(nuis.log_plate_thickness))
        backlash = effects.get("stage_backlash")
        b = backlash.strength if backlash is not None else 0.0
        out = np.zeros(t.shape)
        if self.run.fixture == "actuator":
            c, k = self._memo(("ck", a), lambda: (act.force_per_volt(a), act.stiffness_N_per_m(a)))
            d = ~is_force
            out[d] = c / k * y[d]
            if is_force.any():
                surface = self.surface_levels(b)[self._stage_index_at((times, lags), te[is_force])]
                f0 = c * y[is_force] + k * (surface + nuis.shift_m)
                f = op.spring_solve_many(f0, k, self._springs(effects))
                out[is_force] = f if self.reads_pull else np.maximum(f, 0.0)
            return out
        return self._leg_values(a, effects, y, te, is_force, nuis, b, (times, lags))

    def _leg_values(self, a: ActuatorParams, effects: Effects, y: np.ndarray, te: np.ndarray, is_force: np.ndarray,
                    nuis: RunNuisance, backlash_m: float, times_key: tuple) -> np.ndarray:
        d = self.design
        assert d is not None  # a leg run always has its design (RunEngine reads it from the recording)
        bias = effects.get("bias_error")
        if bias is not None and bias.strength != 0:
            d = dataclasses.replace(d, bias_m=d.bias_m + bias.strength)
        base = effects.get("base_compliance")
        extra = [_SerialSpring(strength=base_compliance_m_per_N(base.strength, 1.0))] \
            if base is not None and base.strength != 0 else []
        key = ("pt", a, d, tuple(e.strength for e in extra))
        p: Powertrain = self._memo(key, lambda: Powertrain(a, d, extra))
        out = np.zeros(te.shape)
        half = np.clip(y / 2.0, -FULL_SCALE_V, FULL_SCALE_V)
        zero = np.zeros(te.shape)
        m = ~is_force
        if m.any():
            table = self._memo(("free_height",) + key[1:], lambda: p.free_foot_height_m(
                np.zeros(FREE_HEIGHT_NODES), FREE_HEIGHT_GRID_V))
            out[m] = -np.interp(half[m], FREE_HEIGHT_GRID_V, table)
        if is_force.any():
            levels, index = self._held_levels(times_key, te[is_force], backlash_m)
            levels = levels + nuis.shift_m
            u = p.free_actuator_deflection_m(zero[is_force], half[is_force])
            # the heights change with the lags, the shift and the backlash only: a Jacobian's columns for the gains'
            # stroke and every drive effect reuse the linkage's trigonometry at them; it is solved at the stage's few
            # levels and spread to the samples
            where = (p.held_foot_key, times_key, backlash_m, nuis.shift_m)

            def held(offset_m: float) -> HeldFoot:
                key = where + (offset_m,)
                pose = _recall(self._held, key)
                if pose is None:
                    pose = p.hold_foot(levels + offset_m).take(index)
                    _keep(self._held, key, pose)
                return pose

            f = p.force_on_held_foot(held(0.0), u)
            sensor = effects.get("sensor_compliance")
            if sensor is not None and sensor.strength != 0:
                # the sensor gives way under the force, so the foot sits lower: F = F(h - C F), F(h) / (1 + C dF/dh)
                dh = 2e-6
                kc = (p.force_on_held_foot(held(dh), u) - p.force_on_held_foot(held(-dh), u)) / (2 * dh)
                f = f / (1.0 + sensor.strength * np.maximum(np.nan_to_num(kc), 0.0))
            f = np.nan_to_num(f)
            out[is_force] = f if self.reads_pull else np.maximum(f, 0.0)
        return out

    def predict(self, effects: Effects, nuis: RunNuisance) -> np.ndarray:
        """Model value per row (mean of cycle means over the row's sample times, minus the camera reference).
        Raises HamrBenchError where the effects put the linkage beyond its reach."""
        v = self._values("t", self.t, self.eval_is_force, effects, nuis)
        out = self._row_mean(v, self.row_of, self._w)
        if self._rw is not None:
            r = self._values("rt", self.rt, np.zeros(self.rt.size, bool), effects, nuis)
            out -= self._row_mean(r, self.rrow, self._rw)
        return out

    def safe_predict(self, effects: Effects, nuis: RunNuisance) -> np.ndarray:
        try:
            out = self.predict(effects, nuis)
        except (HamrBenchError, FloatingPointError, ValueError):
            return np.full(self.n_rows, np.nan)
        return out

    # --- the drift baseline (linear) -----------------------------------------------------------------------
    def force_span_s(self) -> tuple[float, float] | None:
        """First and last force sample, on the clock its baseline shares (its own, less `run.clock_offset_s`)."""
        if not self.eval_is_force.any():
            return None
        tf = self.t[self.eval_is_force] - self.run.clock_offset_s
        return float(tf.min()), float(tf.max())

    def drift_basis(self, log10_tau_s: float, span_s: tuple[float, float] | None = None,
                    knot_s: float = 4.0) -> np.ndarray:
        """Columns of this run's force baseline (rows x columns; 0 on camera rows): a cubic B-spline over the
        run's own force samples plus a warm-up from its first one. Empty for a run without force rows.

        With `span_s` (times on a clock several runs share, `force_span_s`), the spline and warm-up span it, so
        the runs' columns are one curve, and each force row takes its step's mean level (`_step_levels`): the
        curve is then seen where it can be told from the drive, as one level per step at that step's time: free
        to differ between a step's phase windows, a baseline fits whatever the drive does in a run's few cycles,
        an effect as well as a drift (docs/gap.md). A run on its own clock keeps that freedom: it is the only way
        its drift shows."""
        own = self.force_span_s()
        if own is None:
            return np.zeros((self.n_rows, 0))
        t0, t1 = span_s or own
        t = self.t - self.run.clock_offset_s
        key = (knot_s, t0, t1)
        spline = self._spline_rows.get(key)
        if spline is None:  # the spline's columns do not depend on the warm-up's time constant, which is fitted
            basis = op.spline_basis(t, t0, t1, drift_knot_s(t0, t1, knot_s))
            spline = self._spline_rows[key] = np.array([self.row_means(c) for c in basis.T]).T
        warm = self.row_means(op.warm_up(t - t0, 10.0 ** log10_tau_s))
        out = np.column_stack([spline, warm])
        out[~self.is_force_row] = 0.0
        return self._step_levels @ out if span_s else out

    @cached_property
    def force_steps(self) -> list[list[int]]:
        """This run's force rows grouped by step (one repetition, direction, mode and ramp rate: phase windows of
        the same cycles), in row order."""
        steps: dict[tuple, list[int]] = {}
        for i, (r, force) in enumerate(zip(self.rows, self.is_force_row, strict=True)):
            if force:
                steps.setdefault((r.step, r.repetition, r.direction, r.mode, r.ramp_s), []).append(i)
        return list(steps.values())

    @cached_property
    def _step_levels(self) -> np.ndarray:
        """Row-averaging matrix: each force row gets the mean over its step's force rows (`force_steps`)."""
        m = np.zeros((self.n_rows, self.n_rows))
        for same in self.force_steps:
            m[np.ix_(same, same)] = 1.0 / len(same)
        return m

    def has_contact(self) -> bool:
        return bool(self.is_force_row.any()) and self.run.t_contact_s is not None


def command_step_s(t_cmd: np.ndarray) -> float:
    """A staircase's step (s): the median spacing of its samples, 0 without two."""
    d = np.diff(t_cmd)
    d = d[d > 0]
    return float(np.median(d)) if d.size else 0.0


def drift_knot_s(t0_s: float, t1_s: float, knot_s: float = 4.0) -> float:
    """Knot spacing of a baseline spline over [t0, t1]: `knot_s`, or an eighth of the span if longer."""
    return max(knot_s, (t1_s - t0_s) / 8.0)


def drift_wander(coefs: np.ndarray, log10_tau_s: float, span_s: tuple[float, float],
                 knot_s: float = 4.0) -> tuple[float, float]:
    """(sum of squared changes of a fitted baseline (`RunEngine.drift_basis` over `span_s`) between points
    `knot_s` apart, the time they span): a random walk of rate q has E[sum] = q^2 x span, so q^2 = sum / span."""
    t0, t1 = span_s
    if coefs.size == 0 or t1 <= t0:
        return 0.0, 0.0
    grid = np.linspace(t0, t1, max(2, int(round((t1 - t0) / knot_s)) + 1))
    spline = op.spline_basis(grid, t0, t1, drift_knot_s(t0, t1, knot_s))
    b = np.column_stack([spline, op.warm_up(grid - t0, 10.0 ** log10_tau_s)]) @ coefs
    return float(np.sum(np.diff(b) ** 2)), t1 - t0


def base_compliance_m_per_N(loss: float, exponent: float) -> float:
    """The base spring's compliance for a strength given as the blocked-force loss it causes on the reference
    actuator (2 layers, Table I effective values) at 250 V: a fixed conversion, so one strength means one spring
    whatever actuator the data holds (a stiffer actuator loses more to the same spring)."""
    a = REFERENCE_ACTUATOR
    return op.compliance_for_loss(loss, act.stiffness_N_per_m(a), float(act.blocked_force_N(a, 250.0)), exponent)


def spring_fraction(k_N_per_m: float, compliance: float) -> float:
    """Blocked-force loss of a linear series spring: 1 - 1 / (1 + C k)."""
    return 1.0 - 1.0 / (1.0 + compliance * k_N_per_m)


__all__ = ["DENSE_DT_S", "FULL_SCALE_V", "EffectValue", "Effects", "RunEngine", "RunNuisance", "base_params",
           "spring_fraction"]
