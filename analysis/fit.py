"""Fitting the model to a Dataset: the actuator's five effective parameters per layer count (paper Table I) and
each design's serial compliance, flexure stiffnesses and actual bias (paper Table III), with 95 % intervals and an
identifiability verdict per parameter (analysis/uncertainty.py).

Weights: residuals are grouped by (run, quantity); each group's sigma is the pooled scatter between repetitions of
the same condition (or, without repetitions, the within-step spread over cycles), then re-estimated from the
residuals (`fit_weighted`); only the RELATIVE weights matter, the overall noise scale is estimated from the fit
(see uncertainty.py). Every run with a contact search has its own zero offset, a nuisance parameter with a prior
(analysis/observations.py); the intervals profile it out.

References (start point, and where a parameter the data cannot constrain is left):
- actuator: Table I "reported" values (the as-built, caliper and data-sheet numbers) for E_p, d31, t_p, length,
  width; the non-fitted fields (carbon-fibre thickness, FR-4, taper, extension, E_c) from the recording's
  parameter set (`design.params_set`, `design.model_params`);
- transmission: k_ser = 1000 N/m, kappa_i = 0 (a zero-stiffness flexure), bias = the DESIGNED bias of the design
  (0 or 200 um, Table II). The geometry is the model's (docs/model.md) and is not fitted.
The transmission fit uses the actuator the leg recordings name (their params_set / model_params) unless
`actuator_source="fit"` and the dataset has actuator recordings of that layer count.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field, fields, replace
from typing import Any
from collections.abc import Iterable

import numpy as np

from analysis.dataset import Dataset, Observation
from analysis.observations import LegObservations, actuator_prediction
from analysis.uncertainty import FitOutcome, ParamSpec, Problem, fit_problem
from hamr_bench.errors import ConfigError, HamrBenchError
from hamr_bench.model import ActuatorParams, DesignParams, Powertrain, actuator_preset, design_preset

METHODS = ("least-squares", "nelder-mead")
LEG_FIT_PROTOCOLS = ("blocked-force", "sag-sweep", "free-displacement")

ACTUATOR_SPECS = (
    ParamSpec("E_p", "Pa", 5e9, 150e9),
    ParamSpec("d31", "m/V", 0.05e-9, 3e-9),
    ParamSpec("t_p", "m", 40e-6, 400e-6),
    ParamSpec("length", "m", 3e-3, 25e-3),
    ParamSpec("width", "m", 0.5e-3, 12e-3),
)
ACTUATOR_FIELDS = {"E_p": "pzt_modulus_Pa", "d31": "d31_m_per_V", "t_p": "pzt_thickness_m",
                   "length": "length_m", "width": "width_nom_m"}

TRANSMISSION_SPECS = (
    ParamSpec("k_ser", "N/m", 30.0, 1e5),
    ParamSpec("kappa_1", "N m/rad", 0.0, 5e-4, log=False, typical=1e-5),
    ParamSpec("kappa_2", "N m/rad", 0.0, 5e-4, log=False, typical=1e-5),
    ParamSpec("kappa_3", "N m/rad", 0.0, 5e-4, log=False, typical=1e-5),
    ParamSpec("bias", "m", -150e-6, 350e-6, log=False, typical=1e-4),
)
TRANSMISSION_REFERENCE_K_SER = 1000.0
CORRELATION_WARNING = 0.98


@dataclass(frozen=True)
class ParamEstimate:
    name: str
    value: float
    ci95: tuple[float, float] | None
    unit: str
    status: str                 # identified | weakly identified | upper limit | not identifiable | not computed
    reference: float

    def as_json(self) -> dict[str, Any]:
        return {"value": _num(self.value), "ci95": None if self.ci95 is None else [_num(v) for v in self.ci95],
                "unit": self.unit, "status": self.status, "identifiable": self.status in ("identified", "upper limit"),
                "reference": _num(self.reference)}


@dataclass
class GroupFit:
    """One fitted group: an actuator (by layer count) or a design."""

    key: str
    params: dict[str, ParamEstimate]
    rms_N: float | None
    rms_m: float | None
    n_observations: int
    chi2: float
    dof: int
    method: str
    warnings: list[str] = field(default_factory=list)
    derived: dict[str, Any] = field(default_factory=dict)  # name -> a value's record, or a list (protocols)
    model: Any = None             # ActuatorParams or (ActuatorParams, DesignParams)
    specimens: dict[str, GroupFit] = field(default_factory=dict)   # per-specimen fits (two or more specimens)
    sessions: dict[str, list[str]] = field(default_factory=dict)   # session key -> its recordings

    def as_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {name: p.as_json() for name, p in self.params.items()}
        out.update(rms_N=_num(self.rms_N), rms_m=_num(self.rms_m), n_observations=self.n_observations,
                   reduced_chi2=_num(self.chi2 / self.dof) if self.dof > 0 else None, warnings=self.warnings)
        if self.derived:
            out["derived"] = self.derived
        if self.sessions:
            out["sessions"] = self.sessions
        if self.specimens:
            out["specimens"] = {k: v.as_json() for k, v in self.specimens.items()}
        return out


@dataclass
class FitReport:
    method: str
    actuators: dict[int, GroupFit]
    designs: dict[int, GroupFit]
    warnings: list[str] = field(default_factory=list)

    def as_json(self) -> dict[str, Any]:
        return {"method": self.method,
                "actuators": {str(k): v.as_json() for k, v in sorted(self.actuators.items())},
                "designs": {str(k): v.as_json() for k, v in sorted(self.designs.items())},
                "warnings": self.warnings}

    def to_json(self) -> str:
        return json.dumps(self.as_json(), indent=2)


def _num(x: float | None) -> float | None:
    if x is None:
        return None
    x = float(x)
    return x if math.isfinite(x) else None


# ----------------------------------------------------------------------------------------------- weights
def setup_of(o: Observation) -> str:
    """The setup an observation was measured in: its session (analysis.sessions), or its run when it has none."""
    return o.session or f"run {o.run}"


def group_sigmas(obs: list[Observation]) -> np.ndarray:
    """Per observation, the sigma of its (session, quantity) group (see module docstring)."""
    keys = [(setup_of(o), o.quantity) for o in obs]
    sig = np.empty(len(obs))
    for key in set(keys):
        idx = [i for i, k in enumerate(keys) if k == key]
        members = [obs[i] for i in idx]
        conds: dict[tuple, list[float]] = {}
        for o in members:
            conds.setdefault((o.mode, round(o.voltage_V, 6), round(o.sag_m, 9), o.protocol), []).append(o.value)
        ss, df = 0.0, 0
        for vals in conds.values():
            if len(vals) > 1:
                v = np.asarray(vals)
                ss += float(np.sum((v - v.mean()) ** 2))
                df += v.size - 1
        values = np.asarray([o.value for o in members])
        scale = float(np.sqrt(np.mean(values**2))) or 1.0
        if df > 0:
            s = math.sqrt(ss / df)
        else:
            spreads = [o.spread / math.sqrt(o.n_cycles) for o in members if np.isfinite(o.spread) and o.n_cycles > 1]
            s = float(np.median(spreads)) if spreads else 0.01 * scale
        sig[idx] = max(s, 1e-4 * scale, 1e-12)
    return sig


@dataclass(frozen=True)
class Nuisance:
    """Per-session zero offsets (analysis/observations.py): one parameter per setup (a native run with its contact
    search, or the files of one specimen and session), with a Gaussian prior of width `sigma` around 0 (the
    search's resolution), entered as one extra residual each. Per session, not per file: a session split into one
    file per voltage must not get one offset per voltage, which would absorb a voltage-dependent effect."""

    runs: tuple[str, ...]            # the session keys (`setup_of`)
    row_index: np.ndarray            # per observation row: index into runs, or -1 (no offset)
    specs: tuple[ParamSpec, ...]
    sigma: float

    def per_row(self, values: np.ndarray) -> np.ndarray:
        v = np.r_[np.asarray(values, float), 0.0]
        return v[self.row_index]

    def prior_residuals(self, values: np.ndarray) -> np.ndarray:
        return np.asarray(values, float) / self.sigma


def make_nuisance(obs: list[Observation], applies, name: str, unit: str, sigma: float, bound: float) -> Nuisance:
    setups = tuple(dict.fromkeys(setup_of(o) for o in obs if applies(o)))
    pos = {r: i for i, r in enumerate(setups)}
    rows = np.array([pos[setup_of(o)] if applies(o) else -1 for o in obs], dtype=int)
    specs = tuple(ParamSpec(f"{name}[{r}]", unit, -bound, bound, log=False, typical=sigma) for r in setups)
    return Nuisance(setups, rows, specs, sigma)


def fit_weighted(obs: list[Observation], y: np.ndarray, predict, specs, reference: np.ndarray, nuisance: Nuisance,
                 method: str, intervals: bool, level: float = 0.95) -> tuple[FitOutcome, np.ndarray]:
    """Weighted fit of physical `specs` plus the `nuisance` offsets; `predict(physical, offsets_per_row)`.

    Two passes. (1) weights from the replicate scatter (`group_sigmas`), fit (to a looser tolerance: it only sets
    the weights). (2) each group's sigma re-estimated from its residuals pooled with its replicate scatter
    (dof-weighted: a group of 8 points with 4 replicate dof is otherwise badly weighted), fit again from the first
    solution, with profile intervals for the physical parameters. Pass 2 starts with pass 1's Jacobian, its rows
    rescaled to the new weights (a residual is (prediction - y) / sigma, so this is exact at the same point).
    Returns (outcome over physical + nuisance parameters, sigmas)."""
    sig = group_sigmas(obs)
    n_phys = len(specs)
    all_specs = tuple(specs) + nuisance.specs
    all_ref = np.r_[reference, np.zeros(len(nuisance.specs))]

    def full_predict(p: np.ndarray) -> np.ndarray | None:
        return predict(p[:n_phys], nuisance.per_row(p[n_phys:]))

    def make(sigma: np.ndarray) -> Problem:
        sigma = sigma.copy()    # this problem's weights (the caller updates its own array between passes)

        def residuals(p: np.ndarray) -> np.ndarray:
            pred = full_predict(p)
            if pred is None:
                return np.full(y.size + len(nuisance.specs), np.nan)
            return np.r_[(pred - y) / sigma, nuisance.prior_residuals(p[n_phys:])]

        return Problem(all_specs, all_ref, residuals)

    out1 = fit_problem(make(sig), method, intervals=False, tol=1e-4)   # only sets the weights: pass 2 refines
    sig1 = sig.copy()
    pred = full_predict(out1.values)
    if pred is not None and np.all(np.isfinite(pred)):
        res = pred - y
        n, p = y.size, len(all_specs)
        keys = [(setup_of(o), o.quantity) for o in obs]
        for key in set(keys):
            idx = np.array([i for i, k in enumerate(keys) if k == key])
            df_rep = _replicate_dof([obs[i] for i in idx])
            df_res = idx.size * max(1.0 - p / n, 0.1)
            var = (float(np.sum(res[idx] ** 2)) + df_rep * float(sig[idx][0]) ** 2) / (df_res + df_rep)
            sig[idx] = max(math.sqrt(var), 1e-3 * float(sig[idx][0]))
    z1 = np.array([sp.to_z(v, r) for sp, v, r in zip(all_specs, out1.values, all_ref)])
    # each group's sigma was estimated from these residuals: one degree of freedom each
    n_groups = len({(setup_of(o), o.quantity) for o in obs})
    J0 = None
    if out1.jacobian is not None:
        J0 = out1.jacobian.copy()
        J0[: y.size] *= (sig1 / sig)[:, None]
    out = fit_problem(make(sig), method, intervals, z0=z1, profile=range(n_phys), level=level,
                      extra_dof_used=n_groups, J0=J0)
    return out, sig


def _replicate_dof(members: list[Observation]) -> int:
    conds: dict[tuple, int] = {}
    for o in members:
        key = (o.mode, round(o.voltage_V, 6), round(o.sag_m, 9), o.protocol)
        conds[key] = conds.get(key, 0) + 1
    return sum(c - 1 for c in conds.values())


# ----------------------------------------------------------------------------------------------- actuator
def _actuator_base(dataset: Dataset, obs: list[Observation], layers: int) -> ActuatorParams:
    info = dataset.runs[obs[0].run].info
    params_set = info.params_set if info.params_set in ("reported", "effective") else "effective"
    base = actuator_preset(layers, params_set)
    known = {f.name for f in fields(ActuatorParams)}
    mp = info.model_params or {}
    # the runner writes {"actuator": {field: value}, "design": {...}}; a flat {field: value} is accepted too.
    # Only the actuator is taken: the design's values are what a fit must find, never an input to it.
    mp = mp.get("actuator", mp) if isinstance(mp.get("actuator"), dict) else mp
    overrides: dict[str, Any] = {k: v for k, v in mp.items()
                 if k in known and k not in ("layers", "label") and isinstance(v, (int, float))}
    return replace(base, **overrides) if overrides else base


def actuator_with(base: ActuatorParams, values: dict[str, float]) -> ActuatorParams:
    fields: dict[str, Any] = {ACTUATOR_FIELDS[k]: float(v) for k, v in values.items()}
    return replace(base, **fields)


ACTUATOR_OFFSET_SIGMA_N = 5e-3     # the actuator protocol's contact threshold: the search resolves zero to this


def fit_actuator(dataset: Dataset, layers: int, method: str = "least-squares", intervals: bool = True,
                 level: float = 0.95, specimen: str | None = None) -> GroupFit:
    """Fit one layer count's actuator (one specimen's rows when `specimen` is given)."""
    obs = [o for o in dataset.observations if o.fixture == "actuator" and o.layers == layers
           and (specimen is None or o.specimen == specimen)]
    if not obs:
        raise ConfigError(f"no actuator observations with {layers} layers in the given recordings")
    base = _actuator_base(dataset, obs, layers)
    reported = actuator_preset(layers, "reported")
    reference = np.array([getattr(reported, ACTUATOR_FIELDS[s.name]) for s in ACTUATOR_SPECS])
    mode = np.array([o.mode for o in obs])
    volts = np.array([o.voltage_V for o in obs])
    push = np.array([o.sag_m for o in obs])
    y = np.array([o.value for o in obs])
    # the stiffness sweep pushes from the same contact as the blocked steps: one tip-zero offset for both
    nuisance = make_nuisance(obs, lambda o: o.mode in ("blocked", "stiffness"), "f0", "N", ACTUATOR_OFFSET_SIGMA_N,
                             0.05)

    def model(p: np.ndarray) -> ActuatorParams:
        return actuator_with(base, dict(zip(ACTUATOR_FIELDS, p)))

    def predict(p: np.ndarray, offsets: np.ndarray) -> np.ndarray | None:
        try:
            return actuator_prediction(model(p), mode, volts, offsets, push)
        except HamrBenchError:
            return None

    out, sig = fit_weighted(obs, y, predict, ACTUATOR_SPECS, reference, nuisance, method, intervals, level)
    n = len(ACTUATOR_SPECS)
    fitted = model(out.values[:n])
    pred = predict(out.values[:n], nuisance.per_row(out.values[n:]))
    g = _group(f"{layers}", ACTUATOR_SPECS, reference, out, obs, y, pred, method)
    g.model = fitted
    g.derived = _actuator_derived(obs, sig, fitted, level)
    g.derived["zero_offsets"] = _offsets_json(dataset, nuisance, out.values[n:], "N")
    g.sessions = _sessions(dataset, obs)
    return g


def _offsets_json(dataset: Dataset, nuisance: Nuisance, values: np.ndarray, unit: str) -> dict[str, Any]:
    """Zero offsets per session, and per recording (the mean of its sessions': one per native run)."""
    by_setup = {k: float(v) for k, v in zip(nuisance.runs, values, strict=True)}
    runs: dict[str, list[float]] = {}
    for run_index, run in enumerate(dataset.runs):
        key = run.info.session or f"run {run_index}"
        if key in by_setup:
            runs.setdefault(run.info.path, []).append(by_setup[key])
    return {"unit": unit, "note": "zero offset at nominal zero sag / tip zero per session (nuisance parameter)",
            "sessions": by_setup, "runs": {p: float(np.mean(v)) for p, v in runs.items()}}


def _slope_ci(x: np.ndarray, y: np.ndarray, sig: np.ndarray, groups: np.ndarray | None) -> tuple[float, float, int]:
    """Weighted least-squares slope (through the origin, or with one intercept per group), its standard error with
    the noise scale estimated from the residuals, and the degrees of freedom."""
    cols = [x]
    if groups is not None:
        cols += [(groups == g).astype(float) for g in np.unique(groups)]
    X = np.column_stack(cols) / sig[:, None]
    yw = y / sig
    beta, *_ = np.linalg.lstsq(X, yw, rcond=None)
    dof = x.size - X.shape[1]
    if dof <= 0:
        return float(beta[0]), math.nan, dof
    s2 = float(np.sum((yw - X @ beta) ** 2)) / dof
    cov = np.linalg.inv(X.T @ X) * s2
    return float(beta[0]), math.sqrt(cov[0, 0]), dof


def _actuator_derived(obs: list[Observation], sig: np.ndarray, a: ActuatorParams,
                      level: float = 0.95) -> dict[str, dict[str, Any]]:
    """What the actuator data DO identify: blocked force per volt c and free deflection per volt s (hence stiffness
    c/s and energy c s V^2), each from its own rows. Both observations are linear in them (F = c V + f0_run,
    stroke = 2 s V), so the 95 % intervals are exact weighted-regression intervals (Student t). With the undriven
    stiffness sweep in the data, the tip stiffness is also measured directly (`stiffness_direct`, F = k push +
    f0_run), to compare with c/s."""
    from scipy import stats

    from hamr_bench.model import actuator as act

    v = np.array([o.voltage_V for o in obs])
    y = np.array([o.value for o in obs])
    runs = np.array([setup_of(o) for o in obs])   # one force offset per session: the intercept groups
    mode = np.array([o.mode for o in obs])
    blocked, free, stiff = mode == "blocked", mode == "free", mode == "stiffness"
    push = np.array([o.sag_m for o in obs])
    out: dict[str, dict[str, Any]] = {}
    est = {}
    for name, m, xx, grp in (("force_per_volt", blocked, v, runs), ("displacement_per_volt", free, 2 * v, None)):
        if m.sum() >= 3:
            est[name] = _slope_ci(xx[m], y[m], sig[m], None if grp is None else grp[m])
    # the undriven stiffness sweep measures the tip stiffness directly (slope of force on push, one intercept per
    # run: the contact offset); loading and unloading rows both count (a stage's reversal error shifts the
    # unloading branch by k x play but leaves the slope, as long as the tip stays in contact)
    touching = stiff & (y > 3 * sig)   # out of contact (a play larger than the push) reads 0 + noise
    if touching.sum() >= 3 and np.unique(push[touching]).size >= 2:
        k, sk, dk = _slope_ci(push[touching], y[touching], sig[touching], runs[touching])
        if dk > 0 and np.isfinite(sk):
            t = stats.t.ppf(0.5 + 0.5 * level, dk)
            out["stiffness_direct"] = {"value": k, "ci95": [k - t * sk, k + t * sk], "unit": "N/m",
                                       "note": "slope of the undriven stiffness sweep (force on push past contact)"}
    v_max = float(v.max())
    # the name carries the voltage to 3 digits: a measured V_bias (an imported trace's 200.006 V) names the same
    # quantity as the nominal 200 V
    at = f"{v_max:.3g}V"

    def entry(value: float, rel_sd: float, dof: int, unit: str) -> dict[str, Any]:
        t = stats.t.ppf(0.5 + 0.5 * level, max(dof, 1))
        return {"value": value, "ci95": [value * (1 - t * rel_sd), value * (1 + t * rel_sd)], "unit": unit}

    if "force_per_volt" in est:
        c, sc, dc = est["force_per_volt"]
        out["force_per_volt"] = entry(c, sc / c, dc, "N/V")
        out[f"blocked_force_at_{at}"] = entry(c * v_max, sc / c, dc, "N")
    if "displacement_per_volt" in est:
        s, ss, ds = est["displacement_per_volt"]
        out["displacement_per_volt"] = entry(s, ss / s, ds, "m/V")
        out[f"free_displacement_at_{at}"] = entry(s * v_max, ss / s, ds, "m")
    if len(est) == 2:
        rel = math.hypot(sc / c, ss / s)
        dof = min(dc, ds)
        out["stiffness"] = entry(c / s, rel, dof, "N/m")
        m = act.mass_kg(a)
        out[f"energy_at_{at}"] = entry(c * s * v_max**2, rel, dof, "J")
        out[f"energy_density_at_{at}"] = {**entry(c * s * v_max**2 / m, rel, dof, "J/kg"),
                                                "note": f"mass {m * 1e6:.2f} mg from the fitted geometry "
                                                        "(not measured)"}
    return out


# ----------------------------------------------------------------------------------------------- transmission
def leg_actuator(dataset: Dataset, obs: list[Observation], layers: int,
                 fitted: dict[int, GroupFit] | None) -> ActuatorParams:
    if fitted and layers in fitted and fitted[layers].model is not None:
        return fitted[layers].model
    return _actuator_base(dataset, obs, layers)


def design_with(base: DesignParams, values: dict[str, float]) -> DesignParams:
    return replace(base, k_ser_N_per_m=float(values["k_ser"]),
                   kappa_N_m_per_rad=(float(values["kappa_1"]), float(values["kappa_2"]), float(values["kappa_3"])),
                   bias_m=float(values["bias"]))


def zero_sag_sigma_m(dataset: Dataset, obs: list[Observation], a: ActuatorParams, base: DesignParams,
                     reference: np.ndarray) -> float:
    """Prior width of a leg run's zero-sag offset: the contact search's force threshold over the leg's stiffness
    at zero sag, for the REFERENCE transmission (not the fitted one, so the prior does not move with the fit)."""
    threshold = 0.4e-3
    for o in obs:
        c = dataset.runs[o.run].info.protocol_params.get("contact") if isinstance(
            dataset.runs[o.run].info.protocol_params, dict) else None
        if isinstance(c, dict) and "threshold_N" in c:
            threshold = float(c["threshold_N"])
            break
    try:
        k = float(Powertrain(a, design_with(base, dict(zip([s.name for s in TRANSMISSION_SPECS], reference))))
                  .leg_stiffness_N_per_m(0.0))
    except HamrBenchError:
        k = math.nan
    k = k if np.isfinite(k) and k > 0.5 else 0.5
    return max(threshold / k, 5e-6)


def fit_transmission(dataset: Dataset, design: int, method: str = "least-squares", intervals: bool = True,
                     protocols: Iterable[str] = LEG_FIT_PROTOCOLS,
                     fitted_actuators: dict[int, GroupFit] | None = None, level: float = 0.95,
                     specimen: str | None = None) -> GroupFit:
    """Fit one design's transmission (one specimen's rows when `specimen` is given)."""
    protocols = tuple(protocols)
    obs = [o for o in dataset.observations if o.fixture == "leg" and o.design == design and o.protocol in protocols
           and (specimen is None or o.specimen == specimen)]
    if not obs:
        raise ConfigError(f"no leg observations of design {design} ({', '.join(protocols)}) in the given recordings")
    layer_counts = sorted({o.layers for o in obs})
    if len(layer_counts) > 1:
        raise ConfigError(f"design {design}: recordings mix actuators with {layer_counts} layers; fit them apart")
    a = leg_actuator(dataset, obs, layer_counts[0], fitted_actuators)
    base = design_preset(design)
    reference = np.array([TRANSMISSION_REFERENCE_K_SER, 0.0, 0.0, 0.0, base.bias_designed_m])
    legs = LegObservations([o.protocol for o in obs], [o.voltage_V for o in obs], [o.sag_m for o in obs])
    y = np.array([o.value for o in obs])
    names = [s.name for s in TRANSMISSION_SPECS]
    sigma_h = zero_sag_sigma_m(dataset, obs, a, base, reference)
    nuisance = make_nuisance(obs, lambda o: o.quantity == "force_N", "h0", "m", sigma_h, 0.5e-3)

    predict = _CachedLegPrediction(legs, lambda p: Powertrain(a, design_with(base, dict(zip(names, p)))))
    out, _sig = fit_weighted(obs, y, predict, TRANSMISSION_SPECS, reference, nuisance, method, intervals, level)
    n = len(TRANSMISSION_SPECS)
    d = design_with(base, dict(zip(names, out.values[:n])))
    pred = predict(out.values[:n], nuisance.per_row(out.values[n:]))
    g = _group(str(design), TRANSMISSION_SPECS, reference, out, obs, y, pred, method)
    g.model = (a, d)
    g.derived = {"actuator": {"layers": a.layers, "label": a.label,
                              "source": "fit" if fitted_actuators and a.layers in fitted_actuators else "recording"},
                 "protocols": sorted({o.protocol for o in obs}),
                 "zero_offsets": {**_offsets_json(dataset, nuisance, out.values[n:], "m"),
                                  "prior_sigma": sigma_h}}
    g.sessions = _sessions(dataset, obs)
    return g


class _CachedLegPrediction:
    """`predict(physical, offsets_per_row)` for leg rows, keeping the last few Powertrains with their free-foot
    predictions. Building a Powertrain and solving its free equilibria is most of an evaluation, and neither
    depends on the per-run zero offsets (they only shift the held foot height of force rows, a closed-form
    force), so a Jacobian column or a step that moves only offsets reuses them. Same numbers as
    `LegObservations.predict` on all rows (the rows are split, each part predicted by the same method)."""

    def __init__(self, legs: LegObservations, build, size: int = 4) -> None:
        self.build = build
        self.size = size
        self.n = legs.voltage_V.size
        self.free_rows = np.flatnonzero(legs.is_free)
        self.held_rows = np.flatnonzero(~legs.is_free)
        self.free_legs = LegObservations(legs.protocol[self.free_rows], legs.voltage_V[self.free_rows],
                                         legs.sag_m[self.free_rows])
        self.held_legs = LegObservations(legs.protocol[self.held_rows], legs.voltage_V[self.held_rows],
                                         legs.sag_m[self.held_rows])
        self.cache: dict[bytes, tuple[Powertrain, np.ndarray] | None] = {}

    def _model(self, p: np.ndarray) -> tuple[Powertrain, np.ndarray] | None:
        key = np.asarray(p, float).tobytes()
        if key in self.cache:
            hit = self.cache.pop(key)
        else:
            try:
                pt = self.build(p)
                hit = (pt, self.free_legs.predict(pt) if self.free_rows.size else np.empty(0))
            except HamrBenchError:
                hit = None
        self.cache[key] = hit              # most recent last
        while len(self.cache) > self.size:
            self.cache.pop(next(iter(self.cache)))
        return hit

    def __call__(self, p: np.ndarray, offsets: np.ndarray) -> np.ndarray | None:
        hit = self._model(p)
        if hit is None:
            return None
        pt, free_pred = hit
        out = np.empty(self.n)
        out[self.free_rows] = free_pred
        if self.held_rows.size:
            try:
                out[self.held_rows] = self.held_legs.predict(pt, np.broadcast_to(np.asarray(offsets, float),
                                                                                 (self.n,))[self.held_rows])
            except HamrBenchError:
                return None
        return out


# ----------------------------------------------------------------------------------------------- common
def _group(key: str, specs, reference, out: FitOutcome, obs, y, pred, method) -> GroupFit:
    params = {}
    warnings = []
    for j, spec in enumerate(specs):
        iv = out.intervals[j] if out.intervals else None
        status = iv.status if iv else "not computed"
        params[spec.name] = ParamEstimate(spec.name, float(out.values[j]), (iv.lo, iv.hi) if iv else None,
                                          spec.unit, status, float(reference[j]))
        if iv and status == "not identifiable":
            warnings.append(f"{spec.name}: not identifiable from these data (the profile stays within the 95 % "
                            f"threshold across the whole search range); value left near the reference "
                            f"{reference[j]:.4g} {spec.unit}")
        elif iv and status == "weakly identified":
            warnings.append(f"{spec.name}: weakly identified (95 % interval {iv.lo:.4g}..{iv.hi:.4g} {spec.unit})")
    corr = out.correlation
    # Correlations only between parameters the data constrain on both sides (one pinned at a bound, e.g. a kappa
    # at zero, has no meaningful local correlation).
    statuses = [iv.status if iv is not None else "not computed" for iv in out.intervals or ()]
    constrained = [not statuses or statuses[j] in ("identified", "weakly identified") for j in range(len(specs))]
    for i in range(len(specs)):
        for j in range(i + 1, len(specs)):
            r = corr[i, j]
            if constrained[i] and constrained[j] and np.isfinite(r) and abs(r) > CORRELATION_WARNING:
                warnings.append(f"{specs[i].name} and {specs[j].name} strongly correlated (r = {r:+.3f}): the data "
                                f"constrain a combination of them")
    q = np.array([o.quantity for o in obs])
    res = pred - y
    rms_N = float(np.sqrt(np.nanmean(res[q == "force_N"] ** 2))) if np.any(q == "force_N") else None
    rms_m = float(np.sqrt(np.nanmean(res[q == "displacement_m"] ** 2))) if np.any(q == "displacement_m") else None
    return GroupFit(key, params, rms_N, rms_m, len(obs), out.chi2, out.dof, method, warnings)


def _sessions(dataset: Dataset, obs: list[Observation]) -> dict[str, list[str]]:
    """Session key -> the recordings (file, and specimen where the file has several) it groups."""
    out: dict[str, list[str]] = {}
    for r in sorted({o.run for o in obs}):
        info = dataset.runs[r].info
        name = info.path + (f" (specimen {info.specimen})" if info.span_s is not None else "")
        out.setdefault(info.session or f"run {r}", []).append(name)
    return out


def specimens_of(obs: Iterable[Observation]) -> list[str]:
    """The specimen labels among observations, in order of appearance."""
    return list(dict.fromkeys(o.specimen for o in obs))


def combine_specimens(key: str, fits: dict[str, GroupFit], level: float = 0.95) -> GroupFit:
    """Per-specimen fits of one group -> the population (analysis/specimens.py): each parameter and derived
    quantity as the mean over specimens with the interval of that mean and the between-specimen spread. The fit
    statistics are the specimens' own (within-specimen residuals): scatter between specimens is not lack of fit."""
    from analysis.specimens import population, standard_error

    first = next(iter(fits.values()))
    labels = list(fits)
    params = {}
    for name, p0 in first.params.items():
        estimates = [f.params[name] for f in fits.values()]
        statuses = {e.status for e in estimates}
        identified = statuses <= {"identified"}
        pop = population([e.value for e in estimates], level=level)
        value = pop["value"] if pop else p0.value
        if identified and pop:
            ci: tuple[float, float] | None = (pop["ci95"][0], pop["ci95"][1])
            status = "identified"
        else:
            known = [e.ci95 for e in estimates if e.ci95 is not None]
            ci = (min(c[0] for c in known), max(c[1] for c in known)) if known else None
            status = next(st for st in ("not identifiable", "weakly identified", "upper limit", "not computed",
                                        "identified") if st in statuses)
        params[name] = ParamEstimate(name, value, ci, p0.unit, status, p0.reference)
    derived: dict[str, dict[str, Any]] = {}
    for name, d0 in first.derived.items():
        entries = [e for e in (f.derived.get(name) for f in fits.values())
                   if isinstance(e, dict) and "value" in e and "ci95" in e]
        if len(entries) < len(fits):
            continue
        pop = population([float(e["value"]) for e in entries], [standard_error(e, level) for e in entries], level)
        if pop:
            derived[name] = {**pop, "unit": d0.get("unit", ""),
                             "note": f"population of {len(entries)} specimens ({', '.join(labels)}): mean, 95 % "
                                     "interval of the mean (t), between-specimen SD, tau = SD beyond each "
                                     "specimen's own error"}
    derived["zero_offsets"] = {"unit": first.derived.get("zero_offsets", {}).get("unit", ""),
                               "sessions": {k: v for f in fits.values()
                                            for k, v in f.derived.get("zero_offsets", {}).get("sessions", {}).items()},
                               "runs": {k: v for f in fits.values()
                                        for k, v in f.derived.get("zero_offsets", {}).get("runs", {}).items()}}
    rms = {}
    for unit in ("rms_N", "rms_m"):
        parts = [(getattr(f, unit), f.n_observations) for f in fits.values() if getattr(f, unit) is not None]
        rms[unit] = math.sqrt(sum(r * r * n for r, n in parts) / sum(n for _r, n in parts)) if parts else None
    warnings = [f"specimen-to-specimen scatter modelled by per-specimen fits ({len(fits)} specimens: "
                f"{', '.join(labels)}): values are population means, intervals the 95 % interval of the mean; "
                "each derived quantity gives the between-specimen SD (not lack of fit)"]
    by_text: dict[str, list[str]] = {}
    for k, f in fits.items():
        for w in f.warnings:
            by_text.setdefault(w, []).append(k)
    warnings += [f"specimen{'s' if len(ks) > 1 else ''} {', '.join(ks)}: {w}" for w, ks in by_text.items()]
    g = GroupFit(key, params, rms["rms_N"], rms["rms_m"], sum(f.n_observations for f in fits.values()),
                 sum(f.chi2 for f in fits.values()), sum(f.dof for f in fits.values()), first.method, warnings,
                 derived)
    g.specimens = dict(fits)
    g.sessions = {k: v for f in fits.values() for k, v in f.sessions.items()}
    g.model = _mean_model(first.model, [f.model for f in fits.values()])
    return g


def _mean_model(first: Any, models: list[Any]) -> Any:
    """The population model: the fitted fields averaged over specimens."""
    if isinstance(first, ActuatorParams):
        means: dict[str, Any] = {f: float(np.mean([getattr(m, f) for m in models])) for f in ACTUATOR_FIELDS.values()}
        return replace(first, **means)
    if isinstance(first, tuple):
        a = _mean_model(first[0], [m[0] for m in models])
        d = first[1]
        d = replace(d, k_ser_N_per_m=float(np.mean([m[1].k_ser_N_per_m for m in models])),
                    bias_m=float(np.mean([m[1].bias_m for m in models])),
                    kappa_N_m_per_rad=tuple(float(x) for x in np.mean([m[1].kappa_N_m_per_rad for m in models],
                                                                      axis=0)))
        return (a, d)
    return first


def _fit_actuator_task(args: tuple) -> GroupFit:
    dataset, layers, method, intervals, level, specimen = args
    return fit_actuator(dataset, layers, method, intervals, level, specimen=specimen)


def _fit_transmission_task(args: tuple) -> GroupFit:
    dataset, design, method, intervals, actuators, level, specimen = args
    return fit_transmission(dataset, design, method, intervals, fitted_actuators=actuators, level=level,
                            specimen=specimen)


def _by_specimen(tasks: list[tuple[Any, list[str]]], results: list[GroupFit], key_of, level: float
                 ) -> dict[Any, GroupFit]:
    """Group results of (group, specimens) tasks: one specimen -> its fit; several -> their population."""
    out = {}
    it = iter(results)
    for group, labels in tasks:
        fits = {label: next(it) for label in labels}
        if len(labels) == 1:
            out[group] = fits[labels[0]]
        else:
            out[group] = combine_specimens(key_of(group), fits, level)
    return out


def fit_dataset(dataset: Dataset, method: str = "least-squares", intervals: bool = True,
                actuator_source: str = "recording", designs: Iterable[int] | None = None,
                level: float = 0.95, jobs: int | None = 1, scheduler: Any = None) -> FitReport:
    """Fit every actuator layer count and every design present in the dataset (intervals at confidence `level`;
    the JSON keeps the name ci95, so callers that change it must say so). A group with several specimens is fitted
    per specimen and reported as their population (`combine_specimens`). The fits are independent: `jobs` spreads
    them over local processes (None: one per core), `scheduler` over a Dask cluster."""
    from analysis.parallel import parallel_map

    if not 0.5 < level < 1.0:
        raise ConfigError(f"confidence level {level!r}: expected a number between 0.5 and 1")
    if method not in METHODS:
        raise ConfigError(f"--method {method!r}: expected one of {', '.join(METHODS)}")
    report = FitReport(method, {}, {})
    act_tasks = [(n, specimens_of(o for o in dataset.observations if o.fixture == "actuator" and o.layers == n))
                 for n in sorted({o.layers for o in dataset.observations if o.fixture == "actuator"})]
    fitted = parallel_map(_fit_actuator_task, [(dataset, n, method, intervals, level, sp if len(sps) > 1 else None)
                                               for n, sps in act_tasks for sp in sps], jobs=jobs, scheduler=scheduler)
    report.actuators.update(_by_specimen(act_tasks, fitted, str, level))
    wanted = sorted({o.design for o in dataset.observations
                     if o.fixture == "leg" and o.design is not None and o.protocol in LEG_FIT_PROTOCOLS})
    if designs is not None:
        wanted = [d for d in wanted if d in set(designs)]
    actuators = report.actuators if actuator_source == "fit" else None
    leg_tasks = [(d, specimens_of(o for o in dataset.observations if o.fixture == "leg" and o.design == d
                                  and o.protocol in LEG_FIT_PROTOCOLS)) for d in wanted]
    fitted = parallel_map(_fit_transmission_task,
                          [(dataset, d, method, intervals, actuators, level, sp if len(sps) > 1 else None)
                           for d, sps in leg_tasks for sp in sps], jobs=jobs, scheduler=scheduler)
    report.designs.update(_by_specimen(leg_tasks, fitted, str, level))
    if not report.actuators and not report.designs:
        report.warnings.append("no fittable observations (actuator or blocked-force/sag-sweep/free-displacement)")
    return report
