"""The benchmark harness runs (quick mode, one cheap benchmark) and prints one JSON object of well-formed records.
Only the shape and the internal consistency of the records are checked: speed is never asserted in tests."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

from benchmarks.__main__ import record

ROOT = Path(__file__).resolve().parents[2]
FIELDS = {"name", "value", "unit", "baseline", "ratio", "goal", "met"}


def test_quick_model_benchmark_emits_valid_json_records():
    proc = subprocess.run([sys.executable, "-m", "benchmarks", "--quick", "--only", "model", "--json"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)  # the whole of stdout is one JSON object
    assert out["quick"] is True and out["errors"] == {}
    assert {"cpus", "load_average_before", "load_average_after"} <= set(out["machine"])
    (rec,) = out["records"]
    assert set(rec) >= FIELDS
    assert rec["name"] == "model.leg_conditions_per_s" and rec["unit"] == "conditions/s"
    assert rec["value"] > 0 and rec["baseline"] > 0
    assert math.isclose(rec["ratio"], rec["value"] / rec["baseline"], rel_tol=1e-9)
    assert rec["goal"] == {"on": "value", "op": ">=", "target": 1e5}
    assert rec["met"] is (rec["value"] >= 1e5)


def test_unknown_benchmark_is_refused_in_one_line():
    proc = subprocess.run([sys.executable, "-m", "benchmarks", "--only", "nosuch"], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.strip().count("\n") == 0 and "nosuch" in proc.stderr


def test_met_follows_the_goal():
    g = {"on": "ratio", "op": "<=", "target": 1.5}
    assert record("x", 1.0, "px", 1.0, ratio=1.4, goal_=g)["met"] is True
    assert record("x", 1.0, "px", 1.0, ratio=1.6, goal_=g)["met"] is False
    assert record("x", None, "px", goal_=g)["met"] is None  # not measured: no verdict
    assert record("x", 3.0, "s")["met"] is None  # no goal: no verdict
    assert record("x", 0, "samples", goal_={"on": "value", "op": "==", "target": 0})["met"] is True
