"""The scorer: run hamr-bench on every case exactly as a user would, then compare its answer with the
manifest.

Per case: `python3 -m hamr_bench import trace FILE.csv --protocol actuator --layers N --out X.mcap` for every
CSV (layer count from the lab's files.csv), then `python3 -m hamr_bench gap DIR --json` on the directory of
the imported recordings. A refusal (an import or the diagnosis stopping with an error) is a finding: the case
is scored `refused` with hamr-bench's own one-line reason, and the scorer goes on.

Figures (effects without a candidate in today's library are reported, not scored as misses):
- single-effect cases: top-1 = the diagnosis names exactly the effect's candidate;
- multi-effect cases: each present effect named (recall), and every one named in the case;
- nulls: false attributions (anything named);
- decoys: left unexplained (nothing named);
plus a confusion matrix (true effect x answer). `ambiguous` answers are counted apart, with whether the set
they name holds the truth.
"""

from __future__ import annotations

import csv
import json
import shutil
import subprocess
import sys
import time
from collections import Counter, defaultdict
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]

# The one mapping table: the generator's effect -> the diagnosis candidate names that mean the same physical
# effect. Main's names (analysis/gap/library.py CANDIDATES) and the names the issue-16 diagnosis adds
# (grounding_lengthening, pzt_thickness, pzt_modulus). A longer active length and a
# compliant clamp are one observable, an effective length (the paper: "effective length to be greater due to
# imperfect mechanical grounding"), so both map to it. A name counts as "in the library" for a case when the
# diagnosis lists it among the `candidates` the data can show (whether or not a gap was found); a checkout whose
# JSON has no `candidates` is read from the ranking, which is empty where no gap was found.
CANDIDATE_NAMES: dict[str, tuple[str, ...]] = {
    "hysteresis": ("hysteresis",),
    "creep": ("creep",),
    "d31_field": ("field_dependent_d31",),
    "drift": ("sensor_drift",),
    "base_compliance": ("base_compliance",),
    "sensor_compliance": ("sensor_compliance",),
    "width_loss": ("width_loss",),
    "grounding": ("grounding_lengthening",),
    "pzt_thickness": ("pzt_thickness",),
    "pzt_modulus": ("pzt_modulus",),
    "length": ("grounding_lengthening",),
}
# Candidates the issue says blocked force and free stroke alone cannot tell apart (a secondary, class-level
# top-1 counts an answer inside the truth's class).
SAME_SIGNATURE: tuple[frozenset[str], ...] = (
    frozenset({"base_compliance", "sensor_compliance", "width_loss"}),)


@dataclass
class CaseResult:
    case_id: str
    kind: str
    truth: list[str]                                  # generator effect names
    named: list[str] = field(default_factory=list)    # candidate names the diagnosis named
    best: str | None = None
    verdict: str = ""                                 # the top-ranked entry's verdict
    ambiguous_set: list[str] = field(default_factory=list)
    library: list[str] = field(default_factory=list)  # the candidates the diagnosis could name in this case
    refused: str = ""                                 # hamr-bench's one-line reason, "" if it answered
    refused_files: list[str] = field(default_factory=list)
    outcome: str = ""
    elapsed_s: float = 0.0


def _run(args: list[str], cwd: Path, timeout_s: float) -> tuple[int, str, str]:
    try:
        p = subprocess.run([sys.executable, "-m", "hamr_bench", *args], cwd=cwd, capture_output=True,
                           text=True, timeout=timeout_s)
    except subprocess.TimeoutExpired:
        return -1, "", f"timed out after {timeout_s:.0f} s"
    return p.returncode, p.stdout, p.stderr


def _reason(stderr: str) -> str:
    """hamr-bench's one-line error, or the last line of whatever it printed (a traceback's last line)."""
    lines = [ln.strip() for ln in stderr.strip().splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("hamr-bench: error")]
    return (errors[0] if errors else lines[-1] if lines else "no output")[:300]


def read_index(case_dir: Path) -> list[dict[str, str]]:
    with (case_dir / "files.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def run_case(case_dir: Path, work: Path, root: Path, timeout_s: float) -> tuple[dict[str, Any] | None, str,
                                                                               list[str]]:
    """Import every CSV, then diagnose the imported directory: (gap JSON or None, refusal reason, refused
    files)."""
    if work.exists():
        shutil.rmtree(work)
    work.mkdir(parents=True)
    refused_files = []
    first_reason = ""
    for row in read_index(case_dir):
        csv_path = (case_dir / row["file"]).resolve()
        out = work / (Path(row["file"]).stem + ".mcap")
        rc, _, err = _run(["import", "trace", str(csv_path), "--protocol", "actuator",
                           "--layers", row["layers"], "--out", str(out)], root, timeout_s)
        if rc != 0:
            reason = _reason(err)
            refused_files.append(f"{row['file']}: {reason}")
            first_reason = first_reason or f"import {row['file']}: {reason}"
            out.unlink(missing_ok=True)
    if not any(work.glob("*.mcap")):
        return None, first_reason or "nothing imported", refused_files
    rc, out_text, err = _run(["gap", str(work.resolve()), "--json"], root, timeout_s)
    if rc != 0:
        return None, f"gap: {_reason(err)}", refused_files
    try:
        return json.loads(out_text), "", refused_files
    except ValueError:
        return None, "gap: --json output is not JSON", refused_files


