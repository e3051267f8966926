"""Blind self-check of the gap diagnosis, run the way another lab's data reaches it.

Each trial draws one hidden case from its own seed (`sim_devices.scenarios.draw_scenario`): 0-3 simultaneous
effects in the simulated bench's GENERATOR forms (which share no formula with the candidate families: docs/gap.md
lists them side by side), decoys outside the library, nulls, and several specimens whose parameters are drawn
within fabrication tolerances, so the nominal model is off from the truth as on a real rig. Each specimen runs the
actuator protocol through the real drivers against the emulators; the runs are written as another lab's CSV files
(`sim_devices.trace_export`: one file per test x layer count x V_bias, the specimens one after another, the
project's commanded timelines dropped), imported with the documented importer and diagnosed from the imported
recordings alone. The diagnosis is never told the effect, its strength or the specimens' parameters.

Scores (`score`): top-1 on single-effect trials, every effect named on multi-effect trials, false attributions on
nulls, decoys left unexplained, and interval coverage of the truth's strength where the generator's and the
candidate's units measure the same quantity (the scenario gives that `library_strength`).

What this check shares with the diagnosis, so it is NOT independent: the presets (nominal parameters), the
laminate model both the bench and the diagnosis evaluate, and the trace format. What it does not share: the effect
forms, the drive timing (inferred from the traces), the specimen draw. The external-lab check
(`benchmarks/external_lab`) shares none of these.
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from hamr_bench.model import ActuatorParams
    from sim_devices.scenarios import Scenario, SpecimenTruth

# The trial's actuator protocol: three voltages, two repetitions (the second at the slow ramp), four cycles a step.
TRIAL_OPTIONS = ["voltages_V=100,175,250", "repetitions=2", "drive.cycles=4"]
TRIAL_SPECIMENS = 3
TRIAL_LAYERS = (2,)   # the layer counts a trial builds its specimens of (the effects' strengths refer to 2 layers)
# Library effects an actuator-only trace cannot show, left out of the draw (reported with the figures).
EXCLUDED_FROM_DRAW: dict[str, str] = {
    "stage_backlash": "the exported traces hold blocked-force and free-displacement steps only; no stage reversal",
    "bias_error": "a leg-fixture effect",
}


@dataclass
class Trial:
    seed: int
    kind: str                           # null | single | multi | decoy
    truth: list[str]                    # library candidates present (decoys excluded)
    decoys: list[str]
    truth_strength: dict[str, float | None]   # in the candidate's unit, where the units coincide
    best: str | None
    named: dict[str, str]               # effect -> verdict
    ambiguous_sets: list[list[str]]
    strength_ci95: dict[str, list[float]] = field(default_factory=dict)
    sim_s: float = 0.0
    diagnose_s: float = 0.0
    joint: list[list[str]] = field(default_factory=list)   # pairs that entered together (`joint_entry`)

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _draw_pool() -> tuple[str, ...]:
    from sim_devices.scenarios import LIBRARY_EFFECTS

    return tuple(n for n in LIBRARY_EFFECTS if n not in EXCLUDED_FROM_DRAW)


def draw_trial(seed: int, null_fraction: float = 0.15, decoy_fraction: float = 0.1,
               specimens: int = TRIAL_SPECIMENS, layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> Scenario:
    """The trial's scenario: what the simulated bench will hold (effects, strengths, specimens of each layer
    count; the effects and the 2-layer specimens are drawn as without the other layer counts)."""
    from sim_devices.scenarios import draw_scenario

    return draw_scenario(seed, null_fraction=null_fraction, decoy_fraction=decoy_fraction, n_specimens=specimens,
                         fixtures=("actuator",), pool=_draw_pool(), layers=_reference_layers(layer_counts),
                         layer_counts=tuple(layer_counts))


def _reference_layers(layer_counts: tuple[int, ...]) -> int:
    """The layer count the effects' strengths refer to: 2 where the trial builds it, else its first."""
    return 2 if 2 in layer_counts else layer_counts[0]


def trial_recordings(sc: Scenario, seed: int, root: Path) -> list[Path]:
    """The trial as another lab's data: each specimen recorded on the simulated bench, exported as trace CSVs and
    imported as a user would (`hamr-bench import trace`), into MCAP files under `root`."""
    from analysis.importer import import_trace
    from sim_devices.trace_export import export_actuator_traces, exported_layers, record_specimens

    runs = record_specimens(sc, root / "runs", set_options=TRIAL_OPTIONS, seed=seed)
    paths = []
    for csv_path in export_actuator_traces(sc, root / "csv", recordings=runs):
        out = root / "imported" / (csv_path.stem + ".mcap")
        out.parent.mkdir(exist_ok=True)
        import_trace(csv_path, out, "actuator", layers=exported_layers(csv_path))
        paths.append(out)
    return paths


