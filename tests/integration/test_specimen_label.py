"""A native run names its specimen (`hamr-bench run --specimen`), and the gap diagnosis's readers keep differently
labelled recordings apart, while unlabelled recordings from several files are pointed out (they share one
specimen's gains)."""

from __future__ import annotations

import pytest

from analysis.gap.features import load_gap_data
from hamr_bench.cli import main
from hamr_bench.recording import RecordingReader
from hamr_bench.recording.info import format_summary, summarise

QUICK = ["--set", "repetitions=1", "--set", "voltages_V=150", "--set", "drive.cycles=1", "--set", "drive.slow_ramp_s=0"]


def _run(path, *extra: str) -> None:
    assert main(["run", "actuator", "--sim", "--quiet", "--out", str(path), *QUICK, *extra]) == 0


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("specimens")
    paths = {"A7": d / "a7.mcap", "B2": d / "b2.mcap", "": d / "none.mcap", "again": d / "none2.mcap"}
    _run(paths["A7"], "--specimen", "A7")
    _run(paths["B2"], "--specimen", "B2", "--seed", "1")
    _run(paths[""])
    _run(paths["again"], "--seed", "2")
    return paths


def test_every_step_carries_the_label(recordings):
    steps = [e for e in RecordingReader(recordings["A7"]).events() if e.kind == "step"]
    assert steps and all(e.data["specimen"] == "A7" for e in steps)
    unlabelled = [e for e in RecordingReader(recordings[""]).events() if e.kind == "step"]
    assert unlabelled and all("specimen" not in e.data for e in unlabelled)
    # `hamr-bench info` shows it
    assert summarise(recordings["A7"])["specimens"] == ["A7"]
    assert "specimens: A7" in format_summary(summarise(recordings["A7"]))
    assert summarise(recordings[""])["specimens"] == []


def test_labelled_recordings_are_separate_specimens(recordings):
    data = load_gap_data([recordings["A7"], recordings["B2"]])
    assert sorted({r.specimen for r in data.runs}) == ["A7", "B2"]
    assert data.specimen_notes() == []


def test_unlabelled_recordings_from_several_files_are_pointed_out(recordings):
    (note,) = load_gap_data([recordings[""], recordings["again"], recordings["A7"]]).specimen_notes()
    assert note.startswith("2 actuator recordings of the 2-layer actuator name no specimen")
    assert "--specimen" in note
    assert load_gap_data([recordings[""]]).specimen_notes() == []


def test_a_label_with_a_line_break_is_refused(tmp_path, capsys):
    assert main(["run", "actuator", "--sim", "--quiet", "--out", str(tmp_path / "x.mcap"),
                 "--specimen", "A\nB"]) != 0
    err = capsys.readouterr().err
    assert "--specimen" in err and "Traceback" not in err
    assert not (tmp_path / "x.mcap").exists()
