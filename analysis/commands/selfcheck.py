"""`hamr-bench selfcheck [--trials N] [--seed S] [--jobs J] [--specimens K] [--layers 1,2,3] --json`: the gap
diagnosis checked blind on the simulated bench (hidden effect of random type and realistic strength, null cases, decoys;
analysis/gap/selfcheck.py)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

TRIAL_SPECIMENS = 3   # as analysis.gap.selfcheck.TRIAL_SPECIMENS (not imported here: that module is heavy)
TRIAL_LAYERS = "2"    # as analysis.gap.selfcheck.TRIAL_LAYERS


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("selfcheck", help="blind check of the gap diagnosis on the simulated bench")
    parser.add_argument("--trials", type=int, default=20, help="number of blind trials (default 20)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the trial draws (default 0)")
    parser.add_argument("--jobs", type=int, default=1, help="trials run in parallel processes (default 1)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the trials on a Dask cluster (tcp://HOST:8786; needs the 'dask' extra)")
    parser.add_argument("--null-fraction", type=float, default=0.15, help="share of no-effect trials")
    parser.add_argument("--decoy-fraction", type=float, default=0.1, help="share of decoy trials")
    parser.add_argument("--specimens", type=int, default=TRIAL_SPECIMENS,
                        help=f"specimens built per trial, each with its own fabrication scatter (default "
                             f"{TRIAL_SPECIMENS}; a common shift's detection limit falls as 1 / sqrt(specimens))")
    parser.add_argument("--layers", default=TRIAL_LAYERS, metavar="N,N,...",
                        help=f"layer counts a trial builds --specimens of each of (default {TRIAL_LAYERS}; e.g. 1,2,3: "
                             "one CSV per test x layer count x V_bias; the draw's effects refer to 2 layers)")
    parser.add_argument("--raw", type=Path, metavar="FILE",
                        help="append each trial's result to FILE as it ends (JSON lines; a long run stopped part way "
                             "keeps its trials: score them with analysis.gap.selfcheck.score_raw)")
    parser.add_argument("--json", action="store_true", help="print the scores as JSON")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hamr_bench.errors import ConfigError

    if args.trials < 1:
        raise ConfigError(f"--trials: expected at least 1, got {args.trials}")
    if args.specimens < 1:
        raise ConfigError(f"--specimens: expected at least 1, got {args.specimens}")
    if not (args.null_fraction >= 0 and args.decoy_fraction >= 0 and args.null_fraction + args.decoy_fraction <= 1):
        raise ConfigError("--null-fraction and --decoy-fraction: expected shares in [0, 1] summing to at most 1")
    layer_counts = _layer_counts(args.layers)
    if args.raw is not None and not args.raw.parent.is_dir():
        raise ConfigError(f"--raw {args.raw}: the folder {args.raw.parent} does not exist")
    from analysis.gap.selfcheck import selfcheck

    out = selfcheck(trials=args.trials, seed=args.seed, jobs=max(1, args.jobs), null_fraction=args.null_fraction,
                    decoy_fraction=args.decoy_fraction, progress=not args.json, scheduler=args.scheduler,
                    raw_path=str(args.raw) if args.raw else None, specimens=args.specimens,
                    layer_counts=layer_counts)
    if args.json:
        print(json.dumps(out, indent=1, default=float))
    else:
        summary = {k: v for k, v in out.items() if k not in ("per_trial", "confusion")}
        for k, v in summary.items():
            print(f"{k}: {v}")
    return 0


def _layer_counts(text: str) -> tuple[int, ...]:
    from hamr_bench.errors import ConfigError

    try:
        counts = tuple(int(x) for x in text.split(","))
    except ValueError:
        counts = ()
    if not counts or min(counts) < 1 or max(counts) > 3 or len(set(counts)) != len(counts):
        raise ConfigError(f"--layers {text!r}: expected distinct layer counts 1-3, comma-separated (e.g. 1,2,3)")
    return tuple(sorted(counts))
