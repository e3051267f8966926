"""`hamr-bench info` and `hamr-bench recover` through `hamr_bench.cli.main`."""

from __future__ import annotations

import json

import pytest

from hamr_bench.cli import main
from hamr_bench.recording import Recorder, RecordingReader


@pytest.fixture()
def recording(tmp_path):
    path = tmp_path / "run.mcap"
    with Recorder(path) as rec:
        rec.add_metadata("protocol", {"name": "sag-sweep", "parameters": "{}"})
        rec.add_metadata("rig", {"path": "rigs/bench.toml", "text": "x" * 500})
        for k in range(1001):
            rec.write_scalar("/force", k * 1e-3, force_N=0.0)
        for k in range(11):
            rec.write_scalar("/stage/position", k * 0.1, position_m=0.0)
        rec.flush()
        rec.close("aborted", "interrupted (Ctrl-C)")
    return path


def test_info_text_shows_counts_rates_span_exit_and_crc(recording, capsys):
    assert main(["info", str(recording)]) == 0
    out = capsys.readouterr().out
    assert "complete" in out and "CRC check: ok" in out
    assert "exit status: aborted - interrupted (Ctrl-C)" in out
    force_line = next(line for line in out.splitlines() if line.strip().startswith("/force"))
    assert "1001" in force_line and "1000.0 Hz" in force_line and "1.000 s" in force_line
    stage_line = next(line for line in out.splitlines() if line.strip().startswith("/stage/position"))
    assert "11" in stage_line and "10.0 Hz" in stage_line
    assert 'name="sag-sweep"' in out and 'path="rigs/bench.toml"' in out
    assert "x" * 100 not in out  # the rig text is not dumped


def test_info_json(recording, capsys):
    assert main(["info", str(recording), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["exit_status"] == "aborted" and summary["crc"]["result"] == "ok"
    topics = {t["topic"]: t for t in summary["topics"]}
    assert topics["/force"]["messages"] == 1001 and topics["/force"]["rate_Hz"] == pytest.approx(1000.0)
    assert summary["time_span_s"] == pytest.approx([0.0, 1.0])
    assert summary["metadata"]["rig"]["text"] == "x" * 500


def test_info_on_a_truncated_file_says_partial_and_exits_1(recording, tmp_path, capsys):
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(recording.read_bytes()[: recording.stat().st_size // 2])
    assert main(["info", str(cut)]) == 1
    out = capsys.readouterr().out
    assert "PARTIAL" in out and "unknown (no run_end record" in out


def test_info_on_a_corrupted_file_reports_the_crc_failure(tmp_path, capsys):
    path = tmp_path / "plain.mcap"
    with Recorder(path, compression="none") as rec:  # uncompressed: the damaged chunk still parses without CRCs
        for k in range(1001):
            rec.write_scalar("/force", k * 1e-3, force_N=0.0)
    data = bytearray(path.read_bytes())
    data[len(data) // 3] ^= 0xFF  # inside the one chunk's messages
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    assert main(["info", str(bad)]) == 1
    out = capsys.readouterr().out
    assert "CRC check: FAILED" in out and "chunk CRC mismatch" in out
    assert "/force" in out  # still summarised from the unvalidated read


def test_info_on_a_non_recording_is_a_one_line_error(tmp_path, capsys):
    junk = tmp_path / "notes.txt"
    junk.write_text("hello")
    assert main(["info", str(junk)]) == 2
    err = capsys.readouterr().err
    assert err == f"hamr-bench: error: {junk} is not an MCAP recording (bad magic bytes at the start)\n"


def test_recover_cli_writes_a_valid_file_and_refuses_to_overwrite(recording, tmp_path, capsys):
    cut = tmp_path / "killed.mcap"
    cut.write_bytes(recording.read_bytes()[: int(recording.stat().st_size * 0.6)])
    out = tmp_path / "fixed.mcap"
    assert main(["recover", str(cut), "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "recovered" in text and "exit_status=" in text
    reader = RecordingReader(out)
    assert not reader.partial and reader.metadata()["run_end"]["recovered"] == "true"
    before = out.read_bytes()
    assert main(["recover", str(cut), "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(["recover", str(cut), "-o", str(out), "--force"]) == 0
    assert main(["recover", str(out), "-o", str(out), "--force"]) == 2  # never onto its own source
