"""`hamr-bench model ...` and `hamr-bench paper`: JSON shapes, and one-line errors naming the parameter."""

import json
import subprocess
import sys

import pytest

from hamr_bench.cli import main
from hamr_bench.model.designs import DEFAULT_KAPPA_UNITS


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


def test_paper_json_carries_kind_margin_band_reproduced(capsys):
    out = _json(["paper", "--json", "--samples", "8"], capsys)
    assert out["kappa_units"] == DEFAULT_KAPPA_UNITS and out["samples"] == 8
    assert len(out["claims"]) >= 15
    for c in out["claims"]:
        assert {"id", "claim", "paper", "model", "kind", "margin", "band", "reproduced"} <= set(c)
        assert c["reproduced"] in (True, False, "indeterminate")
    assert {"printed", "nmm", "mixed"} == set(out["readings"])


def test_paper_kappa_units_flag_changes_the_reading(capsys):
    out = _json(["paper", "--json", "--samples", "4", "--kappa-units", "printed"], capsys)
    assert out["kappa_units"] == "printed"
    assert "kappa units: printed" in out["summary"]


def test_paper_markdown(capsys):
    assert main(["paper", "--markdown", "--samples", "4"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("# Paper reproduction") and "## Kappa readings" in text


@pytest.mark.parametrize("argv,needle", [
    (["model", "actuator", "--voltage", "300"], "--voltage 300 V exceeds the configured limit 250 V"),
    (["model", "leg", "--design", "4", "--test", "blocked-force", "--voltage", "251"], "limit 250 V"),
    (["model", "leg", "--design", "4", "--test", "blocked-force", "--friction-mu", "1.5"], "--friction-mu"),
    (["paper", "--samples", "0"], "--samples must be at least 1"),
])
def test_bad_input_is_one_line(argv, needle):
    r = subprocess.run([sys.executable, "-m", "hamr_bench", *argv], capture_output=True, text=True)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr
