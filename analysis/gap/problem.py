"""The joint fit every stage of the diagnosis stands on: observed phase rows with their pure-error noise, the
nominal model with each SPECIMEN's gains under the tolerance prior (a random effect, `tolerances.py`), each
SESSION's contact shift, each sensor chain's lag (with an effect that reads the field, each batch specimen's
plate thickness), and any set of candidate effects (strength and shape parameters, shapes under weak priors),
solved as one bounded nonlinear least-squares problem.

The objective is the sum of squared residuals in noise units, z = (measured - model) / standard error, plus the
prior rows (specimen gains whitened by their tolerance covariance, shapes, the drift spline's smoothness). Every
nuisance is re-fitted with every set of effects: a specimen that is a few % off the presets is absorbed by its
gains at little cost, a shift far beyond the tolerances is not, which is what lets an effect show.

Parameters touch few rows (a specimen's gains its own runs, a session's shift its own runs), so the Jacobian is
sparse; `scipy.optimize.least_squares` groups the finite differences by that sparsity and each run caches its
last predictions, so a column costs the runs it touches."""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from analysis.gap import tolerances as tol
from analysis.gap.engine import EffectValue, Effects, RunEngine, RunNuisance, command_step_s, drift_wander
from analysis.gap.families import FAMILIES
from analysis.gap.features import RAMP_RATE_TOLERANCE, GapData
from analysis.gap.lag_envelope import ENVELOPE_NFEV, FD_STEP, SecantJacobian
from hamr_bench.recording.steps import COMMANDED, INFERRED, LOGGED

# Effects that read the field across a plate: with one of them, the plate thickness of each specimen of a batch is
# fitted (under its tolerance): it sets where its voltage lands on the curve, which a sharp change in field shows
# and the two gains cannot follow.
FIELD_EFFECTS = ("field_dependent_d31",)
PLATE_BOUND = 0.2        # log plate thickness, +-5 tolerance sigmas
LAG_BOUNDS_S = {COMMANDED: (0.0, 0.06), INFERRED: (-0.03, 0.06), LOGGED: (-0.03, 0.06)}
SHIFT_BOUND_M = {"actuator": 60e-6, "leg": 1e-3}
# |log gain| (a factor e): beyond any tolerance, a bound for the solver only. A nominal model so far off that its
# fit stops at it (Table I's reported values) gets the wide bound instead; every other campaign keeps the narrow
# one, since the bounds steer the solver's path (docs/gap.md, Worked example)
GAIN_BOUND = 1.0
WIDE_GAIN_BOUND = 3.0
COVARIANCE_RCOND = 1e-10  # singular values of the Jacobian below this share of the largest: undetermined
NAN_RESIDUAL = 1e3        # a row the model cannot evaluate (beyond the linkage's reach)
RUN_MODEL_CACHE = 64      # predictions kept per run (least recently used dropped): a Jacobian's steps
DRIFT_RIDGE_N = 2e-3      # prior scale of the baseline coefficients (N): a sensor baseline wanders by mN, not by the
#                           blocked force; without it near-collinear spline and warm-up columns trade large opposite
#                           coefficients for phase-dependent offsets


@dataclass(frozen=True)
class Param:
    kind: str           # strength | shape | gain | shift | lag | drift | drift_tau
    key: tuple
    lo: float
    hi: float
    scale: float
    start: float


@dataclass
class Layout:
    """The parameter vector of one set of effects: names -> positions, bounds, the Jacobian's sparsity."""

    names: tuple[str, ...]
    params: list[Param]
    index: dict[tuple, int]
    n_rows: int
    n_prior: int
    sparsity: object = None
    plan: _ResidualPlan | None = field(default=None, repr=False, compare=False)   # index arrays (`Problem._plan`)

    def vector(self, values: dict[tuple, float] | None = None) -> np.ndarray:
        values = values or {}
        x = np.array([values.get((p.kind,) + p.key, p.start) for p in self.params], float)
        lo, hi = self.bounds()
        return np.clip(x, lo, hi)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return (np.array([p.lo for p in self.params]), np.array([p.hi for p in self.params]))

    def values(self, x: np.ndarray) -> dict[tuple, float]:
        return {(p.kind,) + p.key: float(v) for p, v in zip(self.params, x, strict=True)}

    def scales(self) -> np.ndarray:
        """Each parameter's natural size (the solver's x_scale). A pseudo-inverse of the Jacobian is taken on its
        columns times these: in the parameters' own units a contact shift's column (per metre) is ~10^10 times
        a gain's, and a relative cut of singular values would keep or drop directions by the units they are
        written in."""
        return np.array([p.scale for p in self.params])


