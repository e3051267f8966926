"""Another lab's recordings, end to end, as a user would run them: every CSV through `hamr-bench import trace FILE
--protocol actuator --layers N --out X.mcap`, then `hamr-bench gap DIR --json` (and fit, report, replay, compare).
The CSVs come from tests/analysis/lab_traces.py, a generator that shares no code or formula with analysis/ (the
same paper's physics written out again): drive timings unlike the project's defaults, a lagging and overshooting
monitor, three specimens per file, one file per test and voltage, a force sensor that only reads push."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hamr_bench.cli import main
from tests.analysis.lab_traces import Effects, Lab, LabFile, Specimen, per_volt, specimen_rows

SPECIMENS = (Specimen("A", 1.0), Specimen("B", 1.04), Specimen("C", 0.97))
VOLTS = (100.0, 150.0, 200.0)


def write_session(directory, lab: Lab, effects: Effects, seed: int, specimens=SPECIMENS, layers: int = 2,
                  tests=("blocked", "free"), volts=VOLTS) -> list:
    """One CSV per test x V_bias, each with every specimen's rows (its own time from 0), imported one by one."""
    rng = np.random.default_rng(seed)
    offsets = {sp.label: rng.normal(0.0, 2e-3) for sp in specimens}   # each specimen's mount: one force offset
    out = []
    for test in tests:
        for v in volts:
            lab_file = LabFile()
            for sp in specimens:
                lab_file.rows += specimen_rows(sp, layers, test, v, lab, effects, rng,
                                               force_offset_N=offsets[sp.label])
            csv_path = directory / f"{test}_{layers}x_{int(v)}V.csv"
            lab_file.write(csv_path)
            mcap = csv_path.with_suffix(".mcap")
            assert main(["import", "trace", str(csv_path), "--protocol", "actuator", "--layers", str(layers),
                         "--out", str(mcap)]) == 0
            out.append(mcap)
    return out


@pytest.fixture(scope="module")
def null_session(tmp_path_factory):
    d = tmp_path_factory.mktemp("null")
    write_session(d, Lab(), Effects(), seed=11)
    return d


def test_gap_runs_on_imported_traces_and_shows_their_provenance(null_session, capsys):
    capsys.readouterr()
    assert main(["gap", str(null_session), "--json", "--jobs", "1"]) == 0
    out = json.loads(capsys.readouterr().out)
    recordings = out["recordings"]
    # six files x three specimens: each (file, specimen) its own run, labelled
    assert len(recordings) == 18
    assert sorted({r["specimen"] for r in recordings}) == ["A", "B", "C"]
    # the default session rule: same specimen and layer count across the files given to one command
    sessions = {r["session"] for r in recordings}
    assert len(sessions) == 3 and all(r["session_rule"] == "default" for r in recordings)
    for r in recordings:
        assert r["timelines"]["drive"] == "inferred" and r["timelines"]["bias"] == "inferred"
        timing = next(iter(r["drive_timing"].values()))
        lab = Lab()
        assert timing["cycles"] == lab.cycles
        # the lab's timing, not the project's defaults (0.4 / 0.05 / 0.4 s); the monitor's lag widens a ramp
        assert timing["dwell_high_s"] == pytest.approx(lab.dwell_high_s, abs=0.02)
        assert timing["ramp_up_s"] == pytest.approx(lab.ramp_s, abs=0.02)
        assert timing["dwell_low_s"] == pytest.approx(lab.dwell_low_s, abs=0.02)
        assert timing["bias_V"] in [pytest.approx(v, rel=0.01) for v in VOLTS]


def test_the_per_volt_figures_of_the_generator_are_the_papers():
    # the independent generator reproduces Table I's effective 2-layer actuator (paper: 210 mN, 103 um at 250 V)
    c, s = per_volt(2, Specimen("x"))
    assert c * 250 == pytest.approx(0.210, rel=0.01) and s * 250 == pytest.approx(103e-6, rel=0.01)
