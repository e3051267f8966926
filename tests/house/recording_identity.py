"""Check that a change keeps recordings bit-identical: record a fixed set of runs (every protocol, a fault, effects,
serial traffic, replays) with fixed seeds from one source tree, then compare two such sets topic by topic.

    python3 tests/house/recording_identity.py record OUT_DIR [--tree SOURCE_TREE]
    python3 tests/house/recording_identity.py compare DIR_A DIR_B

`--tree` records with another checkout's code (e.g. `git archive main | tar -x -C /tmp/base`), so a branch can be
compared with the main it started from. Not a test (it needs two versions of the code); a refactor that must not
change recordings runs it before it lands. Every message (topic, log time, publish time, payload bytes) and every
metadata record must agree, except the keys that name when or where a run was made (`IGNORED_METADATA`).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
from pathlib import Path

# (name, command-line arguments after `hamr-bench`); {out} is the recording, {src} a recording named in the list.
SHORT = ["--set", "repetitions=1", "--set", "drive.cycles=2"]
RUNS: list[tuple[str, list[str]]] = [
    ("actuator", ["run", "actuator", "--sim", "--seed", "3", *SHORT, "--set", "voltages_V=100,250"]),
    ("blocked-force", ["run", "blocked-force", "--sim", "--seed", "4", "--design", "2", *SHORT,
                       "--effects", "hysteresis=0.12,creep=0.02"]),
    ("sag-sweep", ["run", "sag-sweep", "--sim", "--seed", "5", *SHORT, "--set", "sags_m=0,0.001,0.002"]),
    ("free-displacement", ["run", "free-displacement", "--sim", "--seed", "6", *SHORT,
                           "--set", "voltages_V=100,250"]),
    ("static", ["run", "static", "--sim", "--seed", "7", "--effects", "stage_backlash=2e-5,sensor_drift=3e-5"]),
    ("traffic", ["run", "blocked-force", "--sim", "--seed", "8", *SHORT, "--set", "voltages_V=150",
                 "--record-traffic"]),
    ("fault", ["run", "blocked-force", "--sim", "--seed", "9", *SHORT, "--fault", "stage:following_error@12"]),
    # seed 5 with this drift: the contact search measures from a drifted baseline (its contact_found has baseline_N)
    ("drift", ["run", "blocked-force", "--sim", "--seed", "5", "--set", "repetitions=1", "--set", "drive.cycles=1",
               "--set", "voltages_V=250", "--effects", "sensor_drift=8e-5"]),
    ("replay-actuator", ["replay", "{dir}/actuator.mcap"]),
    ("replay-blocked-force", ["replay", "{dir}/blocked-force.mcap"]),
    ("replay-static", ["replay", "{dir}/static.mcap"]),
    ("replay-free-displacement", ["replay", "{dir}/free-displacement.mcap"]),
    ("replay-drift", ["replay", "{dir}/drift.mcap"]),
    ("replay-traffic", ["replay", "{dir}/traffic.mcap", "--serve-traffic"]),
]
FIXED_START_NS = 1_700_000_000_000_000_000
# Metadata that says when or where a run was made, not what it recorded.
IGNORED_METADATA = {("run", "started_utc"), ("replay", "source"), ("replay", "source_sha256"), ("rig", "path")}


def record(out_dir: Path) -> None:
    from unittest import mock

    from hamr_bench.cli import main

    out_dir.mkdir(parents=True, exist_ok=True)
    for name, args in RUNS:
        out = out_dir / f"{name}.mcap"
        argv = [a.replace("{dir}", str(out_dir)) for a in args] + ["--out", str(out), "--force", "--quiet"]
        err = io.StringIO()
        # The recorder stamps messages from the wall clock at its start (log_time = start + rig time): a fixed
        # start makes two recordings of the same run comparable byte for byte.
        with contextlib.redirect_stderr(err), mock.patch("time.time_ns", return_value=FIXED_START_NS):
            code = main(argv)
        print(f"{name}: exit {code} {err.getvalue().strip()}")


def _contents(path: Path) -> tuple[dict[str, list[tuple[int, int, bytes]]], dict[str, dict[str, str]]]:
    from mcap.reader import make_reader

    topics: dict[str, list[tuple[int, int, bytes]]] = {}
    with path.open("rb") as f:
        reader = make_reader(f)
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            topics.setdefault(channel.topic, []).append((message.log_time, message.publish_time, bytes(message.data)))
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return topics, metadata


def compare(a_dir: Path, b_dir: Path) -> bool:
    same = True
    for name, _args in RUNS:
        a_topics, a_meta = _contents(a_dir / f"{name}.mcap")
        b_topics, b_meta = _contents(b_dir / f"{name}.mcap")
        problems = [f"topic {t}: {len(a_topics.get(t, []))} vs {len(b_topics.get(t, []))} messages"
                    + ("" if len(a_topics.get(t, [])) != len(b_topics.get(t, [])) else ", contents differ")
                    for t in sorted(set(a_topics) | set(b_topics)) if a_topics.get(t) != b_topics.get(t)]
        for record_name in sorted(set(a_meta) | set(b_meta)):
            a_rec, b_rec = a_meta.get(record_name, {}), b_meta.get(record_name, {})
            for key in sorted(set(a_rec) | set(b_rec)):
                if (record_name, key) not in IGNORED_METADATA and a_rec.get(key) != b_rec.get(key):
                    problems.append(f"metadata {record_name}.{key}: {a_rec.get(key)!r} vs {b_rec.get(key)!r}")
        n = sum(len(v) for v in a_topics.values())
        print(f"{name}: {'identical' if not problems else 'DIFFERENT'} ({len(a_topics)} topics, {n} messages)")
        for problem in problems:
            print(f"    {problem}")
        same = same and not problems
    return same


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("record")
    rec.add_argument("out", type=Path)
    rec.add_argument("--tree", type=Path, default=Path(__file__).resolve().parents[2])
    cmp = sub.add_parser("compare")
    cmp.add_argument("a", type=Path)
    cmp.add_argument("b", type=Path)
    args = parser.parse_args()
    if args.command == "record":
        sys.path.insert(0, str(args.tree.resolve()))
        record(args.out.resolve())
        return 0
    return 0 if compare(args.a, args.b) else 1


if __name__ == "__main__":
    sys.exit(main())
