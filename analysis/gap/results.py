"""Typed results of the diagnosis's stages (screen -> fit -> held-out -> rank -> verdict) and their JSON form
(the shape `hamr-bench gap --json` prints; docs/gap.md describes it)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

from analysis.gap.families import FAMILIES

if TYPE_CHECKING:
    import numpy as np

    from analysis.gap.problem import Fit, Problem


@dataclass
class Region:
    """One protocol x condition (x phase) of the rows: its gap against its noise floor (`residuals.regions`)."""

    protocol: str
    condition: str
    quantity: str
    rows: np.ndarray          # indices into Problem.rows
    rms_gap: float            # RMS residual, physical unit of `quantity`
    noise_floor: float        # RMS standard error of the rows (same unit)
    p_value: float            # lack-of-fit F test: mean z^2 over the pure-error variance
    z_rms: float

    def to_json(self) -> dict:
        return {"protocol": self.protocol, "condition": self.condition, "quantity": self.quantity,
                "rms_gap": self.rms_gap, "noise_floor": self.noise_floor, "p_value": self.p_value,
                "gap_over_noise": self.z_rms, "n_rows": int(self.rows.size)}


@dataclass
class LackOfFit:
    """A model's lack of fit over every row: chi^2 of the z-residuals, its F test against the pure error."""

    chi2: float
    n_rows: int
    n_params: int
    pure_error_dof: int
    p_value: float
    z_rms: float

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class Screened:
    """One candidate fitted alone on top of the nominal fit (specimen gains and nuisances refitted)."""

    name: str
    strength: float
    shapes: dict[str, float]
    improvement: float            # objective(nominal) - objective(with it), noise units^2 (`screening.improvement`)
    threshold: float              # the likelihood-ratio threshold it had to pass (over-dispersion included)
    promising: bool
    start: dict[tuple, float] = field(repr=False, default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {"effect": self.name, "strength": self.strength, "unit": FAMILIES[self.name].unit,
                "shapes": dict(self.shapes), "improvement_chi2": self.improvement, "threshold_chi2": self.threshold,
                "promising": self.promising}


@dataclass
class HeldOut:
    """Held-out RMS z of a model (condition folds refitted without each fold), with its bootstrap interval."""

    rms: float
    ci95: tuple[float, float]

    @property
    def reaches_noise_floor(self) -> bool:
        """Its interval reaches 1 (the noise floor): where the selection stops after a named effect."""
        return bool(self.ci95[0] <= 1.0)

    def to_json(self) -> dict[str, Any]:
        return {"rms": self.rms, "ci95": list(self.ci95)}


@dataclass
class StepCandidate:
    """One candidate tried at a step of the forward selection (added to the effects named so far)."""

    name: str
    improvement: float            # in-sample objective decrease over the step's base model (`screening.improvement`)
    heldout: HeldOut
    reduction_ci95: tuple[float, float]   # of the held-out RMS relative to the base model
    strength: float
    bar: float = float("nan")     # the step's likelihood-ratio bar its improvement had to pass

    def to_json(self) -> dict[str, Any]:
        return {"effect": self.name, "improvement_chi2": self.improvement, "heldout": self.heldout.to_json(),
                "reduction_ci95": list(self.reduction_ci95), "strength": self.strength}

    def why_not(self) -> str:
        """Why a candidate tried at a step did not pass it, in words."""
        reasons = []
        if self.reduction_ci95[0] <= 0:
            reasons.append(f"its held-out reduction is not above 0 with 95 % confidence ({self.reduction_ci95[0]:.2f} "
                           f"to {self.reduction_ci95[1]:.2f}; held-out {self.heldout.rms:.2f})")
        if not self.improvement > self.bar:
            reasons.append(f"its in-sample improvement {self.improvement:.4g} is below the step's bar "
                           f"{self.bar:.4g}")
        return "; ".join(reasons) or "it passed, and another candidate was taken"


@dataclass
class WaterfallStep:
    """The held-out gap after adding `added` (with `ambiguous_with`, explanations this step could not tell
    apart from it) to the effects above it."""

    added: str | None             # None: the nominal model (the waterfall's first bar)
    effects: tuple[str, ...]
    heldout: HeldOut
    closed_fraction: float        # of the nominal held-out gap above the noise floor, cumulative
    ambiguous_with: tuple[str, ...] = ()
    tried: list[StepCandidate] = field(default_factory=list)
    joint_with: tuple[str, ...] = ()   # entered as a pair with these (neither passed alone: `joint_entry`)

    def to_json(self) -> dict[str, Any]:
        return {"added": self.added, "effects": list(self.effects), "heldout_rms": self.heldout.rms,
                "heldout_rms_ci95": list(self.heldout.ci95), "closed_fraction": self.closed_fraction,
                "ambiguous_with": list(self.ambiguous_with), "joint_with": list(self.joint_with),
                "tried": [c.to_json() for c in self.tried]}


@dataclass
class NamedEffect:
    """An effect the diagnosis names, in waterfall order (by how much of the held-out gap it closes)."""

    name: str
    verdict: str                  # attributed | ambiguous | unexplained (named but the whole closes too little)
    strength: float
    strength_ci95: tuple[float, float]
    shapes: dict[str, float]
    heldout_before: float
    heldout_after: float
    reduction: float              # 1 - after / before of its own step
    reduction_ci95: tuple[float, float]
    closed_fraction: float        # its own step's share of the nominal held-out gap above noise
    ambiguous_with: tuple[str, ...] = ()
    separated_by: tuple[str, ...] = ()
    beyond_tolerance: bool | None = None
    # explains a real part of the gap: attributed, or ambiguous with a set that would be if it could be split
    explains: bool = False
    notes: tuple[str, ...] = ()

    def to_json(self) -> dict[str, Any]:
        return {"effect": self.name, "verdict": self.verdict, "strength": self.strength,
                "unit": FAMILIES[self.name].unit, "strength_ci95": list(self.strength_ci95),
                "shapes": dict(self.shapes), "heldout_rms_before": self.heldout_before,
                "heldout_rms_after": self.heldout_after, "reduction": self.reduction,
                "reduction_ci95": list(self.reduction_ci95), "closed_fraction": self.closed_fraction,
                "confusable_with": list(self.ambiguous_with), "separated_by": list(self.separated_by),
                "beyond_tolerance": self.beyond_tolerance, "explains_gap": self.explains, "notes": list(self.notes)}


@dataclass(frozen=True)
class Remainder:
    """What the named effects leave: the last step's held-out gap (noise units) with its bootstrap interval,
    whether that interval reaches the noise floor, the final fit's in-sample lack-of-fit p, and the share of the
    nominal held-out gap above the floor closed."""

    heldout: HeldOut
    lack_of_fit_p: float
    closed_fraction: float

    @property
    def at_noise_floor(self) -> bool:
        return self.heldout.reaches_noise_floor

    def to_json(self) -> dict[str, Any]:
        return {"heldout_rms": self.heldout.rms, "heldout_rms_ci95": list(self.heldout.ci95),
                "at_noise_floor": self.at_noise_floor, "lack_of_fit_p": self.lack_of_fit_p,
                "closed_fraction": self.closed_fraction}


@dataclass(frozen=True)
class AmbiguousSet:
    """Explanations the data fitted as well as each other (or an effect and a sensor's timing lag), each with the
    measurement that would tell it from the others."""

    effects: tuple[str, ...]
    separated_by: dict[str, str]

    def to_json(self) -> dict[str, Any]:
        return {"effects": list(self.effects), "separated_by": dict(self.separated_by)}


@dataclass
class Population:
    """The specimens as a population against their tolerances (`diagnose.population_test`): chi^2 of every
    specimen's whitened gains (`total`) and of each layer count's mean (`common`), and the Bonferroni p of the two."""

    chi2: float
    dof: int
    p_total: float
    common_chi2: float
    common_dof: int
    p_common: float
    p_value: float

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class SpecimenDeviation:
    """One specimen's fitted deviation from the presets (fractions) and its prior score; its plates' thickness
    where the final fit holds a field-dependent d31."""

    stroke_change: float
    stiffness_change: float
    tolerance_sigmas: float
    plate_thickness_change: float | None = None

    def to_json(self) -> dict[str, float]:
        return {k: v for k, v in asdict(self).items() if v is not None}   # the plates only where fitted


@dataclass
class DetectionLimit:
    """A layer count's specimens and, per fabrication shift, the smallest change common to them that the
    population test sees (a fraction; None where none within the candidate's range does)."""

    specimens: int
    smallest_common_shift: dict[str, float | None]

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class FitTrail:
    """The fits behind a diagnosis, for the report's plots and for tests: the problem and each selection step's
    fit, the nominal first and the final one last."""

    problem: Problem
    steps: list[Fit]

    @property
    def nominal(self) -> Fit:
        return self.steps[0]

    @property
    def final(self) -> Fit:
        return self.steps[-1]


@dataclass
class Diagnosis:
    """Everything `diagnose` finds: where the gap is, what explains how much of it, what the data cannot tell."""

    where: list[Region]
    gap_above_noise: bool
    nominal_lack_of_fit: LackOfFit
    specimens: dict[str, SpecimenDeviation]   # by specimen group label ("layers=2|specimen=A")
    screening: list[Screened]
    waterfall: list[WaterfallStep]
    named: list[NamedEffect]
    best: str | None
    unexplained: Remainder
    cannot_separate: list[AmbiguousSet]
    sensor_lag_s: dict[str, float]
    ramp_rates_s: list[float]
    elapsed_s: float
    recordings: list[dict[str, Any]] = field(default_factory=list)
    specimen_population: Population | None = None
    detection_limits: dict[str, DetectionLimit] = field(default_factory=dict)   # by "layers=N"
    fits: FitTrail | None = field(default=None, repr=False)
    # the candidates the step after the last named effect tried, none passing (why the selection stopped there)
    turned_down: list[StepCandidate] = field(default_factory=list)
    # every candidate this data can show at all (`diagnose.applicable`), screened or not: with no gap above the
    # noise nothing is screened, and the ranking is empty although these were in the library
    candidates: list[str] = field(default_factory=list)

    def ranking(self) -> list[dict[str, Any]]:
        """Named effects first (waterfall order), each ambiguous one followed by the others of its set (the
        data support them as well, so they rank beside it, not among the candidates turned down), then every
        other candidate with its screening figures."""
        out: list[dict[str, Any]] = []
        seen = {e.name for e in self.named}
        steps = {w.added: w for w in self.waterfall if w.added is not None}
        for e in self.named:
            out.append(e.to_json())
            step = steps.get(e.name)
            for member in e.ambiguous_with:
                row = next((c for c in step.tried if c.name == member), None) if step else None
                if row is None or member in seen:
                    continue   # a timing lag is a sensor chain's parameter, not a candidate; or named already
                seen.add(member)
                out.append(_set_member_entry(e, row))
        for s in sorted(self.screening, key=lambda s: -s.improvement):
            if s.name in seen:
                continue
            out.append({"effect": s.name, "verdict": "not named", "strength": s.strength,
                        "unit": FAMILIES[s.name].unit, "strength_ci95": None, "shapes": dict(s.shapes),
                        "heldout_rms_before": None, "heldout_rms_after": None, "reduction": None,
                        "reduction_ci95": None, "closed_fraction": None, "confusable_with": [],
                        "screen_improvement_chi2": s.improvement, "promising": s.promising})
        return out

    def to_json(self) -> dict[str, Any]:
        return {"best": self.best, "ranking": self.ranking(), "named": [e.to_json() for e in self.named],
                "waterfall": [w.to_json() for w in self.waterfall], "unexplained": self.unexplained.to_json(),
                "cannot_separate": [c.to_json() for c in self.cannot_separate],
                "where": [g.to_json() for g in self.where], "gap_above_noise": self.gap_above_noise,
                "nominal_lack_of_fit": self.nominal_lack_of_fit.to_json(),
                "specimen_population": self.specimen_population.to_json() if self.specimen_population else {},
                "detection_limits": {k: v.to_json() for k, v in self.detection_limits.items()},
                "specimens": {k: v.to_json() for k, v in self.specimens.items()},
                "screening": [s.to_json() for s in self.screening],
                "sensor_lag_s": self.sensor_lag_s, "ramp_rates_s": self.ramp_rates_s,
                "heldout_units": "noise units (z = held-out residual / pure-error standard error / the nominal "
                                 "fit's predictive spread there, the same for every model); 1 = the noise floor",
                "recordings": self.recordings, "elapsed_s": self.elapsed_s, "candidates": list(self.candidates),
                "turned_down": [{**c.to_json(), "bar_chi2": c.bar, "why": c.why_not()} for c in self.turned_down]}


def _set_member_entry(named: NamedEffect, row: StepCandidate) -> dict[str, Any]:
    """A member of `named`'s ambiguous set, as its step tried it: added in `named`'s place, it did as well. Its
    strength is that fit's (no joint-fit interval: the joint fit holds `named`); what would separate them is on
    `named`'s entry and in `cannot_separate`."""
    others = [named.name] + [m for m in named.ambiguous_with if m != row.name]
    before = named.heldout_before
    return {"effect": row.name, "verdict": "ambiguous", "strength": row.strength, "unit": FAMILIES[row.name].unit,
            "strength_ci95": None, "shapes": {}, "heldout_rms_before": before,
            "heldout_rms_after": row.heldout.rms,
            "reduction": 1.0 - row.heldout.rms / before if before > 0 else 0.0,
            "reduction_ci95": list(row.reduction_ci95), "closed_fraction": None, "confusable_with": others,
            "in_set_of": named.name, "improvement_chi2": row.improvement}


def best_text(result: dict[str, Any]) -> str:
    """`gap --json`'s `best` for people: the effect, with the others of its set where the data cannot tell them
    apart, or why there is none."""
    best = result.get("best")
    if not best:
        return "none (nothing named explains the gap)"
    entry: dict[str, Any] = next((e for e in result.get("named", []) if e.get("effect") == best), {})
    others = entry.get("confusable_with") or []
    return f"{best} (ambiguous: or {', '.join(others)})" if entry.get("verdict") == "ambiguous" and others else best


def closed_share_text(fraction: float | None, of: str = "") -> str:
    """A step's share of the nominal held-out gap above the noise floor, for people (`of`: what it is a share of,
    e.g. " of the held-out gap"). Past 100 % the step took the held-out gap below the floor (the share's
    denominator is the gap above it): that reads as all of it."""
    if fraction is None:
        return "-"
    if fraction >= 1.0:
        return f"all{of}, to below the noise floor"
    return f"{fraction:.0%}{of}"


def floor_text(rest: dict) -> str:
    """Where the held-out remainder stands against the noise floor, in words: its interval can reach 1 while the
    figure itself stands well above it (few conditions held out give a wide interval)."""
    if not rest["at_noise_floor"]:
        return ""
    lo, hi = rest["heldout_rms_ci95"]
    if rest["heldout_rms"] <= 1.0:
        return " (at the noise floor)"
    return f" (its 95 % interval, {lo:.2f}-{hi:.2f}, reaches the noise floor)"
