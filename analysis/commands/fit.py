"""`hamr-bench fit RECORDINGS...`: fit the actuator (Table I's five, per layer count) and each design's transmission
(k_ser, kappa_1..3, bias) to recordings, with 95 % intervals and identifiability warnings (analysis/fit.py)."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("fit", help="fit actuator and transmission parameters to recordings")
    parser.add_argument("recordings", type=Path, nargs="+", help="MCAP recordings (or directories of them)")
    parser.add_argument("--method", choices=("nelder-mead", "least-squares"), default="least-squares",
                        help="the paper's RMS cost with Nelder-Mead, or bounded least squares (default)")
    parser.add_argument("--actuator", choices=("recording", "fit"), default="recording",
                        help="actuator used in the transmission fit: the one the leg recordings name (default) "
                             "or the one fitted from actuator recordings of the same layer count")
    parser.add_argument("--no-intervals", action="store_true", help="point estimates only (skip the profiles)")
    parser.add_argument("--json", action="store_true", help="print the result as JSON")
    parser.add_argument("--jobs", type=int, default=None,
                        help="local worker processes for the independent group fits (default: one per core)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the group fits on a Dask cluster (tcp://HOST:8786; needs the 'dask' extra)")
    parser.set_defaults(func=run)


def format_report(report) -> str:
    lines = [f"method: {report.method}"]
    for title, groups in (("actuator", report.actuators), ("design", report.designs)):
        for key, g in sorted(groups.items()):
            rms = []
            if g.rms_N is not None:
                rms.append(f"rms {g.rms_N * 1e3:.3g} mN")
            if g.rms_m is not None:
                rms.append(f"rms {g.rms_m * 1e6:.3g} um")
            label = f"{key} layer(s)" if title == "actuator" else str(key)
            lines.append(f"\n{title} {label}: {g.n_observations} observations, {', '.join(rms)}")
            for p in g.params.values():
                ci = "" if p.ci95 is None else f"  [{p.ci95[0]:.4g}, {p.ci95[1]:.4g}]"
                lines.append(f"  {p.name:8s} {p.value:.4g} {p.unit}{ci}  {p.status}")
            for name, d in g.derived.items():
                if isinstance(d, dict) and "ci95" in d:
                    lines.append(f"  {name}: {d['value']:.4g} {d['unit']}  [{d['ci95'][0]:.4g}, {d['ci95'][1]:.4g}]")
            for w in g.warnings:
                lines.append(f"  warning: {w}")
    for w in report.warnings:
        lines.append(f"warning: {w}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from analysis.dataset import load_dataset
    from analysis.fit import fit_dataset

    dataset = load_dataset(args.recordings)
    report = fit_dataset(dataset, args.method, intervals=not args.no_intervals, actuator_source=args.actuator,
                         jobs=args.jobs, scheduler=args.scheduler)
    print(report.to_json() if args.json else format_report(report))
    return 0
