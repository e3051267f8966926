"""Reader benchmark: the time to open a recording with `RecordingReader` (the whole data section scanned, every CRC
checked), through the message indexes (the default) and record by record (`use_message_indexes=False`, the path
every open took before), on the same files in the same run.

Each protocol (blocked-force, sag-sweep, free-displacement with the camera, actuator with the camera) is recorded
once on the simulated bench; each file is then opened `--repeats` times each way, alternating, and the best wall
time of each is printed, with the file's size, messages and chunks. Opening is ~10 % of a replay's wall time (issue
6), so this is a piece of the replay-speed budget.

Run: `python -m benchmarks.bench_reader [--repeats 3] [--quick] [--json]`. Other load on the machine lowers the
figures: the printed load average says how busy it was.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path

from hamr_bench.protocols.session import RunRequest, run_protocol
from hamr_bench.recording import RecordingReader

CASES: dict[str, list[str]] = {"blocked-force": [], "sag-sweep": [], "free-displacement": [], "actuator": []}
QUICK = {"blocked-force": ["repetitions=2"], "sag-sweep": ["repetitions=1"], "free-displacement": ["repetitions=1"],
         "actuator": ["repetitions=1"]}


def time_open(path: Path, repeats: int) -> dict:
    best = {True: float("inf"), False: float("inf")}
    for _ in range(repeats):
        for indexed in (True, False):
            t0 = time.perf_counter()
            reader = RecordingReader(path, use_message_indexes=indexed)
            best[indexed] = min(best[indexed], time.perf_counter() - t0)
    return {
        "size_MB": path.stat().st_size / 1e6,
        "messages": sum(t.message_count for t in reader.topics().values()),
        "chunks": reader.status.chunks,
        "indexed_open_s": best[True],
        "plain_open_s": best[False],
        "speedup_x": best[False] / best[True],
    }


def run(quick: bool = False, repeats: int = 3, files: list[Path] | None = None) -> dict:
    rows = []
    if files:
        rows = [{"recording": str(path), **time_open(path, repeats)} for path in files]
    else:
        cases = QUICK if quick else CASES
        with tempfile.TemporaryDirectory() as tmp:
            for protocol, options in cases.items():
                path = Path(tmp) / f"{protocol}.mcap"
                run_protocol(RunRequest(protocol=protocol, out=path, set_options=options, seed=1, overwrite=True))
                rows.append({"recording": protocol, "options": options, **time_open(path, repeats)})
    return {
        "load_average_1min": os.getloadavg()[0], "cpus": os.cpu_count(), "repeats": repeats, "rows": rows,
        "total_indexed_open_s": sum(r["indexed_open_s"] for r in rows),
        "total_plain_open_s": sum(r["plain_open_s"] for r in rows),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="shorter protocols")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("files", nargs="*", type=Path, help="time these recordings instead of recording new ones")
    args = parser.parse_args(argv)
    result = run(args.quick, args.repeats, args.files or None)
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"RecordingReader open, best of {args.repeats} (load average {result['load_average_1min']:.2f} on "
          f"{result['cpus']} CPUs)")
    print(f"{'recording':<20} {'MB':>7} {'messages':>9} {'chunks':>6} {'indexed s':>10} {'plain s':>9} {'x':>6}")
    for r in result["rows"]:
        print(f"{Path(r['recording']).stem:<20} {r['size_MB']:7.1f} {r['messages']:9d} {r['chunks']:6d} "
              f"{r['indexed_open_s']:10.4f} {r['plain_open_s']:9.4f} {r['speedup_x']:6.2f}")
    print(f"{'total':<45} {result['total_indexed_open_s']:10.4f} {result['total_plain_open_s']:9.4f} "
          f"{result['total_plain_open_s'] / result['total_indexed_open_s']:6.2f}")


if __name__ == "__main__":
    main()
