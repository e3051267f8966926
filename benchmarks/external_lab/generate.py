"""Cases to files: for each case, one CSV per test x layer count x bias voltage in the documented trace format
(docs/log-format.md, "Trace": time_s, voltage_V, stage_position_m, force_N, displacement_m) plus a `specimen`
column holding every specimen's block, and a second layout with one specimen per file and no `specimen` column
(for an importer that does not read the column yet). Each case directory also gets `files.csv`, what a lab
would send with its data (file, test, layer count, bias set-point, specimens): no truth. The truth goes to
`manifest.json` beside the case directories.

Layout of OUT:
    manifest.json                       the truth of every case (a hidden judge's copy)
    cases/<case-id>/*.csv, files.csv    specimen column, several specimens per file
    cases-per-specimen/<case-id>/...    one specimen per file, no specimen column
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.external_lab import simulate as sim
from benchmarks.external_lab import truth
from benchmarks.external_lab.cases import Case, draw_case

LAYOUTS = ("cases", "cases-per-specimen")
HEADER = ("time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m")


def _stage_cell(case: Case, test: str) -> str:
    position = case.stage_m["blocked_m"] - (case.stage_m["retract_m"] if test == "free" else 0.0)
    return f"{position:.7f}"


def block_lines(case: Case, block: sim.Block, data: sim.BlockData) -> list[str]:
    """CSV lines of one block (no specimen cell); times on the session clock or from 0, as the case's lab
    writes them. One format per row: columns never measured in this block are empty in the format itself, a
    blank reading (NaN) prints as 'nan' and is blanked afterwards."""
    t = data.time_s + (block.session_start_s if case.time_layout == "continuous" else 0.0)
    stage = _stage_cell(case, block.test)
    stage_fmt = stage if case.stage_style == "constant" else ""
    values = [t, data.voltage_V]
    fmt = "%.5f,%.3f," + stage_fmt
    if data.force_N is not None:
        values.append(data.force_N)
        fmt += ",%.5f,"
    else:
        fmt += ",,"
    if data.displacement_m is not None:
        values.append(data.displacement_m)
        fmt += "%.5e"
    rows = np.column_stack(values).tolist()
    lines = [(fmt % tuple(r)).replace("nan", "") for r in rows]
    if case.stage_style == "first-row" and lines:
        head = lines[0].split(",")
        head[2] = stage
        lines[0] = ",".join(head)
    return lines


def _write(path: Path, header: Iterable[str], lines: list[str]) -> None:
    with path.open("w", encoding="utf-8", newline="\n") as f:
        f.write(",".join(header) + "\n")
        f.write("\n".join(lines))
        f.write("\n")


def file_stem(test: str, layers: int, bias_V: float) -> str:
    return f"{test}_{layers}L_{bias_V:.0f}V"


def write_case(case: Case, out: Path) -> dict[str, Any]:
    """Simulate the case's session and write both layouts; returns the manifest entry."""
    results = sim.run_session(case)
    files: dict[str, list[dict[str, Any]]] = {layout: [] for layout in LAYOUTS}
    grouped: dict[tuple[str, int, float], list[tuple[sim.Block, sim.BlockData]]] = {}
    for blk, data in results:
        nominal = case.voltages_V[blk.rng_key[3]]
        grouped.setdefault((blk.test, blk.specimen.layers, nominal), []).append((blk, data))
    dirs = {layout: out / layout / case.case_id for layout in LAYOUTS}
    for d in dirs.values():
        d.mkdir(parents=True, exist_ok=True)
    for (test, layers, nominal), members in sorted(grouped.items()):
        stem = file_stem(test, layers, nominal)
        per_block = [(blk, block_lines(case, blk, data)) for blk, data in members]
        _write(dirs["cases"] / f"{stem}.csv", (*HEADER, "specimen"),
               [f"{line},{blk.specimen.label}" for blk, lines in per_block for line in lines])
        files["cases"].append({"file": f"{stem}.csv", "test": test, "layers": layers, "bias_V": nominal,
                               "specimens": [blk.specimen.label for blk, _ in per_block]})
        for blk, lines in per_block:
            name = f"{stem}_{blk.specimen.label}.csv"
            _write(dirs["cases-per-specimen"] / name, HEADER, lines)
            files["cases-per-specimen"].append({"file": name, "test": test, "layers": layers,
                                                "bias_V": nominal, "specimens": [blk.specimen.label]})
    for layout, d in dirs.items():
        index = [f"{f['file']},{f['test']},{f['layers']},{f['bias_V']:.0f},{';'.join(f['specimens'])}"
                 for f in files[layout]]
        _write(d / "files.csv", ("file", "test", "layers", "bias_V", "specimens"), index)
    truth.effect_observables(case)
    return truth.manifest_entry(case, [d.notes for _, d in results], files)


def _finite(obj: Any) -> Any:
    """JSON has no infinity: non-finite floats become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def generate(seed: int, n_cases: int, out: Path, progress: bool = True) -> Path:
    """Cases seed, seed + 1, ..., seed + n_cases - 1 into `out`; the manifest is merged with an existing one
    (a case id is its seed, so regenerating a case replaces its entry)."""
    out.mkdir(parents=True, exist_ok=True)
    manifest_path = out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {"cases": {}}
    manifest["generator"] = "benchmarks.external_lab"
    manifest["layouts"] = {"cases": "specimen column, several specimens per file",
                           "cases-per-specimen": "one specimen per file, no specimen column"}
    for s in range(seed, seed + n_cases):
        t0 = time.perf_counter()
        case = draw_case(s)
        manifest["cases"][case.case_id] = _finite(write_case(case, out))
        if progress:
            names = ", ".join(e["name"] for e in case.effects) or "-"
            print(f"{case.case_id}: {case.kind:6s} {names:50s} layers {case.layers} "
                  f"{len(manifest['cases'][case.case_id]['files']['cases'])} files "
                  f"({time.perf_counter() - t0:.1f} s)", flush=True)
    manifest_path.write_text(json.dumps(manifest, indent=1, sort_keys=True))
    return manifest_path
