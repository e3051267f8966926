"""`hamr-bench demo`: the product end to end on the simulated bench. A campaign with realistic effects switched on,
then every analysis step that exists (fit, report, replay and compare, gap diagnosis), each run through the same
command-line entry points a user would type, ending with where to look at the results."""

from __future__ import annotations

import argparse
import shutil
import time
from pathlib import Path

from hamr_bench.cli import declared_commands

# The "real" bench of the demo: the simulated bench with an effect the nominal model lacks.
DEMO_EFFECTS = "hysteresis=0.12"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("demo", help="run a simulated campaign and the analysis steps, end to end")
    parser.add_argument("--out", type=Path, default=Path("demo-out"), help="output folder (default: demo-out)")
    parser.add_argument("--effects", default=DEMO_EFFECTS,
                        help=f"effects of the simulated 'real' bench (default {DEMO_EFFECTS})")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--quiet", action="store_true", help="no progress bars")
    parser.set_defaults(func=run)


def _available(command: str) -> bool:
    """The command is declared (its module lives in whichever package it drives)."""
    return command in declared_commands()


def run(args: argparse.Namespace) -> int:
    from hamr_bench.cli import main

    out: Path = args.out
    if out.exists():
        shutil.rmtree(out)  # the demo's own folder: always a fresh run
    out.mkdir(parents=True)
    campaign = out / "campaign"
    quiet = ["--quiet"] if args.quiet else []
    looks: list[str] = []

    def shown(argv: list[str]) -> str:
        """The command as a person would type it: the campaign's files as one glob."""
        files = [a for a in argv if a.startswith(str(campaign)) and a.endswith(".mcap")]
        if len(files) > 1:
            argv = [a for a in argv if a not in files[1:]]
            argv[argv.index(files[0])] = f"{campaign}/*.mcap"
        return " ".join(a if a else "''" for a in argv)

    def step(title: str, argv: list[str]) -> bool:
        print(f"\n== {title}\n$ hamr-bench {shown(argv)}", flush=True)
        start = time.perf_counter()
        code = main(argv)
        print(f"   ({time.perf_counter() - start:.1f} s, exit {code})", flush=True)
        return code == 0

    print(f"hamr-bench demo: a simulated bench with {args.effects} plays the real rig.")
    if not step("1. The paper's test matrix on the simulated bench",
                ["campaign", "--sim", "--effects", args.effects, "--seed", str(args.seed), "--out", str(campaign),
                 *quiet]):
        return 1
    recordings = sorted(str(p) for p in campaign.glob("*.mcap"))
    looks.append(f"{campaign}/  one MCAP recording per run (open in Foxglove, or `hamr-bench info FILE`)")
    step("2. What one recording holds", ["info", recordings[0]])

    if _available("paper"):
        step("3. The model against the paper's claims", ["paper"])
    else:
        print("\n== 3. paper reproduction: not built yet")
    if _available("fit"):
        fit_json = out / "fit.json"
        print("\n== 4. Fit the model's parameters to the recordings")
        argv = ["fit", *recordings, "--json"]
        print(f"$ hamr-bench {shown(argv)} > {fit_json}")
        import contextlib
        import io

        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            main(argv)
        fit_json.write_text(buffer.getvalue())
        looks.append(f"{fit_json}  fitted parameters with 95 % intervals")
    else:
        print("\n== 4. fit: not built yet")
    if _available("report"):
        if step("5. Figures and summary", ["report", *recordings, "--out", str(out / "report")]):
            looks.append(f"{out / 'report'}/  the paper's figures from these data, and a summary")
    else:
        print("\n== 5. report: not built yet")
    if _available("replay") and _available("compare"):
        source = next((r for r in recordings if "blocked-force" in r), recordings[0])
        twin = out / "twin.mcap"
        # No effects and another seed: the twin is what the nominal model predicts under the same commands.
        if step("6. Replay one run through the nominal simulated bench",
                ["replay", source, "--out", str(twin), "--effects", "", "--seed", str(args.seed + 1), *quiet]):
            step("   ... and compare the two", ["compare", source, str(twin), "--plots", str(out / "compare")])
            looks.append(f"{out / 'compare'}/  the recording overlaid on its nominal-model twin")
    else:
        print("\n== 6. replay and compare: not built yet")
    if _available("gap"):
        if step("7. Where the model and the 'real' bench part, and why",
                ["gap", *recordings, "--report", str(out / "gap")]):
            looks.append(f"{out / 'gap'}/  residual map, the effects named (if any), and how far they close the gap")
    else:
        print("\n== 7. gap diagnosis: not built yet")

    print("\nWhere to look:")
    for line in looks:
        print(f"  {line}")
    return 0
