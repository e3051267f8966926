"""The gap diagnosis, stage by stage: fit the nominal model with each specimen's gains under the tolerance prior
and every nuisance (fit before you diagnose), test the rows' lack of fit and the specimens as a population against
their tolerances, map where the rest of the gap lies (`residuals`), screen each
candidate family alone (`screening`), name effects by forward selection on held-out conditions (`ranking`), and
decide what each named effect means (`verdict`)."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from functools import partial
from typing import Any

import numpy as np
from scipy import optimize, stats

from analysis.gap import residuals as res
from analysis.gap import tolerances as tol
from analysis.gap.families import CANDIDATES, FABRICATION, FAMILIES
from analysis.gap.fitpool import FitPool
from analysis.gap.features import GapData
from analysis.gap.heldout import Judge
from analysis.gap.problem import WIDE_GAIN_BOUND, Fit, Problem
from analysis.gap.ranking import select
from analysis.gap.results import DetectionLimit, Diagnosis, FitTrail, Population, Remainder, SpecimenDeviation
from analysis.gap.screening import screen
from analysis.gap.verdict import decide
from hamr_bench.errors import ModelError

GAP_ALPHA = 1e-3
# How far (in tolerance sigmas) a change common to a layer count's specimens must move their mean gains before the
# population test can tell it from scatter: the 2-dof mean test at the gap level
DETECTION_SIGMAS = math.sqrt(float(stats.chi2.ppf(1 - GAP_ALPHA, 2)))


def applicable(p: Problem, names: Sequence[str]) -> list[str]:
    """The candidates this data can show at all: leg effects need leg runs, stage effects stage moves, drive
    effects driven rows, force-side effects force rows."""
    fixtures = {e.run.fixture for e in p.engines}
    has_force = any(r.quantity == "force_N" for r in p.rows)
    driven = any(r.phase != "hold" for r in p.rows)
    stage = any(e.run.stage_cmd[0].size > 1 for e in p.engines)
    out = []
    for n in names:
        kind = FAMILIES[n].kind
        if (kind == "design" and "leg" not in fixtures) or (kind == "stage" and not stage) \
                or (kind == "drive" and not driven) or (kind in ("contact", "baseline") and not has_force):
            continue
        out.append(n)
    return out


def nominal_fit(p: Problem) -> Fit:
    """The presets with every nuisance fitted. A specimen gain stopped at the solver's bound means the presets are
    further off than the bound allows: the problem then takes the wide bound, for this fit and every later one."""
    fit = p.solve((), p.initial_nuisances(), max_nfev=100)
    gains = [abs(v) for q, v in zip(fit.layout.params, fit.x, strict=True) if q.kind == "gain"]
    if gains and max(gains) >= p.gain_bound * (1.0 - 1e-6) and p.gain_bound < WIDE_GAIN_BOUND:
        p.gain_bound = WIDE_GAIN_BOUND
        fit = p.solve((), fit.values(), max_nfev=100)
    return fit


def _whitened_gains(p: Problem, fit: Fit, g: str) -> np.ndarray:
    """A specimen group's fitted (stroke, stiffness) log gains in units of the tolerance prior."""
    return p.gain_whitening[g] @ np.array([fit.value("gain", g, 0), fit.value("gain", g, 1)])


def population_test(p: Problem, fit: Fit) -> Population:
    """Are the specimens, as a population, where the tolerances put them? In-sample a shift common to every
    specimen is absorbed by their gains and leaves no lack of fit in the rows: it shows here.

    Two chi^2 tests of the specimens' whitened gains (unit normal under the tolerance prior), each at half the
    gap level (Bonferroni): `common`, the mean of each layer count's specimens (n |mean|^2, 2 dof per layer
    count), which is what a fabrication shift of the batch moves, and is as sensitive to it with many specimens
    as its detection limit (`DETECTION_SIGMAS`, `detection_limits`) assumes; and `total`, every specimen (2 dof each),
    which also sees specimens scattered beyond their tolerances in different directions. `p_value` is the
    smaller p times 2."""
    by_type: dict[Any, list[np.ndarray]] = {}
    for g in p.groups:
        by_type.setdefault(p.group_type[g], []).append(_whitened_gains(p, fit, g))
    total = sum(float(w @ w) for ws in by_type.values() for w in ws)
    common = sum(len(ws) * float(np.mean(ws, axis=0) @ np.mean(ws, axis=0)) for ws in by_type.values())
    dof_total, dof_common = 2 * len(p.groups), 2 * len(by_type)
    p_total = float(stats.chi2.sf(total, dof_total)) if dof_total else 1.0
    p_common = float(stats.chi2.sf(common, dof_common)) if dof_common else 1.0
    return Population(chi2=total, dof=dof_total, p_total=p_total, common_chi2=common, common_dof=dof_common,
                      p_common=p_common, p_value=min(1.0, 2.0 * min(p_total, p_common)))