def _entries(out: dict[str, Any]) -> list[dict[str, Any]]:
    """The diagnosis's verdicts: the `named` list where there is one (issue 16), else the ranking (main)."""
    named = out.get("named")
    source = named if isinstance(named, list) else out.get("ranking") or []
    return [e for e in source if isinstance(e, dict)]


def named_effects(out: dict[str, Any]) -> list[str]:
    """Every effect the diagnosis names as attributed: `best` (a pair "a+b" names both) and every entry whose
    verdict is `attributed` ("within tolerance", "ambiguous" and "unexplained" name nothing)."""
    names: list[str] = []
    best = out.get("best")
    if isinstance(best, str) and best:
        names += best.split("+")
    for entry in _entries(out):
        if entry.get("verdict") == "attributed":
            names += str(entry.get("effect", "")).split("+")
    return sorted({n for n in names if n})


def read_answer(result: CaseResult, out: dict[str, Any]) -> None:
    ranking = [e for e in out.get("ranking") or [] if isinstance(e, dict)]
    result.best = out.get("best") if isinstance(out.get("best"), str) else None
    result.named = named_effects(out)
    candidates = out.get("candidates")
    result.library = sorted(str(n) for n in candidates) if isinstance(candidates, list) else \
        sorted({n for e in ranking for n in str(e.get("effect", "")).split("+") if n})   # a checkout before them
    entries = _entries(out)
    if entries:
        result.verdict = str(entries[0].get("verdict", ""))
    ambiguous: set[str] = set()
    for entry in entries:
        if entry.get("verdict") == "ambiguous":
            ambiguous |= {*str(entry.get("effect", "")).split("+"), *(entry.get("confusable_with") or [])}
    result.ambiguous_set = sorted(ambiguous)


def candidates_for(effect: str, library: list[str]) -> list[str]:
    """The effect's candidate names present in the library ([] = no candidate today)."""
    return [n for n in CANDIDATE_NAMES.get(effect, ()) if n in library]


def judge(r: CaseResult) -> str:
    """One word for the case's outcome."""
    if r.refused:
        return "refused"
    if r.kind == "null":
        return "false-attribution" if r.named else ("ambiguous" if r.ambiguous_set else "correct-null")
    if r.kind == "decoy":
        return "decoy-attributed" if r.named else ("ambiguous" if r.ambiguous_set else "decoy-unexplained")
    present = [c for e in r.truth for c in candidates_for(e, r.library)[:1]]
    if r.kind == "single":
        if not present:
            return "no-candidate:" + ("named " + "+".join(r.named) if r.named else "unexplained")
        if top1(r, present[0]):
            extra = len(set(r.named) - {present[0]})
            return "top1-correct" + (f" (+{extra} extra named)" if extra else "")
        if r.ambiguous_set and present[0] in r.ambiguous_set:
            return "ambiguous-with-truth"
        if present[0] in r.named:
            return "named-not-first"
        return "wrong" if r.named else "missed"
    hit = sum(c in r.named for c in present)
    return f"named {hit}/{len(present)}" + (f" (+{len(set(r.named) - set(present))} extra)"
                                             if set(r.named) - set(present) else "")


def top1(r: CaseResult, candidate: str) -> bool:
    """`best` is the effect, alone (a pair is not a top-1 answer)."""
    return r.best == candidate


def truth_label(r: CaseResult) -> str:
    if r.kind == "null":
        return "null"
    if r.kind == "decoy":
        return "decoy:" + r.truth[0]
    return "+".join(r.truth)


def answer_label(r: CaseResult) -> str:
    if r.refused:
        return "refused"
    if r.named:
        return "+".join(r.named)
    return "ambiguous" if r.ambiguous_set else "none"


def _same_class(truth: str, named: list[str]) -> bool:
    return bool(named) and any(truth in cls and set(named) <= cls for cls in SAME_SIGNATURE)