@dataclass(frozen=True)
class _ResidualPlan:
    """A layout's prior rows and drift baselines as index arrays into its parameter vector (`Problem._plan`)."""

    gains: list[tuple[np.ndarray, int, int]]   # each specimen group's whitening and its two gains
    point: np.ndarray                          # shape and plate parameters, in parameter order
    point_centre: np.ndarray
    point_scale: np.ndarray
    smooth: list[tuple[np.ndarray, float]]     # each baseline's smoothed coefficients and their second-difference sd
    ridge: np.ndarray                          # every drift coefficient
    drift: list[np.ndarray]                    # each baseline's coefficients


@dataclass
class Fit:
    """A solved set of effects: its parameters, objective, the Jacobian at the optimum (rows + prior rows)."""

    names: tuple[str, ...]
    layout: Layout
    x: np.ndarray
    residual: np.ndarray          # z rows then prior rows
    jac: np.ndarray
    effects: Effects
    drift_strength: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def objective(self) -> float:
        return float(self.residual @ self.residual)

    @property
    def z(self) -> np.ndarray:
        return self.residual[:self.layout.n_rows]

    @property
    def n_gain_prior_rows(self) -> int:
        """The prior rows of the specimens' gains come first after the data rows, two per specimen group."""
        return sum(1 for q in self.layout.params if q.kind == "gain")

    @property
    def chi2_rows(self) -> float:
        z = self.z
        return float(z @ z)

    def value(self, kind: str, *key: object) -> float:
        return float(self.x[self.layout.index[(kind,) + tuple(key)]])

    def values(self) -> dict[tuple, float]:
        return self.layout.values(self.x)

    def covariance(self) -> np.ndarray:
        """(J^T J)^+ (unit noise), from the singular values of J itself. Forming J^T J squares J's condition
        number, and a direction only the tolerance prior pins (a fabrication shift against the specimens' gains,
        whose data columns are 10^4 times larger) then fell below the pseudo-inverse's cut: its variance came
        out 0 and a shift's interval 0.1 % wide. Taken on the columns in the parameters' scaled units
        (`Layout.scales`); directions below 1e-10 of the largest singular value there are dropped (rounding). A
        direction the data barely see is kept, with the large variance it has: the held-out steps drop those too
        (`heldout.determined`), since a step along one is noise, but a variance along one is the honest answer."""
        if "covariance" not in self.extra:
            scale = self.layout.scales()
            _, sv, vt = np.linalg.svd(self.jac * scale, full_matrices=False)
            keep = sv > COVARIANCE_RCOND * (sv[0] if sv.size else 0.0)
            cov = (vt[keep].T / sv[keep] ** 2) @ vt[keep]
            self.extra["covariance"] = cov * scale[:, None] * scale[None, :]
        return self.extra["covariance"]