def run_trial(seed: int, null_fraction: float = 0.15, decoy_fraction: float = 0.1,
              specimens: int = TRIAL_SPECIMENS, layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> Trial:
    from analysis.gap.diagnose import diagnose
    from analysis.gap.features import load_gap_data

    sc = draw_trial(seed, null_fraction, decoy_fraction, specimens, layer_counts)
    with tempfile.TemporaryDirectory(prefix="hamr-selfcheck-") as tmp:
        t0 = time.perf_counter()
        paths = trial_recordings(sc, seed, Path(tmp))
        t1 = time.perf_counter()
        result = diagnose(load_gap_data(paths), seed=seed)   # the recordings alone
        t2 = time.perf_counter()
    library = [e for e in sc.effects if not e.decoy and e.library_name]
    return Trial(
        seed=seed, kind=sc.kind, truth=[str(e.library_name) for e in library],
        decoys=[e.name for e in sc.effects if e.decoy],
        truth_strength={str(e.library_name): e.library_strength for e in library},
        best=result.best, named={e.name: e.verdict for e in result.named},
        ambiguous_sets=[list(s.effects) for s in result.cannot_separate],
        strength_ci95={e.name: [float(x) for x in e.strength_ci95] for e in result.named},
        sim_s=t1 - t0, diagnose_s=t2 - t1, joint=joint_pairs(result.waterfall))


def joint_pairs(waterfall: list[Any]) -> list[list[str]]:
    """The pairs of a waterfall that entered together, each once, in waterfall order."""
    out: list[list[str]] = []
    for step in waterfall:
        pair = sorted([str(step.added), *step.joint_with]) if step.joint_with else None
        if pair and pair not in out:
            out.append(pair)
    return out


def _attributed(t: Trial) -> set[str]:
    return {n for n, v in t.named.items() if v == "attributed"}


def _extra_attributions(t: Trial) -> set[str]:
    """Effects the trial does not hold but the diagnosis claims: attributed, or `best` unless it leads a set that
    holds a hidden effect (a set the data cannot split, the truth in it, claims no more than the data show). On a
    single- or multi-effect trial, what a null's false attribution is on a null."""
    truth = set(t.truth)
    claims = _attributed(t)
    if t.best and not any(t.best in s and truth & set(s) for s in t.ambiguous_sets):
        claims = claims | {t.best}
    return claims - truth


def _answered(t: Trial) -> bool:
    """The trial names something as the gap's cause: an attributed effect, or a `best` (which an ambiguous set
    that would be attributed gives too)."""
    return bool(_attributed(t)) or t.best is not None


def _in_ambiguous_set(t: Trial, name: str) -> bool:
    return any(name in s for s in t.ambiguous_sets) or t.named.get(name) == "ambiguous"


def _named_at_a_step(t: Trial, name: str) -> bool:
    """Named at a waterfall step, attributed or ambiguous (the multi-effect figure's count)."""
    return t.named.get(name) in ("attributed", "ambiguous")


def _covers(t: Trial, name: str) -> bool:
    return t.strength_ci95[name][0] <= float(t.truth_strength[name] or 0.0) <= t.strength_ci95[name][1]


def score(trials: list[Trial]) -> dict[str, Any]:
    """The issue's bars, each as a measured fraction with the number of trials it rests on."""
    single = [t for t in trials if t.kind == "single"]
    multi = [t for t in trials if t.kind == "multi"]
    nulls = [t for t in trials if t.kind == "null"]
    decoy_only = [t for t in trials if t.kind == "decoy" and not t.truth]

    def frac(a: int, b: int) -> float | None:
        return a / b if b else None

    multi_pairs = [(t, n) for t in multi for n in t.truth]
    coverage = [(t, n) for t in trials for n in t.truth
                if t.truth_strength.get(n) is not None and n in _attributed(t) and n in t.strength_ci95]
    covered = [(t, n) for t, n in coverage if _covers(t, n)]
    by_effect: dict[str, list[int]] = {}
    for t in single:
        row = by_effect.setdefault(t.truth[0], [0, 0])
        row[0] += t.best == t.truth[0]
        row[1] += 1
    multi_by_effect: dict[str, list[int]] = {}
    for t, n in multi_pairs:
        row = multi_by_effect.setdefault(n, [0, 0])
        row[0] += _named_at_a_step(t, n)
        row[1] += 1
    coverage_by_effect: dict[str, list[int]] = {}
    for t, n in coverage:
        row = coverage_by_effect.setdefault(n, [0, 0])
        row[0] += _covers(t, n)
        row[1] += 1
    extras = [_extra_attributions(t) for t in single + multi]
    extras_by_effect: dict[str, int] = {}
    for claimed in extras:
        for n in sorted(claimed):
            extras_by_effect[n] = extras_by_effect.get(n, 0) + 1
    return {
        "trials": len(trials), "single_trials": len(single), "multi_trials": len(multi),
        "null_trials": len(nulls), "decoy_only_trials": len(decoy_only),
        "top1_single": frac(sum(t.best == t.truth[0] for t in single), len(single)),
        "top1_single_by_effect": by_effect,
        "truth_in_ambiguous_set_single": frac(sum(t.best != t.truth[0] and _in_ambiguous_set(t, t.truth[0])
                                                  for t in single), len(single)),
        "multi_effects_named": frac(sum(_named_at_a_step(t, n) for t, n in multi_pairs), len(multi_pairs)),
        "multi_effect_count": len(multi_pairs),
        "multi_effects_named_by_effect": multi_by_effect,
        # the looser reading: a hidden effect inside a set the diagnosis names as one it cannot separate
        "multi_effects_named_or_in_set": frac(sum(_named_at_a_step(t, n) or _in_ambiguous_set(t, n)
                                                  for t, n in multi_pairs),
                                              len(multi_pairs)),
        "false_attribution_rate_null": frac(sum(_answered(t) for t in nulls), len(nulls)),
        # precision on the trials that hold an effect: an effect attributed that is not among the hidden ones
        "extra_attribution_rate_effect_trials": frac(sum(bool(c) for c in extras), len(extras)),
        "extra_attributions_by_effect": extras_by_effect,
        "decoys_unexplained": frac(sum(not _answered(t) for t in decoy_only), len(decoy_only)),
        "interval_coverage": frac(len(covered), len(coverage)), "coverage_effects": len(coverage),
        "interval_coverage_by_effect": coverage_by_effect,
        "mean_sim_s": float(np.mean([t.sim_s for t in trials])) if trials else None,
        "mean_diagnose_s": float(np.mean([t.diagnose_s for t in trials])) if trials else None,
        "trials_with_a_joint_entry": sum(bool(t.joint) for t in trials),
    }




def gain_sigmas(seed: int, null_fraction: float = 0.15, decoy_fraction: float = 0.1,
                specimens: int = TRIAL_SPECIMENS, layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> dict[str, float]:
    """For each hidden effect that acts on a trial's actuators as a change of their common gains (a fabrication
    shift; a series spring, to first order), how far it moves the mean of its specimens' gains in units of the
    tolerance prior's spread of that mean (sqrt(n) x the Mahalanobis length of the (log stroke, log stiffness)
    change; over several layer counts, the root of the summed squares): the best any method that allows the
    tolerances can do. Below the design's level (`design_study.Design.threshold_sigmas`; `DETECTION_SIGMAS` on
    one layer count) such an effect looks like specimen scatter. A spring's change is its blocked-force loss at
    250 V (free stroke unchanged); a hardening spring's loss differs across voltages, which a method could still
    see: for springs the limit is that of the linear part. Recomputed from the trial's seed (no simulation), so a
    raw file of an earlier run can be scored too (`design_study.effect_sigmas`)."""
    from analysis.gap.design_study import Design, effect_sigmas, gain_strength

    sc = draw_trial(seed, null_fraction, decoy_fraction, specimens, layer_counts)
    design = Design(sc.layer_counts, specimens)
    out = {}
    for e in sc.effects:
        strength = gain_strength(e)
        if e.decoy or not e.library_name or strength is None:
            continue
        sig = effect_sigmas(e.library_name, strength, e.shape, design)
        if sig is not None:
            out[e.library_name] = sig
    return out


def realised_sigmas(seed: int, null_fraction: float = 0.15, decoy_fraction: float = 0.1,
                    specimens: int = TRIAL_SPECIMENS, layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> float:
    """How far the trial's specimens, as built (each its own fabrication scatter, with every hidden effect on the
    gains applied by the bench's own forms), sit from the presets as a population: sqrt(n) x the Mahalanobis
    length of their mean (log stroke, log stiffness) change under the diagnosis's tolerance prior, per layer
    count (the root of the summed squares over several). It is what the population test sees with the gains known
    exactly, so below the design's level no method that allows the tolerances can tell these specimens from
    scatter, whatever the drawn strength (`gain_sigmas`) promised: the scatter of a few specimens can cancel part
    of a shift or add to it."""
    return built_sigmas(draw_trial(seed, null_fraction, decoy_fraction, specimens, layer_counts))


def built_sigmas(sc: Scenario) -> float:
    """`realised_sigmas` of one drawn scenario."""
    from analysis.gap import tolerances as tol
    from hamr_bench.model import actuator_preset

    total = 0.0
    for layers in sc.layer_counts:
        preset = actuator_preset(layers, sc.params_set)
        changes = [_built_change(sc, spec, preset, layers) for spec in sc.specimens if spec.layers == layers]
        mean = np.mean(changes, axis=0)
        total += len(changes) * float(np.linalg.norm(tol.whitening(preset) @ mean)) ** 2
    return math.sqrt(total)


def _built_change(sc: Scenario, spec: SpecimenTruth, preset: ActuatorParams, layers: int) -> np.ndarray:
    """One specimen's (log stroke, log stiffness) against its preset, as the bench builds it: its drawn
    parameters, every hidden shift in the bench's own form, and the force share every series spring takes."""
    from analysis.gap import tolerances as tol
    from analysis.gap.design_study import spring_loss
    from hamr_bench.model import actuator as act
    from sim_devices.bench_effects import MODEL_HOOKS

    a = act.with_changes(preset, **spec.actuator)
    for e in sc.effects:    # a design-side hook (a flexure decoy) leaves the plate as it is
        if e.name in MODEL_HOOKS:
            a = MODEL_HOOKS[e.name](strength=e.strength).actuator_params(a)
    kept = 1.0              # a series spring after the plate: its share of the tip's deflection is lost
    for e in sc.effects:
        if e.name == "sensor_compliance":
            kept /= 1.0 + float(e.strength) * act.stiffness_N_per_m(a)
        elif e.name == "base_compliance":
            loss = e.observable["blocked_force_loss_250V"] if layers == sc.layers else \
                spring_loss(e.name, e.strength, e.shape, preset)
            kept *= 1.0 - loss
    return tol.log_outputs(a) - tol.log_outputs(preset) + np.array([0.0, math.log(kept)])


def detectability_breakdown(trials: list[Trial], null_fraction: float = 0.15, decoy_fraction: float = 0.1,
                            specimens: int = TRIAL_SPECIMENS,
                            layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> dict[str, Any]:
    """The single- and multi-effect scores split by kind of hidden effect: effects on the specimens' common gains
    (shifts and springs) above and below their detection limit (`gain_sigmas`), and every other effect. Single:
    top-1, and how often the truth was inside a set the diagnosis named as one it cannot separate; multi: each
    hidden effect named (attributed or ambiguous) or inside a named set. The single trials on the gains are split
    a second time by the specimens as built (`realised_sigmas`). The fractions, specimens and layer counts must
    be the run's (they set the draw)."""
    from analysis.gap.design_study import Design

    level = Design(tuple(layer_counts), specimens).threshold_sigmas
    kinds = ("gain_above_limit", "gain_below_limit", "other")
    single = {k: [0, 0, 0] for k in kinds}
    multi = {k: [0, 0, 0] for k in kinds}
    realised = {k: [0, 0, 0] for k in ("above_limit", "below_limit")}
    for t in trials:
        if t.kind not in ("single", "multi"):
            continue
        sigmas = gain_sigmas(t.seed, null_fraction, decoy_fraction, specimens, layer_counts)
        if t.kind == "single" and t.truth[0] in sigmas:
            built = realised_sigmas(t.seed, null_fraction, decoy_fraction, specimens, layer_counts)
            row = realised["above_limit" if built >= level else "below_limit"]
            row[0] += t.best == t.truth[0]
            row[1] += t.best != t.truth[0] and _in_ambiguous_set(t, t.truth[0])
            row[2] += 1
        for n in t.truth[:1] if t.kind == "single" else t.truth:
            sig = sigmas.get(n)
            key = "other" if sig is None else ("gain_above_limit" if sig >= level else "gain_below_limit")
            named = _named_at_a_step(t, n)
            row = single[key] if t.kind == "single" else multi[key]
            row[0] += t.best == n if t.kind == "single" else named
            row[1] += (t.best != n if t.kind == "single" else not named) and _in_ambiguous_set(t, n)
            row[2] += 1
    return {"detection_sigmas": level,
            "top1_single": {k: {"right": v[0], "in_set": v[1], "of": v[2]} for k, v in single.items()},
            # the single trials on the gains again, split by the specimens as built (`realised_sigmas`)
            "top1_single_gain_as_built": {k: {"right": v[0], "in_set": v[1], "of": v[2]} for k, v in realised.items()},
            "multi_named": {k: {"named": v[0], "in_set_only": v[1], "of": v[2]} for k, v in multi.items()}}


def _trial_worker(args: tuple[int, float, float, int, tuple[int, ...]]) -> Trial | str:
    """One trial; a trial that crashes is reported by its seed and error (counted, never scored)."""
    try:
        return run_trial(*args)
    except Exception as exc:  # noqa: BLE001 - the check must finish and say what failed
        return f"seed {args[0]}: {type(exc).__name__}: {exc}"


def score_raw(raw_path: str | Path, null_fraction: float = 0.15, decoy_fraction: float = 0.1,
              specimens: int = TRIAL_SPECIMENS, layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> dict[str, Any]:
    """Score the trials of a raw file (`selfcheck(raw_path=...)`), e.g. of a run stopped part way (the fractions,
    specimens and layer counts of that run, for the detectability breakdown)."""
    trials, errors = [], []
    for line in Path(raw_path).read_text(encoding="utf-8").splitlines():
        item = json.loads(line)
        if isinstance(item, str):
            errors.append(item)
        else:
            trials.append(Trial(**item))
    out = score(trials)
    out["errors"] = errors
    out["detectability"] = detectability_breakdown(trials, null_fraction, decoy_fraction, specimens, layer_counts)
    return out


def _run_trials(args: list[tuple[int, float, float, int, tuple[int, ...]]], jobs: int, scheduler: Any,
                take: Callable[[Trial | str], None]) -> None:
    """Each trial's result to `take` as it ends: in this process, in local processes, or on a Dask cluster."""
    if jobs <= 1 and scheduler is None:
        for a in args:
            take(_trial_worker(a))
    elif scheduler is None:
        # as each ends, not in order: a long run shows progress and its raw file keeps what finished
        from concurrent.futures import ProcessPoolExecutor, as_completed

        from analysis.parallel import one_blas_thread

        with ProcessPoolExecutor(max_workers=jobs, initializer=one_blas_thread) as pool:
            for future in as_completed([pool.submit(_trial_worker, a) for a in args]):
                take(future.result())
    else:
        from analysis.parallel import parallel_map

        for t in parallel_map(_trial_worker, args, scheduler=scheduler):
            take(t)


def selfcheck(trials: int = 20, seed: int = 0, jobs: int = 1, null_fraction: float = 0.15,
              decoy_fraction: float = 0.1, progress: bool = False, raw_path: str | None = None,
              scheduler: Any = None, specimens: int = TRIAL_SPECIMENS,
              layer_counts: tuple[int, ...] = TRIAL_LAYERS) -> dict[str, Any]:
    """Blind trials, scored. `jobs` local processes, or `scheduler` a Dask cluster (analysis.parallel);
    `specimens` of each of `layer_counts` a trial."""
    seeds = [seed * 100_000 + i for i in range(trials)]
    layer_counts = tuple(layer_counts)
    args = [(s, null_fraction, decoy_fraction, specimens, layer_counts) for s in seeds]
    done: list[Trial] = []
    errors: list[str] = []
    if raw_path is not None:
        Path(raw_path).write_text("")

    def take(t: Trial | str) -> None:
        if isinstance(t, str):
            errors.append(t)
        else:
            done.append(t)
        if raw_path is not None:   # one JSON line per trial as it ends: a long run stopped part way keeps its trials
            with open(raw_path, "a", encoding="utf-8") as fh:
                fh.write(json.dumps(t if isinstance(t, str) else t.to_json(), default=float) + "\n")
        if progress:
            n = len(done) + len(errors)
            shown = t if isinstance(t, str) else f"{t.kind} {'+'.join(t.truth + t.decoys) or '-'} -> {t.best}"
            print(f"trial {n}/{trials}: {shown}", flush=True)

    _run_trials(args, jobs, scheduler, take)
    out = score(done)
    out["errors"] = errors
    out["detectability"] = detectability_breakdown(done, null_fraction, decoy_fraction, specimens, layer_counts)
    out["seed"] = seed
    out["design"] = {"layer_counts": list(layer_counts), "specimens_per_layer_count": specimens}
    out["excluded_from_draw"] = dict(EXCLUDED_FROM_DRAW)
    out["per_trial"] = [t.to_json() for t in done]
    return out
