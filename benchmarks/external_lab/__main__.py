"""`python3 -m benchmarks.external_lab generate --seed S --cases N --out DIR` and
`python3 -m benchmarks.external_lab score DIR [--layout cases|cases-per-specimen] [--work DIR] [--root DIR]
[--case ID ...] [--timeout S]`: make another lab's actuator data, and score hamr-bench's gap diagnosis on
it."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python3 -m benchmarks.external_lab", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    gen = sub.add_parser("generate", help="write cases (CSV files) and their manifest (the truth)")
    gen.add_argument("--seed", type=int, required=True, help="first case seed (case k uses seed + k)")
    gen.add_argument("--cases", type=int, default=20, help="number of cases (default 20)")
    gen.add_argument("--out", type=Path, required=True, help="output directory")
    sc = sub.add_parser("score", help="import and diagnose every case as a user would; compare")
    sc.add_argument("dir", type=Path, help="a directory written by `generate`")
    sc.add_argument("--layout", choices=("cases", "cases-per-specimen"), default="cases",
                    help="files with a specimen column (default) or one specimen per file")
    sc.add_argument("--work", type=Path, help="where the imported recordings go (default DIR/work-LAYOUT)")
    sc.add_argument("--root", type=Path, help="hamr-bench checkout to run (default: this one)")
    sc.add_argument("--case", action="append", help="score only this case id (repeatable)")
    sc.add_argument("--timeout", type=float, default=1800.0, help="seconds per hamr-bench command")
    args = parser.parse_args(argv)
    if args.command == "generate":
        from benchmarks.external_lab.generate import generate

        if args.cases < 1:
            parser.error(f"--cases: expected at least 1, got {args.cases}")
        print(f"manifest: {generate(args.seed, args.cases, args.out)}")
        return 0
    from benchmarks.external_lab.score import ROOT, score

    if not (args.dir / "manifest.json").is_file():
        parser.error(f"{args.dir}: no manifest.json (write the cases with `generate` first)")
    score(args.dir, args.layout, args.work, (args.root or ROOT).resolve(), args.case, args.timeout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
