"""`hamr-bench gap RECORDINGS... [--params FIT.json] [--effects NAME,...] [--jobs J] [--scheduler ADDRESS] --json
[--report DIR]`: where the
recordings part from the nominal model, which candidate effect explains it, and how far it closes the gap on
held-out conditions (analysis/gap/)."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from analysis.gap.results import best_text, closed_share_text, floor_text


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("gap", help="sim-to-real gap diagnosis: where, which effect, how far it closes")
    parser.add_argument("recordings", type=Path, nargs="+", help="MCAP recordings (or directories of them)")
    parser.add_argument("--params", type=Path, help="a fit's JSON (hamr-bench fit --json) as the nominal model")
    parser.add_argument("--effects", help="candidate effects to consider, comma-separated (default: all)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write the residual map, overlays and ranking")
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")
    parser.add_argument("--jobs", type=int, default=None,
                        help="processes reading the recordings and fitting the candidates side by side (default: "
                             "one per core; 1: this process; the result does not depend on it)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="read the recordings on a Dask cluster (tcp://HOST:8786; needs the 'dask' extra)")
    parser.set_defaults(func=run)


def load_params(path: Path | None) -> dict | None:
    from hamr_bench.errors import ConfigError

    if path is None:
        return None
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(f"--params {path}: cannot read ({exc.strerror})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConfigError(f"--params {path}: not JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, dict) or not ({"actuators", "designs"} & set(data)):
        raise ConfigError(f"--params {path}: expected the object `hamr-bench fit --json` prints "
                          f"(keys 'actuators' and/or 'designs')")
    return data


def format_text(result: dict) -> str:
    """The JSON result (`Diagnosis.to_json`) as a few lines for a terminal."""
    lack = result["nominal_lack_of_fit"]
    lines = [f"note: {n}" for n in result.get("notes", [])]
    lines += [f"gap above noise: {'yes' if result['gap_above_noise'] else 'no'} (lack-of-fit p = "
              f"{lack['p_value']:.3g}, RMS gap {lack['z_rms']:.2f} x noise, after fitting each specimen within its "
              "tolerances)", "", "where (largest first):"]
    for g in result["where"][:8]:
        lines.append(f"  {g['protocol']:18s} {g['condition']:40s} gap {g['rms_gap']:.3g} vs noise "
                     f"{g['noise_floor']:.3g} ({g['quantity']}), p = {g['p_value']:.2g}")
    lines += ["", "waterfall (held-out RMS gap, noise units; 1 = the noise floor):"]
    for w in result["waterfall"]:
        label = "nominal" if w["added"] is None else f"+ {w['added']}"
        amb = f" (or {', '.join(w['ambiguous_with'])})" if w["ambiguous_with"] else ""
        lines.append(f"  {label:30s} {w['heldout_rms']:.2f} [{w['heldout_rms_ci95'][0]:.2f}, "
                     f"{w['heldout_rms_ci95'][1]:.2f}]{amb}")
    lines += ["", "named effects:"]
    for e in result["named"]:
        ci = e["strength_ci95"]
        lines.append(f"  {e['effect']:22s} {e['verdict']:16s} strength {e['strength']:.4g} [{ci[0]:.4g}, {ci[1]:.4g}] "
                     f"{e['unit']}; closes {closed_share_text(e['closed_fraction'], ' of the held-out gap')}"
                     + (f"; confusable with {', '.join(e['confusable_with'])}" if e["confusable_with"] else ""))
        lines += [f"      {n}" for n in e.get("notes", [])]
    if not result["named"]:
        lines.append("  none")
    for c in result["cannot_separate"]:
        lines.append(f"  cannot separate {', '.join(c['effects'])}: "
                     + "; ".join(f"{k}: {v}" for k, v in c["separated_by"].items() if v))
    if result.get("turned_down"):
        lines += ["", "tried next, none passing:"]
        lines += [f"  {c['effect']:22s} {c['why']}" for c in result["turned_down"]]
    rest = result["unexplained"]
    lines += ["", f"left unexplained: held-out RMS {rest['heldout_rms']:.2f} x noise" + floor_text(rest),
              f"best: {best_text(result)}"]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from analysis.gap.diagnose import diagnose
    from analysis.gap.families import check_names
    from analysis.gap.features import load_gap_data

    from hamr_bench.errors import ConfigError

    jobs = args.jobs if args.jobs is not None else (os.cpu_count() or 1)
    if jobs < 1:
        raise ConfigError(f"--jobs: expected at least 1, got {args.jobs}")
    names = check_names(args.effects.split(",")) if args.effects else None
    params = load_params(args.params)
    data = load_gap_data(args.recordings, jobs=args.jobs, scheduler=args.scheduler)
    diagnosis = diagnose(data, params, names, seed=args.seed, jobs=jobs)
    out = diagnosis.to_json()
    out["nominal_source"] = f"fit {args.params}" if args.params else "the presets the recordings name"
    out["notes"] = data.specimen_notes()
    if args.report:
        from analysis.gap.report import write_report

        out["report"] = str(write_report(diagnosis, out, args.report))
    print(json.dumps(out, indent=1, default=float) if args.json else format_text(out))
    return 0