def detection_limits(p: Problem) -> dict[str, DetectionLimit]:
    """Per layer count: its specimens and, for each fabrication shift, the smallest change (a fraction, either sign,
    within the candidate's range) that moves their mean gains by DETECTION_SIGMAS, where the population test starts
    to see it in that layer count alone. A smaller shift common to every specimen looks like specimen scatter to
    any method that allows the tolerances (a shift every layer count shares shows a little sooner); the limit
    falls roughly as 1 / sqrt(specimens). None where no change within the range reaches it."""
    out: dict[str, DetectionLimit] = {}
    for layers in sorted(set(p.group_type.values()), key=str):
        groups = [g for g in p.groups if p.group_type[g] == layers]
        actuator, w = p.group_engine[groups[0]].actuator, p.gain_whitening[groups[0]]
        smallest: dict[str, float | None] = {}
        for name in FABRICATION:
            beyond = partial(_beyond_detection, actuator, w, len(groups), name)
            ends = [_realisable(beyond, end) for end in FAMILIES[name].bounds if end != 0]
            found = [abs(optimize.brentq(beyond, 0.0, end, xtol=1e-6)) for end in ends if beyond(end) > 0]
            smallest[name] = min(found) if found else None
        out[f"layers={layers}"] = DetectionLimit(specimens=len(groups), smallest_common_shift=smallest)
    return out


def _realisable(beyond: Any, end: float) -> float:
    """The candidate's range end, or as near to it as the actuator can take (a width loss at the family's bound
    can leave a tapered plate's tip wider than the model allows): the largest 0.9^k x end it can."""
    for _ in range(60):
        try:
            beyond(end)
            return end
        except ModelError:
            end *= 0.9
    return end


def _beyond_detection(actuator: Any, whitening: np.ndarray, n: int, name: str, s: float) -> float:
    return tol.common_shift_sigmas(actuator, whitening, n, name, s) - DETECTION_SIGMAS


def specimen_table(p: Problem, fit: Fit, final: Fit | None = None) -> dict[str, SpecimenDeviation]:
    """Each specimen's fitted deviation from the presets in `fit` (free stroke and stiffness, %) and its prior
    score, and, where the `final` fit holds a field-dependent effect, its plates' thickness against the nominal."""
    out = {}
    for g in p.groups:
        a, b = fit.value("gain", g, 0), fit.value("gain", g, 1)
        score = float(np.linalg.norm(_whitened_gains(p, fit, g)))
        plate = math.expm1(final.value("plate", g)) if final and ("plate", g) in final.layout.index else None
        out[g] = SpecimenDeviation(stroke_change=math.expm1(a), stiffness_change=math.expm1(b),
                                   tolerance_sigmas=score, plate_thickness_change=plate)
    return out


def diagnose(data: GapData, fit_params: dict | None = None, candidates: Sequence[str] | None = None,
             seed: int = 0, jobs: int = 1) -> Diagnosis:
    """`jobs` > 1: the candidate fits of screening and of each selection step run in that many processes (the
    result does not depend on it)."""
    t0 = time.perf_counter()
    p = Problem(data, fit_params)
    names = applicable(p, list(candidates or CANDIDATES))
    nominal = nominal_fit(p)
    lack = res.global_test(p, nominal.z, len(nominal.layout.params))
    population = population_test(p, nominal)
    gap = lack.p_value < GAP_ALPHA or population.p_value < GAP_ALPHA
    judge = Judge(p, seed, reference=nominal)
    # forked after the nominal fit, so the workers start from its warmed caches
    with FitPool(p, jobs if gap else 1, judge) as pool:
        screened, screen_fits = screen(p, nominal, names, pool.add_each) if gap else ([], {})
        sel = select(p, nominal, screened, judge, gap, pool.add_each_judged, screen_fits, pool.grid_objectives,
                     pool.add_onto)
    named, best, cannot = decide(p, sel, judge)
    final = sel.fits[-1]
    last = sel.steps[-1]
    unexplained = Remainder(last.heldout, res.global_test(p, final.z, len(final.layout.params)).p_value,
                            last.closed_fraction)
    lags = {"/".join(q.key): final.value("lag", *q.key) for q in final.layout.params if q.kind == "lag"}
    return Diagnosis(where=res.regions(p, nominal.z), gap_above_noise=bool(gap), nominal_lack_of_fit=lack,
                     specimens=specimen_table(p, nominal, final), screening=screened, waterfall=sel.steps, named=named,
                     best=best, unexplained=unexplained, cannot_separate=cannot, sensor_lag_s=lags,
                     ramp_rates_s=p.ramp_rates, elapsed_s=time.perf_counter() - t0,
                     recordings=data.provenance() if hasattr(data, "provenance") else [],
                     specimen_population=population, detection_limits=detection_limits(p),
                     turned_down=sel.rejected, candidates=list(names),
                     fits=FitTrail(problem=p, steps=list(sel.fits)))
