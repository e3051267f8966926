"""Bad input through the command line: what a user actually runs. (The recording library's own truncation and byte-flip
tests are tests/recording/test_bad_files.py; these add the CLI commands that read recordings, rig and protocol files
mutated at random, and CSV imports.)

- `hamr-bench info` and `hamr-bench recover` on every truncation point of a real recording and on random byte
  flips: exit code 0 (read), 1 (partial / damaged, said so) or 2 (error), at most one line on stderr, never a
  traceback; what `recover` writes reads back with CRC validation.
- rig files and protocol files with a value replaced by something of the wrong kind, a key misspelt or a line
  dropped: either the run starts (a harmless change) or one line names the file and the key.
- CSV files for `hamr-bench import` with a cell replaced, a row cut or the header damaged: a recording, or one line
  naming the file and the line.
"""

from __future__ import annotations

import contextlib
import io
import re
import warnings

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hamr_bench.cli import main
from hamr_bench.recording import RecordingReader
from hamr_bench.rig import sim_rig_path
from tests.reliability.harness import run_cli


def cli(argv: list[str]) -> tuple[int, list[str], str]:
    """main(argv) in-process: (exit code, stderr lines, stdout). An exception escaping main fails the test."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
        warnings.simplefilter("ignore")  # partial-read warnings are reported by the command itself
        code = main(argv)
    lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
    assert "Traceback" not in err.getvalue()
    return code, lines, out.getvalue()


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    """A real recording from the simulated bench, cut short by a fault: every kind of metadata, events, scalars."""
    out = tmp_path_factory.mktemp("small") / "run.mcap"
    run_cli("blocked-force", out, faults=("force_sensor:disconnect@0.9",))
    return out, out.read_bytes()


def check_read_commands(path, tmp_path, do_recover: bool) -> str:
    code, err, _ = cli(["info", str(path)])
    assert code in (0, 1, 2) and len(err) <= 1, err
    outcome = {0: "ok", 1: "partial", 2: "error"}[code]
    if do_recover:
        dst = tmp_path / "rec.mcap"
        rcode, rerr, _ = cli(["recover", str(path), "-o", str(dst), "--force"])
        assert rcode in (0, 2) and len(rerr) <= 1, rerr
        if rcode == 0:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                RecordingReader(dst, validate_crcs=True)
    return outcome


def test_info_and_recover_on_every_truncation_point(small_run, tmp_path):
    path, data = small_run
    target = tmp_path / "cut.mcap"
    outcomes = {"ok": 0, "partial": 0, "error": 0}
    step = max(1, len(data) // 250)  # every byte of a tiny file; an even spread of 250 points otherwise
    cuts = sorted(set(range(len(data) - 1, -1, -step)) | set(range(0, 40)), reverse=True)  # and the header
    for cut in cuts:
        target.write_bytes(data[:cut])
        outcomes[check_read_commands(target, tmp_path, do_recover=cut % (step * 17) == 0)] += 1
    assert outcomes["ok"] == 0, "a truncated file was reported as complete"
    assert outcomes["partial"] > 0 and outcomes["error"] > 0


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(flips=st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(1, 255)), min_size=1, max_size=4))
def test_info_and_recover_on_random_byte_flips(small_run, tmp_path, flips):
    path, data = small_run
    damaged = bytearray(data)
    for where, xor in flips:
        damaged[int(where * len(data))] ^= xor
    target = tmp_path / "flipped.mcap"
    target.write_bytes(bytes(damaged))
    outcome = check_read_commands(target, tmp_path, do_recover=True)
    assert outcome != "ok" or bytes(damaged) == data  # a flip is always noticed (CRCs everywhere)


@pytest.mark.parametrize("schema, field", [(b"hamr_bench/Event.proto", b"message"),
                                           (b"hamr_bench/Event.proto", b"kind")])
def test_info_on_a_stored_schema_whose_field_name_was_flipped(small_run, tmp_path, schema, field):
    """A schema record has no checksum: one flipped letter in a field's name still decodes, as a message without
    that field. `info` says so in one line instead of an AttributeError's traceback."""
    path, data = small_run
    start = data.index(schema)
    at = data.index(field, start)
    damaged = bytearray(data)
    damaged[at + len(field) - 1] ^= 0x01          # "message" -> "messagd": the same length, a valid name
    target = tmp_path / "schema.mcap"
    target.write_bytes(bytes(damaged))
    code, err, _ = cli(["info", str(target)])
    assert code == 2 and len(err) == 1 and "no field" in err[0], err


# ------------------------------------------------------------------------------------ rig and protocol files
RIG_LINES = [ln for ln in sim_rig_path().read_text().splitlines() if re.match(r"^[a-z_]+ *=", ln)]
BAD_VALUES = ['"text"', "-1", "1e400", "[1, 2, 3]", "{ a = 1 }", "true", "0", '""', "nan"]


def rig_variant(kind: str, line: str, value: str) -> str:
    text = sim_rig_path().read_text()
    key = line.split("=")[0].strip()
    if kind == "value":
        new = f"{key} = {value}"
    elif kind == "misspell":
        new = line.replace(key, key[:-1] + "x", 1)
    else:
        new = ""
    text = text.replace(line, new, 1)
    # the shipped file names the Nano17 calibration relative to rigs/; keep that true from the test's directory
    return text.replace('calibration_file = "../', f'calibration_file = "{sim_rig_path().parent}/../')


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(kind=st.sampled_from(["value", "misspell", "drop"]), line=st.sampled_from(RIG_LINES),
       value=st.sampled_from(BAD_VALUES))
def test_mutated_rig_file_runs_or_names_the_place_in_one_line(tmp_path, kind, line, value):
    rig = tmp_path / "mutated.toml"
    rig.write_text(rig_variant(kind, line, value))
    out = tmp_path / "run.mcap"
    # A fault soon after the start ends a run that starts, so a harmless change costs little.
    code, err, _ = cli(["run", "blocked-force", "--rig", str(rig), "--quiet", "--force", "--out", str(out),
                        "--fault", "stage:disconnect@0.2", "--set", "repetitions=1"])
    assert len(err) == 1, err
    if code == 2:
        key = line.split("=")[0].strip()
        assert str(rig) in err[0] or "mutated.toml" in err[0], err[0]
        assert key[:-1] in err[0] or kind == "drop", err[0]
    else:
        assert code == 1 and "run failed" in err[0] and "stage" in err[0], err[0]


PROTOCOL_KEYS = {
    "blocked-force": ["voltages_V", "repetitions", "alternate_direction", "drive.ramp_s", "drive.cycles",
                      "drive.sample_rate_Hz", "contact.threshold_N", "contact.coarse_step_m", "nonsense"],
    "static": ["max_sag_m", "step_m", "settle_s", "hold_s", "unload", "contact.max_travel_m", "nonsense"],
}
PROTOCOL_VALUES = ['"x"', "-1", "0", "1e400", "[]", "[1, \"a\"]", "{ b = 2 }", "true", "2.5", "1e9"]


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(protocol=st.sampled_from(sorted(PROTOCOL_KEYS)), data=st.data())
def test_bad_protocol_file_names_the_parameter_in_one_line(tmp_path, protocol, data):
    key = data.draw(st.sampled_from(PROTOCOL_KEYS[protocol]))
    value = data.draw(st.sampled_from(PROTOCOL_VALUES))
    table, _, name = key.rpartition(".")
    text = (f"[{table}]\n" if table else "") + f"{name} = {value}\n"
    file = tmp_path / "protocol.toml"
    file.write_text(text)
    out = tmp_path / "run.mcap"
    code, err, _ = cli(["run", protocol, "--sim", "--quiet", "--force", "--out", str(out), "--protocol-file",
                        str(file), "--fault", "stage:disconnect@0.2"])
    assert len(err) == 1, err
    if code == 2:
        # the parameter is always named; the file is named except for values the protocol's own validate()
        # rejects (test_a_value_validation_rejects_names_the_protocol_file below)
        assert name in err[0], err[0]
    else:  # a value that happens to be valid: the run started and the fault ended it
        assert code == 1 and "run failed" in err[0], err[0]


def test_a_value_validation_rejects_names_the_protocol_file(tmp_path):
    file = tmp_path / "protocol.toml"
    file.write_text("repetitions = -1\n")
    code, err, _ = cli(["run", "blocked-force", "--sim", "--quiet", "--out", str(tmp_path / "r.mcap"),
                        "--protocol-file", str(file)])
    assert code == 2 and len(err) == 1 and "repetitions" in err[0]
    assert "protocol.toml" in err[0], err[0]


# ------------------------------------------------------------------------------------ CSV import
POINTS = ("protocol,design,layers,voltage_V,sag_m,repetition,force_N,displacement_m\n"
          "blocked-force,4,2,100,0,1,0.004,\n"
          "blocked-force,4,2,250,0,1,0.011,\n"
          "free-displacement,4,2,250,,1,,0.0009\n")
TRACE = "time_s,voltage_V,stage_position_m,force_N,displacement_m\n" + "".join(
    f"{k * 0.01:.2f},{250.0 if 20 <= k < 60 else 0.0},0.002,{0.01 if 20 <= k < 60 else 0.0},\n" for k in range(80))
CELL_GARBAGE = ["abc", "nan", "inf", "-1", "1e400", "", "\"unterminated", ";", "4,5", "\x00"]


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(fmt=st.sampled_from(["points", "trace"]), data=st.data())
def test_mutated_csv_imports_or_names_the_line_in_one_line(tmp_path, fmt, data):
    pytest.importorskip("analysis.importer")
    text = POINTS if fmt == "points" else TRACE
    rows = [r.split(",") for r in text.splitlines()]
    mutation = data.draw(st.sampled_from(["cell", "cut", "header"]))
    r = data.draw(st.integers(0 if mutation == "header" else 1, len(rows) - 1))
    if mutation == "cut":
        rows = rows[:r] + [rows[r][: data.draw(st.integers(0, len(rows[r]) - 1))]] + rows[r + 1:]
    else:
        c = data.draw(st.integers(0, len(rows[r]) - 1))
        rows[r][c] = data.draw(st.sampled_from(CELL_GARBAGE))
    file = tmp_path / "in.csv"
    file.write_text("\n".join(",".join(row) for row in rows) + "\n")
    out = tmp_path / "imported.mcap"
    argv = ["import", fmt, str(file), "--out", str(out), "--force"]
    if fmt == "trace":
        argv += ["--protocol", "blocked-force", "--design", "4"]
    code, err, _ = cli(argv)
    if code == 0:
        RecordingReader(out, validate_crcs=True)
    else:
        assert code == 2 and len(err) == 1, err
        assert "in.csv" in err[0], err[0]
