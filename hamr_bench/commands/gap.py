"""`hamr-bench gap RECORDINGS... [--params FIT.json] [--effects NAME,...] [--jobs J] [--scheduler ADDRESS] --json
[--report DIR]`: where the
recordings part from the nominal model, which candidate effect explains it, and how far it closes the gap on
held-out conditions (analysis/gap/)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("gap", help="sim-to-real gap diagnosis: where, which effect, how far it closes")
    parser.add_argument("recordings", type=Path, nargs="+", help="MCAP recordings (or directories of them)")
    parser.add_argument("--params", type=Path, help="a fit's JSON (hamr-bench fit --json) as the nominal model")
    parser.add_argument("--effects", help="candidate effects to consider, comma-separated (default: all)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--report", type=Path, metavar="DIR", help="write the residual map, overlays and ranking")
    parser.add_argument("--seed", type=int, default=0, help="seed of the bootstrap (default 0)")
    parser.add_argument("--jobs", type=int, default=None,
                        help="processes reading the recordings (default: one per core; 1: this process)")
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
    except ValueError as exc:
        raise ConfigError(f"--params {path}: not JSON (line {exc.lineno}: {exc.msg})") from None
    if not isinstance(data, dict) or not ({"actuators", "designs"} & set(data)):
        raise ConfigError(f"--params {path}: expected the object `hamr-bench fit --json` prints "
                          f"(keys 'actuators' and/or 'designs')")
    return data


def to_json(result: dict) -> dict:
    keys = ("where", "ranking", "best", "gap_above_noise", "nominal_lack_of_fit", "phase_map", "screening",
            "signature_cos", "sensor_lag_s", "heldout_units", "elapsed_s", "recordings")
    return {k: result[k] for k in keys if k in result}


def format_text(result: dict) -> str:
    lines = [f"gap above noise: {'yes' if result['gap_above_noise'] else 'no'} "
             f"(lack-of-fit p = {result['nominal_lack_of_fit']['p_value']:.3g}, "
             f"RMS gap {result['nominal_lack_of_fit']['z_rms']:.2f} x noise)", "", "where (largest first):"]
    for g in result["where"][:8]:
        lines.append(f"  {g['protocol']:18s} {g['condition']:40s} gap {g['rms_gap']:.3g} vs noise "
                     f"{g['noise_floor']:.3g} ({g['quantity']}), p = {g['p_value']:.2g}")
    lines += ["", "ranking:"]
    for e in result["ranking"]:
        if e.get("reduction") is None:
            continue
        ci = e.get("strength_ci95")
        ci_text = f" [{ci[0]:.4g}, {ci[1]:.4g}]" if ci else ""
        strength = e["strength"] if isinstance(e["strength"], list) else f"{e['strength']:.4g}"
        lines.append(f"  {e['effect']:40s} {e['verdict']:12s} strength {strength}{ci_text} {e['unit']}; held-out "
                     f"RMS {e['heldout_rms_before']:.2f} -> {e['heldout_rms_after']:.2f} x noise, reduction "
                     f"{e['reduction']:.0%} [{e['reduction_ci95'][0]:.0%}, {e['reduction_ci95'][1]:.0%}]"
                     + (f"; confusable with {', '.join(e['confusable_with'])}" if e["confusable_with"] else ""))
    lines += ["", f"best: {result['best'] or 'none (no single effect explains the gap)'}"]
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from analysis.gap.attribution import diagnose
    from analysis.gap.features import load_gap_data
    from analysis.gap.library import check_names

    names = check_names(args.effects.split(",")) if args.effects else None
    params = load_params(args.params)
    data = load_gap_data(args.recordings, jobs=args.jobs, scheduler=args.scheduler)
    result = diagnose(data, params, names, seed=args.seed)
    # per run: its specimen, session (the nuisance grouping) and which timelines were commanded or inferred
    result["recordings"] = data.provenance()
    result["nominal_source"] = f"fit {args.params}" if args.params else "the presets the recordings name"
    if args.report:
        from analysis.gap.report import write_report

        path = write_report(result, args.report)
        result["report"] = str(path)
    out = to_json(result)
    if args.report:
        out["report"] = result["report"]
    print(json.dumps(out, indent=1, default=float) if args.json else format_text(result))
    return 0
