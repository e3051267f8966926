"""Replay benchmark: how many times faster than the recording's own duration a replay runs on this machine.

For each protocol (blocked-force and sag-sweep at the paper's defaults, free-displacement with the camera, and the
actuator protocol), a source is recorded once on the simulated bench, then replayed `--repeats` times; the figure is
the source's duration (first to last recorded time) / the best wall time of a replay (reading the source, building
the plan, building the bench, running it, closing the twin). The run that made the source is timed too, for
reference: replay re-executes through the same drivers and emulators, so it cannot be faster than the bench itself.
The goal of issue 6 is >= 50x.

Run: `python -m benchmarks.bench_replay [--repeats 3] [--quick] [--json]`. Other load on the machine lowers the
figures: the printed load average says how busy it was.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from analysis.replay import read_replay_source, replay_recording
from hamr_bench.protocols.session import RunRequest, run_protocol

CASES: dict[str, list[str]] = {
    "blocked-force": [],
    "sag-sweep": [],
    "free-displacement": [],
    "actuator": [],
}
QUICK = {"blocked-force": ["repetitions=2"], "sag-sweep": ["repetitions=1"], "free-displacement": ["repetitions=1"],
         "actuator": ["repetitions=1"]}
GOAL = 50.0


def measure(protocol: str, options: list[str], repeats: int, work: Path) -> dict:
    source = work / f"{protocol}.mcap"
    t0 = time.perf_counter()
    run_protocol(RunRequest(protocol=protocol, out=source, set_options=options, seed=1, overwrite=True))
    run_s = time.perf_counter() - t0
    duration_s = read_replay_source(source).duration_s
    best = float("inf")
    for _i in range(repeats):
        t0 = time.perf_counter()
        result, _ = replay_recording(source, work / f"{protocol}-twin.mcap", overwrite=True)
        best = min(best, time.perf_counter() - t0)
        assert result.ok, result.reason
    return {"protocol": protocol, "options": options, "recording_s": duration_s, "run_wall_s": run_s,
            "replay_wall_s": best, "replay_speed_x": duration_s / best, "run_speed_x": duration_s / run_s}


def run(quick: bool = False, repeats: int = 3) -> dict:
    """Every case recorded once and replayed `repeats` times; the summary `main` prints."""
    cases = QUICK if quick else CASES
    with tempfile.TemporaryDirectory() as tmp:
        rows = [measure(p, opts, repeats, Path(tmp)) for p, opts in cases.items()]
    total_recorded = sum(r["recording_s"] for r in rows)
    total_replay = sum(r["replay_wall_s"] for r in rows)
    return {"load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count(), "rows": rows,
            "recorded_s": total_recorded, "replay_wall_s": total_replay,
            "overall_replay_speed_x": total_recorded / total_replay, "goal_x": GOAL}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="shorter protocols (fewer repetitions)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    summary = run(args.quick, args.repeats)
    rows, total_recorded, total_replay = summary["rows"], summary["recorded_s"], summary["replay_wall_s"]
    if args.json:
        print(json.dumps(summary, indent=2))
        return 0
    print(f"replay speed = recording duration / replay wall time (best of {args.repeats}); goal >= {GOAL:g}x; "
          f"load average {summary['load_average_1min']:.1f} on {summary['cpus']} CPUs")
    print(f"{'protocol':<18} {'recorded s':>10} {'run wall s':>10} {'run x':>7} {'replay wall s':>13} {'replay x':>9}")
    for r in rows:
        print(f"{r['protocol']:<18} {r['recording_s']:>10.1f} {r['run_wall_s']:>10.2f} {r['run_speed_x']:>7.1f} "
              f"{r['replay_wall_s']:>13.2f} {r['replay_speed_x']:>9.1f}")
    print(f"overall: {total_recorded:.1f} s recorded replayed in {total_replay:.2f} s = "
          f"{summary['overall_replay_speed_x']:.1f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