def summary(results: list[CaseResult]) -> dict[str, Any]:
    """The figures of the issue's "Done means", on this set."""
    by_kind: dict[str, list[CaseResult]] = defaultdict(list)
    for r in results:
        by_kind[r.kind].append(r)
    singles = [r for r in by_kind["single"] if not r.refused]
    scorable = [r for r in singles if candidates_for(r.truth[0], r.library)]
    firsts = [candidates_for(r.truth[0], r.library)[0] for r in scorable]
    correct = sum(top1(r, c) for r, c in zip(scorable, firsts, strict=True))
    in_class = sum(top1(r, c) or _same_class(c, [r.best] if r.best else [])
                   for r, c in zip(scorable, firsts, strict=True))
    multi = [r for r in by_kind["multi"] if not r.refused]
    recall_hits = recall_total = every = 0
    for r in multi:
        present = [c for e in r.truth for c in candidates_for(e, r.library)[:1]]
        hits = sum(c in r.named for c in present)
        recall_hits += hits
        recall_total += len(present)
        every += bool(present) and hits == len(present)
    nulls = [r for r in by_kind["null"] if not r.refused]
    decoys = [r for r in by_kind["decoy"] if not r.refused]
    return {
        "cases": len(results), "refused": sum(bool(r.refused) for r in results),
        "kinds": {k: len(v) for k, v in sorted(by_kind.items())},
        "single_top1": [correct, len(scorable)],
        "single_top1_same_signature_class": [in_class, len(scorable)],
        "single_without_candidate": len(singles) - len(scorable),
        "multi_effects_named": [recall_hits, recall_total],
        "multi_every_effect_named": [every, sum(1 for r in multi if any(candidates_for(e, r.library)
                                                                        for e in r.truth))],
        "null_false_attributions": [sum(bool(r.named) for r in nulls), len(nulls)],
        "decoys_unexplained": [sum(not r.named for r in decoys), len(decoys)],
    }


def _fraction(pair: list[int]) -> str:
    a, b = pair
    return f"{a}/{b}" + (f" ({100.0 * a / b:.0f} %)" if b else "")


def format_report(results: list[CaseResult], figures: dict[str, Any]) -> str:
    lines = [f"{'case':10s} {'kind':6s} {'truth':42s} {'answer':34s} {'verdict':12s} outcome / reason"]
    for r in results:
        detail = r.refused if r.refused else judge(r)
        if r.refused_files and not r.refused:
            detail += f"; {len(r.refused_files)} file(s) refused: {r.refused_files[0]}"
        lines.append(f"{r.case_id:10s} {r.kind:6s} {truth_label(r)[:42]:42s} {answer_label(r)[:34]:34s} "
                     f"{r.verdict[:12]:12s} {detail}")
    lines += ["", "figures:",
              f"  refused (import or gap stopped): {figures['refused']}/{figures['cases']}",
              f"  single-effect top-1: {_fraction(figures['single_top1'])}; within the same-signature class "
              f"{_fraction(figures['single_top1_same_signature_class'])}; "
              f"{figures['single_without_candidate']} single case(s) with no candidate in the library",
              f"  multi-effect: effects named {_fraction(figures['multi_effects_named'])}, cases with every "
              f"effect named {_fraction(figures['multi_every_effect_named'])}",
              f"  nulls with a false attribution: {_fraction(figures['null_false_attributions'])}",
              f"  decoys left unexplained: {_fraction(figures['decoys_unexplained'])}", "",
              "confusion (truth x answer):"]
    matrix = Counter((truth_label(r), answer_label(r)) for r in results)
    rows = sorted({t for t, _ in matrix})
    cols = sorted({a for _, a in matrix})
    width = max([len(c) for c in cols] + [5])
    lines.append(" " * 34 + " ".join(f"{c[:width]:>{width}s}" for c in cols))
    for t in rows:
        lines.append(f"{t[:33]:33s} " + " ".join(f"{matrix.get((t, c), 0) or '.':>{width}}" for c in cols))
    return "\n".join(lines)


def score(out_dir: Path, layout: str = "cases", work: Path | None = None, root: Path = ROOT,
          only: list[str] | None = None, timeout_s: float = 1800.0, progress: bool = True) -> dict[str, Any]:
    manifest = json.loads((out_dir / "manifest.json").read_text())
    work = work or out_dir / f"work-{layout}"
    results: list[CaseResult] = []
    for case_id, truth in sorted(manifest["cases"].items()):
        if only and case_id not in only:
            continue
        case_dir = out_dir / layout / case_id
        t0 = time.perf_counter()
        r = CaseResult(case_id, truth["kind"], [e["name"] for e in truth["effects"]])
        if not case_dir.is_dir():
            r.refused = f"no directory {case_dir}"
        else:
            out, r.refused, r.refused_files = run_case(case_dir, work / case_id, root, timeout_s)
            if out is not None:
                read_answer(r, out)
        r.outcome = r.refused and "refused" or judge(r)
        r.elapsed_s = time.perf_counter() - t0
        results.append(r)
        if progress:
            print(f"{case_id}: {truth_label(r)} -> {answer_label(r)} ({r.outcome}; {r.elapsed_s:.0f} s)"
                  + (f" [{r.refused}]" if r.refused else ""), flush=True)
    figures = summary(results)
    report = {"layout": layout, "root": str(root), "figures": figures, "cases": [asdict(r) for r in results]}
    (work / "results.json").parent.mkdir(parents=True, exist_ok=True)
    (work / "results.json").write_text(json.dumps(report, indent=1))
    print(format_report(results, figures))
    return report