class Problem:
    def __init__(self, data: GapData, fit_params: dict | None = None) -> None:
        self.data = data
        self.gain_bound = GAIN_BOUND
        self.engines = [RunEngine(run, fit_params) for run in data.runs]
        self.rows = data.rows
        self.y = np.array([r.value for r in self.rows])
        self.run_of = np.array([r.run for r in self.rows])
        self.sigma = self._noise()
        self.slices: list[slice] = []
        start = 0
        for e in self.engines:
            self.slices.append(slice(start, start + e.n_rows))
            start += e.n_rows
        self.pure_dof = int(sum(max(r.n - 1, 0) for r in self.rows))
        self.groups = sorted({self.group_of(e) for e in self.engines})
        self.sessions = sorted({self.session_of(e) for e in self.engines if e.has_contact()})
        self.chains = sorted({self.chain_of(e, q) for e in self.engines for q in self._quantities(e)})
        # per sensor chain, the longest drive update interval among its runs (`_lag_secants`)
        self.lag_resolution_s: dict[tuple[str, str, str], float] = {}
        for e in self.engines:
            step = command_step_s(e.run.drive_cmd[0])
            for q in self._quantities(e):
                c = self.chain_of(e, q)
                self.lag_resolution_s[c] = max(self.lag_resolution_s.get(c, 0.0), step)
        # per specimen group: maps its two log gains (stroke, stiffness) to independent unit-variance scores
        # under the tolerance prior
        # a run of each specimen group: its actuator (the group's presets) and layer count
        self.group_engine = {g: next(e for e in self.engines if self.group_of(e) == g) for g in self.groups}
        self.gain_whitening = {g: tol.whitening(e.actuator) for g, e in self.group_engine.items()}
        # specimens of one actuator type (layer count) share a batch: a fabrication shift moves them together
        self.group_type = {g: e.run.layers for g, e in self.group_engine.items()}
        # specimens whose plate thickness is fitted with a field-dependent effect: those of a batch (a layer count
        # with two or more specimens), where plates cut from one sheet still differ by its thickness scatter; a
        # lone specimen keeps the nominal plates (its offset trades with the knee, and each plate parameter costs
        # the Jacobian a pass through every drive)
        self.plate_groups = [g for g in self.groups
                             if sum(t == self.group_type[g] for t in self.group_type.values()) >= 2]
        self._cache: list[OrderedDict] = [OrderedDict() for _ in self.engines]
        self._drift_basis: dict[tuple[int, float], list[tuple[int, np.ndarray]]] = {}
        self.baselines = self._baseline_units()
        self._steps_of_baseline: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.ramp_rates = self._ramp_rates()

    # --- structure -----------------------------------------------------------------------------------------
    def _noise(self) -> np.ndarray:
        """Pure-error standard errors; a row without one gets its run's median (never zero)."""
        # pure error, and where the drive was inferred from a measured monitor, the model's own error from it
        se = np.array([math.hypot(r.se, getattr(r, "drive_se", 0.0)) if np.isfinite(r.se) else r.se
                       for r in self.rows], float)
        for k in np.unique(self.run_of):
            m = self.run_of == k
            good = se[m][np.isfinite(se[m]) & (se[m] > 0)]
            fill = float(np.median(good)) if good.size else float(np.nanmax(np.abs(self.y[m])) * 1e-3 + 1e-12)
            se[m] = np.where(np.isfinite(se[m]) & (se[m] > 0), se[m], fill)
        return se

    @staticmethod
    def group_of(e: RunEngine) -> str:
        """Specimen key of the gains: the actuator's layer count and the specimen label (a leg run shares its
        actuator's gains with the bare-actuator runs of the same label and layers)."""
        return f"layers={e.run.layers}|specimen={getattr(e.run, 'specimen', '')}"

    @staticmethod
    def session_of(e: RunEngine) -> str:
        return getattr(e.run, "session", "") or e.run.path

    @staticmethod
    def chain_of(e: RunEngine, quantity: str) -> tuple[str, str, str]:
        source = (getattr(e.run, "timelines", {}) or {}).get("drive", COMMANDED)
        return (e.run.fixture, quantity, source if source in (INFERRED, LOGGED) else COMMANDED)

    @staticmethod
    def _quantities(e: RunEngine) -> list[str]:
        return sorted({r.quantity for r in e.rows})

    def _ramp_rates(self) -> list[float]:
        """Distinct ramp durations of the driven cycles (s, rounded to 10 %): one rate cannot tell a timing lag
        from rate-independent hysteresis. Per cycle, not per step: an imported step can hold repetitions driven
        at both rates, and its mean ramp is neither."""
        out: list[float] = []
        for e in self.engines:
            for timing in (getattr(e.run, "step_timing", {}) or {}).values():
                cycles = getattr(timing, "cycles", None) or [timing]
                for c in cycles:
                    r = float(getattr(c, "ramp_up_s", 0.0) or 0.0)
                    if r > 0 and not any(abs(r - x) <= RAMP_RATE_TOLERANCE * x for x in out):
                        out.append(r)
        return sorted(out)

    def _baseline_units(self) -> list[tuple[int, ...]]:
        """The runs that share one force baseline: those evaluated on one specimen's shared clock
        (`history.share_specimen_history`: a sensor drifts on between the files of one mounting, and its level in
        each file is one sample of one curve), every other run on its own. Runs without force rows have none."""
        shared: dict[str, list[int]] = {}
        out: list[tuple[int, ...]] = []
        for k, e in enumerate(self.engines):
            if e.force_span_s() is None:
                continue
            label = getattr(e.run, "drive_history", "own")
            if label == "own":
                out.append((k,))
            else:
                shared.setdefault(label, []).append(k)
        return sorted(out + [tuple(v) for v in shared.values()])

    def baseline_span_s(self, u: int) -> tuple[float, float]:
        """First and last force sample of baseline u's runs, on their shared clock."""
        spans = [s for s in (self.engines[k].force_span_s() for k in self.baselines[u]) if s is not None]
        return min(a for a, _ in spans), max(b for _, b in spans)

    # --- layout ----------------------------------------------------------------------------------------------
    def layout(self, names: tuple[str, ...] | list[str]) -> Layout:
        names = tuple(names)
        params = self.params_of(names)
        index = {(p.kind,) + p.key: i for i, p in enumerate(params)}
        n_prior = self._n_prior(names, params)
        lay = Layout(names, params, index, self.y.size, n_prior)
        lay.sparsity = self._sparsity(lay)
        return lay

    def params_of(self, names: tuple[str, ...]) -> list[Param]:
        """The parameters of a model naming `names`: each effect's strength and shapes, every nuisance, and what an
        effect brings with it (the plates' thickness with a field-dependent one, the drift's coefficients)."""
        params: list[Param] = []
        for n in names:
            f = FAMILIES[n]
            if f.kind != "baseline":
                lo, hi = f.bounds
                params.append(Param("strength", (n,), lo, hi, f.scale, min(max(0.0, lo), hi)))
            for s_name, shape in f.shapes.items():
                params.append(Param("shape", (n, s_name), shape.lo, shape.hi, max(shape.prior_sd, 1e-3),
                                    shape.default))
        params += self._nuisance_params()
        if any(n in FIELD_EFFECTS for n in names):
            params += [Param("plate", (g,), -PLATE_BOUND, PLATE_BOUND, 0.02, 0.0) for g in self.plate_groups]
        if "sensor_drift" in names:
            for u in range(len(self.baselines)):
                for j in range(self._n_drift_columns(u)):
                    params.append(Param("drift", (u, j), -1.0, 1.0, 1e-3, 0.0))
        return params

    def _nuisance_params(self) -> list[Param]:
        """What every model carries whatever effects it names: per specimen group its two log gains, per session
        its contact shift, per sensor chain its lag."""
        gb = self.gain_bound
        params = [Param("gain", (g, j), -gb, gb, 0.05, 0.0) for g in self.groups for j in (0, 1)]
        for s in self.sessions:
            fixture = next(e.run.fixture for e in self.engines if self.session_of(e) == s)
            b = SHIFT_BOUND_M[fixture]
            params.append(Param("shift", (s,), -b, b, b / 10, 0.0))
        for c in self.chains:
            lo, hi = LAG_BOUNDS_S[c[2]]
            params.append(Param("lag", c, lo, hi, 5e-3, 0.0))
        return params

    def _n_prior(self, names: tuple[str, ...], params: list[Param]) -> int:
        n = 2 * len(self.groups) + sum(1 for p in params if p.kind in ("shape", "plate"))
        n += sum(self._smooth_rows(u) for u in range(len(self.baselines))) if "sensor_drift" in names else 0
        n += sum(1 for p in params if p.kind == "drift")
        return n

    def _runs_where(self, pred) -> np.ndarray:
        m = np.zeros(self.y.size, bool)
        for k, e in enumerate(self.engines):
            if pred(e):
                m[self.slices[k]] = True
        return m

    def _sparsity(self, lay: Layout) -> object:
        n_res = lay.n_rows + lay.n_prior
        row_idx: list[np.ndarray] = []
        col_idx: list[np.ndarray] = []
        prior_of = self.prior_rows(lay)
        everything = np.ones(self.y.size, bool)
        force_rows = np.array([r.quantity == "force_N" for r in self.rows])
        for i, p in enumerate(lay.params):
            if p.kind in ("strength", "shape"):
                rows = force_rows if p.key[0] == "sensor_drift" else everything
            elif p.kind in ("gain", "plate"):
                rows = self._runs_where(lambda e, g=p.key[0]: self.group_of(e) == g)
            elif p.kind == "shift":
                rows = self._runs_where(lambda e, s_=p.key[0]: e.has_contact() and self.session_of(e) == s_)
            elif p.kind == "lag":
                rows = np.array([self.chain_of(self.engines[r.run], r.quantity) == p.key for r in self.rows])
            else:   # drift coefficient of baseline u: its runs' rows
                rows = np.zeros(self.y.size, bool)
                for k in self.baselines[p.key[0]]:
                    rows[self.slices[k]] = True
            hit = np.r_[np.flatnonzero(rows), lay.n_rows + np.asarray(prior_of.get(i, []), dtype=int)]
            row_idx.append(hit)
            col_idx.append(np.full(hit.size, i))
        r, c = np.concatenate(row_idx), np.concatenate(col_idx)
        return coo_matrix((np.ones(r.size, dtype=int), (r, c)), shape=(n_res, len(lay.params))).tocsr()

    def prior_rows(self, lay: Layout) -> dict[int, list[int]]:
        """Parameter index -> the prior rows it enters (offsets after the data rows), in `_prior` order."""
        out: dict[int, list[int]] = {}
        j = 0
        for g in self.groups:
            for comp in (0, 1):
                out.setdefault(lay.index[("gain", g, comp)], []).extend([j, j + 1])
            j += 2
        for i, p in enumerate(lay.params):
            if p.kind in ("shape", "plate"):
                out.setdefault(i, []).append(j)
                j += 1
        if "sensor_drift" in lay.names:
            self._drift_prior_rows(lay, out, j)
        return out

    def _drift_prior_rows(self, lay: Layout, out: dict[int, list[int]], j: int) -> None:
        """The drift baselines' smoothness rows (per baseline), then one ridge row per drift coefficient."""
        for u in range(len(self.baselines)):
            cols = [i for i, p in enumerate(lay.params) if p.kind == "drift" and p.key[0] == u]
            n_s = self._smooth_rows(u)
            for r in range(n_s):
                for c in cols[:-1]:
                    out.setdefault(c, []).append(j + r)
            j += n_s
        for i, p in enumerate(lay.params):
            if p.kind == "drift":
                out.setdefault(i, []).append(j)
                j += 1

    # --- drift baseline --------------------------------------------------------------------------------------
    def drift_columns(self, u: int, log10_tau: float) -> list[tuple[int, np.ndarray]]:
        """Baseline u's columns on each of its runs: (run index, rows x columns)."""
        # computed at the rounded time constant it is kept under, so that a basis is a function of its key alone:
        # computed at whichever value first rounded there, a fit's last digits would depend on the fits a process
        # had made before it (and a pool's on which worker ran it)
        tau = round(float(log10_tau), 6)
        key = (u, tau)
        b = self._drift_basis.get(key)
        if b is None:
            if len(self._drift_basis) > 4 * len(self.baselines):
                self._drift_basis.clear()
            span = self.baseline_span_s(u) if len(self.baselines[u]) > 1 else None
            b = self._drift_basis[key] = [(k, self.engines[k].drift_basis(tau, span)) for k in self.baselines[u]]
        return b

    def _n_drift_columns(self, u: int) -> int:
        return self.drift_columns(u, FAMILIES["sensor_drift"].shapes["warmup_log10_tau_s"].default)[0][1].shape[1]

    def _smooth_rows(self, u: int) -> int:
        return max(self._n_drift_columns(u) - 1 - 2, 0)   # second differences of the spline coefficients (the
        #                                                  warm-up column apart)

    def _smooth_sd(self, u: int) -> float:
        s = np.concatenate([self.sigma[self.slices[k]][self.engines[k].is_force_row] for k in self.baselines[u]])
        return 3.0 * float(np.median(s)) if s.size else 1.0

    # --- the residual ----------------------------------------------------------------------------------------
    def effects_of(self, lay: Layout, x: np.ndarray) -> Effects:
        out: Effects = {}
        for n in lay.names:
            shapes = {s: float(x[lay.index[("shape", n, s)]]) for s in FAMILIES[n].shapes}
            strength = float(x[lay.index[("strength", n)]]) if ("strength", n) in lay.index else 0.0
            out[n] = EffectValue(strength, shapes)
        return out

    def nuisance(self, lay: Layout, x: np.ndarray, k: int) -> RunNuisance:
        e = self.engines[k]
        g = self.group_of(e)
        gains = (float(x[lay.index[("gain", g, 0)]]), float(x[lay.index[("gain", g, 1)]]))
        s_key = ("shift", self.session_of(e))
        shift = float(x[lay.index[s_key]]) if e.has_contact() and s_key in lay.index else 0.0
        lag = {q: float(x[lay.index[("lag",) + self.chain_of(e, q)]]) for q in self._quantities(e)}
        plate = float(x[lay.index[("plate", g)]]) if ("plate", g) in lay.index else 0.0
        return RunNuisance(gains, shift, lag, plate)

    def _acts_on(self, k: int, name: str) -> bool:
        """Can effect `name` change run k's prediction? (The drift is added outside the run model; a design
        effect needs a leg; contact and stage effects act through the force rows, except the base spring of a
        leg, which sits in its transmission and so moves a free foot too.)"""
        kind = FAMILIES[name].kind
        e = self.engines[k]
        if kind == "baseline":
            return False
        if kind == "design":
            return e.run.fixture == "leg"
        if kind in ("contact", "stage"):
            return bool(e.is_force_row.any()) or (name == "base_compliance" and e.run.fixture == "leg")
        return True

    def _run_model(self, k: int, effects: Effects, nuis: RunNuisance) -> np.ndarray:
        # keyed on what this run's prediction depends on only, so a finite-difference step in another run's
        # parameter (or an effect that cannot act on this run) reuses it
        key = (tuple(sorted((n, v.strength, tuple(sorted(v.shapes.items()))) for n, v in effects.items()
                            if self._acts_on(k, n))),
               nuis.gains, nuis.shift_m, tuple(sorted(nuis.lag_s.items())), nuis.log_plate_thickness)
        cache = self._cache[k]
        v = cache.get(key)
        if v is not None:
            cache.move_to_end(key)
            return v
        acting = {n: e for n, e in effects.items() if self._acts_on(k, n)}
        v = cache[key] = self.engines[k].safe_predict(acting, nuis)
        while len(cache) > RUN_MODEL_CACHE:
            cache.popitem(last=False)
        return v

    def model(self, lay: Layout, x: np.ndarray) -> np.ndarray:
        effects = self.effects_of(lay, x)
        out = np.empty(self.y.size)
        for k in range(len(self.engines)):
            out[self.slices[k]] = self._run_model(k, effects, self.nuisance(lay, x, k))
        if "sensor_drift" in lay.names:
            out += self.drift_rows(lay, x)
        return out

    def drift_rows(self, lay: Layout, x: np.ndarray) -> np.ndarray:
        """Per row, what the fitted force baselines add (0 on camera rows and without the drift)."""
        out = np.zeros(self.y.size)
        if "sensor_drift" not in lay.names:
            return out
        tau = float(x[lay.index[("shape", "sensor_drift", "warmup_log10_tau_s")]])
        for u, idx in enumerate(self._plan(lay).drift):
            runs = self.drift_columns(u, tau)
            coef = x[idx[:runs[0][1].shape[1]]]
            for k, cols in runs:
                out[self.slices[k]] += cols @ coef
        return out

    def drift_excursion_N(self, lay: Layout, x: np.ndarray) -> float:
        """The largest span of one fitted baseline over its force rows (N): how far the baseline moved."""
        d = self.drift_rows(lay, x)
        spans = [float(np.ptp(np.concatenate([d[self.slices[k]][self.engines[k].is_force_row] for k in b])))
                 for b in self.baselines]
        return max(spans, default=0.0)

    def residual(self, lay: Layout, x: np.ndarray) -> np.ndarray:
        m = self.model(lay, x)
        with np.errstate(invalid="ignore"):
            z = (self.y - m) / self.sigma
        z = np.where(np.isfinite(z), z, NAN_RESIDUAL)
        return np.r_[z, self._prior(lay, x)]

    def _prior(self, lay: Layout, x: np.ndarray) -> np.ndarray:
        plan = self._plan(lay)
        out = [w @ np.array([x[i], x[j]]) for w, i, j in plan.gains]
        out.append((x[plan.point] - plan.point_centre) / plan.point_scale)
        out += [np.diff(x[idx], 2) / sd for idx, sd in plan.smooth]
        out.append(x[plan.ridge] / DRIFT_RIDGE_N)
        return np.concatenate(out)

    def _plan(self, lay: Layout) -> _ResidualPlan:
        """Where in a layout's parameter vector each prior row and drift baseline reads, found once per layout: the
        residual is evaluated hundreds of times per fit, with hundreds of drift coefficients."""
        if lay.plan is None:
            gains = [(self.gain_whitening[g], lay.index[("gain", g, 0)], lay.index[("gain", g, 1)])
                     for g in self.groups]
            point = [i for i, q in enumerate(lay.params) if q.kind in ("shape", "plate")]
            centre = [FAMILIES[q.key[0]].shapes[q.key[1]].default if q.kind == "shape" else 0.0
                      for q in (lay.params[i] for i in point)]
            scale = [q.scale if q.kind == "shape" else tol.TOLERANCE["pzt_thickness"]
                     for q in (lay.params[i] for i in point)]
            drift = "sensor_drift" in lay.names
            columns = [np.array([lay.index[("drift", u, j)] for j in range(self._n_drift_columns(u))], int)
                       for u in range(len(self.baselines))] if drift else []
            smooth = [(columns[u][:n_s + 2], self._smooth_sd(u)) for u in range(len(columns))
                      if (n_s := self._smooth_rows(u))]
            ridge = [i for i, q in enumerate(lay.params) if q.kind == "drift"] if drift else []
            lay.plan = _ResidualPlan(gains, np.array(point, int), np.array(centre, float), np.array(scale, float),
                                     smooth, np.array(ridge, int), columns)
        return lay.plan

    # --- solving -----------------------------------------------------------------------------------------------
    def solve(self, names: tuple[str, ...] | list[str], start: dict[tuple, float] | None = None,
              max_nfev: int = 60, free_lags: bool = False) -> Fit:
        """Fit the effects `names` with every nuisance; `start` holds parameter values to start from (any
        subset; others from their defaults). `free_lags`: the start's lags were fitted without an effect that
        delays the response on the ramps (a drive effect added to a fit), and are first moved along their
        envelope (`lag_envelope`)."""
        lay = self.layout(names)
        lo, hi = lay.bounds()
        scale = np.array([p.scale for p in lay.params])
        # the solver's finite-difference step is relative to each value: a start a hair off 0 (a grid's midpoint
        # comes out at ~1e-21) gets a step far below the model's resolution, a zero Jacobian column, and the
        # parameter never moves; at exactly 0 the step is absolute
        x0 = lay.vector(start)
        x0 = np.where(np.abs(x0) < 1e-9 * scale, 0.0, x0)
        lags = self._lag_columns(lay) if free_lags else {}
        if lags:
            # a few evaluations with the lags' columns the secants, then the ordinary solve from there
            jac = SecantJacobian(lay.sparsity, lags, lo, hi)
            fun = lambda x: self.residual(lay, x)  # noqa: E731
            x0 = least_squares(fun, x0, jac=lambda x: jac(fun, x), bounds=(lo, hi), x_scale=scale, method="trf",
                               max_nfev=ENVELOPE_NFEV, ftol=1e-6, xtol=1e-6).x
        return self._least_squares(lay, x0, max_nfev)

    def _least_squares(self, lay: Layout, x0: np.ndarray, max_nfev: int) -> Fit:
        """One bounded trust-region solve from x0, the Jacobian by differences grouped by the sparsity."""
        lo, hi = lay.bounds()
        scale = np.array([p.scale for p in lay.params])
        r = least_squares(lambda x: self.residual(lay, x), x0, bounds=(lo, hi), x_scale=scale,
                          jac_sparsity=lay.sparsity, method="trf", max_nfev=max_nfev, diff_step=FD_STEP,
                          ftol=1e-6, xtol=1e-6)
        fit = self._fit(lay, r.x, r.fun, r.jac)
        fit.extra["converged"] = bool(r.status > 0)    # a tolerance met, not stopped by max_nfev
        fit.extra["nfev"] = int(r.nfev)
        return fit

    def _fit(self, lay: Layout, x: np.ndarray, res: np.ndarray, jac: object) -> Fit:
        j = self._lag_secants(lay, x, jac.toarray() if hasattr(jac, "toarray") else np.array(jac, float))
        effects = self.effects_of(lay, x)
        fit = Fit(tuple(lay.names), lay, np.asarray(x, float), np.asarray(res, float), j, effects)
        if "sensor_drift" in lay.names:
            fit.drift_strength = self.drift_strength(lay, x)
            effects["sensor_drift"] = EffectValue(fit.drift_strength, effects["sensor_drift"].shapes)
        return fit

    def _lag_columns(self, lay: Layout) -> dict[int, float]:
        """Each sensor chain's lag: its parameter index -> the chain's drive update interval (s)."""
        out = {}
        for chain, width in self.lag_resolution_s.items():
            i = lay.index.get(("lag",) + chain)
            if i is not None and width > 0.0:
                out[i] = width
        return out

    def _lag_secants(self, lay: Layout, x: np.ndarray, j: np.ndarray) -> np.ndarray:
        """The Jacobian with each sensor chain's lag column taken as the secant over one drive update interval
        centred on the fit (clipped to the bounds). Samples taken in step with a staircase drive read it the
        same way until a lag carries them across its next update: the rows are a staircase in the lag, flat
        then steep within each interval, and a finite difference much finer than it reads either 0 or a slope
        many times the envelope's. The held-out steps extrapolate along this column and the covariance reads
        it, so a steep entry lets a linearised refit move the lag far and predict a left-out condition far off,
        and takes the lag as resolved below the interval the data can place it to. The secant over one
        interval is the envelope's slope wherever in the interval the lag sits (docs/gap.md, Method)."""
        lags = self._lag_columns(lay)
        if lags:
            lo, hi = lay.bounds()
            for i, rows, values in SecantJacobian(lay.sparsity, lags, lo, hi).lag_columns(
                    lambda v: self.residual(lay, v), x):
                j[:, i] = 0.0
                j[rows, i] = values
        return j

    def drift_strength(self, lay: Layout, x: np.ndarray) -> float:
        """Wander rate of the fitted force baselines, N/sqrt(s), a random walk's rate: sqrt(sum of squared changes
        / time spanned) over every baseline. A run on its own clock: its spline's changes between points 4 s
        apart. Runs on a shared clock: the changes between its consecutive step levels, where the data see the
        curve (between them only the smoothness prior shapes it)."""
        tau = float(x[lay.index[("shape", "sensor_drift", "warmup_log10_tau_s")]])
        rows = None
        ss, n = 0.0, 0.0
        for u, runs in enumerate(self.baselines):
            if len(runs) > 1:
                rows = self.drift_rows(lay, x) if rows is None else rows
                t, where = self._step_points(u)
                levels = rows[where]
                a, b = float(np.sum(np.diff(levels) ** 2)), float(t[-1] - t[0]) if t.size else 0.0
            else:
                cols = [i for i, q in enumerate(lay.params) if q.kind == "drift" and q.key[0] == u]
                a, b = drift_wander(x[cols], tau, self.baseline_span_s(u))
            ss, n = ss + a, n + b
        return math.sqrt(ss / n) if n else 0.0

    def _step_points(self, u: int) -> tuple[np.ndarray, np.ndarray]:
        """Shared baseline u's steps in time order: each step's mean sample time on the shared clock, and one of
        its force rows (global index: every force row of a step holds the step's level)."""
        if u not in self._steps_of_baseline:
            pts = []
            for k in self.baselines[u]:
                e = self.engines[k]
                for idx in e.force_steps:
                    t = float(np.mean(np.concatenate([e.rows[i].eval_times_s for i in idx]))) - e.run.clock_offset_s
                    pts.append((t, self.slices[k].start + idx[0]))
            pts.sort()
            self._steps_of_baseline[u] = (np.array([a for a, _ in pts]), np.array([b for _, b in pts], int))
        return self._steps_of_baseline[u]

    def initial_nuisances(self) -> dict[tuple, float]:
        """Starting values of the contact shifts and lags on the nominal model, by a grid per session and per
        chain (a push-only sensor's clip makes the shift's landscape flat far from its optimum)."""
        lay = self.layout(())
        x = lay.vector()
        for _ in range(2):
            for s in self.sessions:
                i = lay.index[("shift", s)]
                x[i] = self._grid(lay, x, i, self._runs_where(lambda e, s_=s: e.has_contact()
                                                             and self.session_of(e) == s_))
            for c in self.chains:
                i = lay.index[("lag",) + c]
                x[i] = self._grid(lay, x, i, np.array([self.chain_of(self.engines[r.run], r.quantity) == c
                                                       for r in self.rows]))
        return lay.values(x)

    def _grid(self, lay: Layout, x: np.ndarray, i: int, rows: np.ndarray, n: int = 25) -> float:
        p = lay.params[i]
        best, best_v = math.inf, float(x[i])
        for v in np.linspace(p.lo, p.hi, n):
            x[i] = v
            z = self.residual(lay, x)[:self.y.size][rows]
            c = float(z @ z)
            if c < best:
                best, best_v = c, float(v)
        step = (p.hi - p.lo) / (n - 1)
        for v in np.linspace(best_v - step, best_v + step, 9):
            x[i] = min(max(v, p.lo), p.hi)
            z = self.residual(lay, x)[:self.y.size][rows]
            c = float(z @ z)
            if c < best:
                best, best_v = c, float(x[i])
        x[i] = best_v
        return best_v
