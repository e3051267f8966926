"""`hamr-bench model ...` and `hamr-bench paper`: JSON shapes, and one-line errors naming the parameter."""

import json
import subprocess
import sys

import pytest

from hamr_bench.cli import main


def _json(argv, capsys):
    assert main(argv) == 0
    return json.loads(capsys.readouterr().out)


def test_model_actuator_json(capsys):
    out = _json(["model", "actuator", "--layers", "3", "--params", "reported", "--voltage", "100", "250", "--json"],
                capsys)
    assert [p["voltage_V"] for p in out["points"]] == [100.0, 250.0]
    keys = {"voltage_V", "blocked_force_N", "free_displacement_m", "stiffness_N_per_m", "mass_kg", "energy_J",
            "energy_density_J_per_kg"}
    assert all(set(p) == keys for p in out["points"])


def test_model_leg_tests(capsys):
    out = _json(["model", "leg", "--design", "4", "--test", "blocked-force", "--voltage", "200", "250",
                 "--sag", "0", "0.001", "--json"], capsys)
    assert len(out["points"]) == 4 and set(out["points"][0]) == {"voltage_V", "sag_m", "force_N"}
    out = _json(["model", "leg", "--design", "1", "--test", "free-displacement", "--voltage", "250", "--json"], capsys)
    assert set(out["points"][0]) == {"voltage_V", "displacement_m"}
    out = _json(["model", "leg", "--design", "5", "--test", "static", "--force", "0.00265", "--json"], capsys)
    assert set(out["points"][0]) == {"force_N", "displacement_m"} and out["points"][0]["displacement_m"] > 0


def test_paper_json_keys(capsys):
    out = _json(["paper", "--json"], capsys)
    assert len(out["claims"]) >= 10
    for c in out["claims"]:
        assert {"id", "claim", "paper", "model", "reproduced", "margin"} <= set(c)


def test_paper_markdown(capsys):
    assert main(["paper", "--markdown"]) == 0
    assert capsys.readouterr().out.startswith("# Paper reproduction")


@pytest.mark.parametrize("argv,needle", [
    (["model", "actuator", "--voltage", "300"], "--voltage 300 V exceeds the configured limit 250 V"),
    (["model", "leg", "--design", "4", "--test", "blocked-force", "--voltage", "251"], "limit 250 V"),
])
def test_bad_input_is_one_line(argv, needle):
    r = subprocess.run([sys.executable, "-m", "hamr_bench", *argv], capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr
