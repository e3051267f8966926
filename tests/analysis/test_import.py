"""CSV import: point tables and time series become recordings that the dataset and the fit read like recorded
runs; malformed input is refused with one line naming the file, the line and the column."""

from __future__ import annotations

import csv
import subprocess
import sys

import numpy as np
import pytest

from analysis.dataset import load_dataset
from analysis.importer import POINT_COLUMNS, import_points, import_trace
from hamr_bench.cli import main
from hamr_bench.errors import ConfigError
from hamr_bench.model import powertrain
from hamr_bench.protocols.drive import trapezoid_V
from tests.analysis.synth import table_dataset


def _write_points(path, observations) -> None:
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(POINT_COLUMNS)
        for o in observations:
            w.writerow([o.protocol, o.design, o.layers, o.voltage_V, o.sag_m, o.repetition,
                        o.value if o.quantity == "force_N" else "",
                        o.value if o.quantity == "displacement_m" else ""])


def test_points_round_trip_through_a_recording(tmp_path):
    table = table_dataset(4, seed=9)
    csv_path = tmp_path / "points.csv"
    _write_points(csv_path, table.observations)
    n = import_points(csv_path, tmp_path / "points.mcap")
    assert n == len(table.observations)
    ds = load_dataset([tmp_path / "points.mcap"])
    assert len(ds.observations) == len(table.observations)
    key = lambda o: (o.protocol, o.quantity, o.voltage_V, o.sag_m, o.repetition)  # noqa: E731
    got = sorted((key(o), o.value, o.design, o.layers) for o in ds.observations)
    want = sorted((key(o), o.value, o.design, o.layers) for o in table.observations)
    assert got == want
    assert ds.runs[0].info.source == "import-points"


@pytest.mark.parametrize("bad, column, line", [
    ("blocked-force,4,2,abc,0,0,0.004,", "voltage_V", 3),
    ("walking,4,2,100,0,0,0.004,", "protocol", 3),
    ("blocked-force,9,2,100,0,0,0.004,", "design", 3),
    ("blocked-force,4,2,100,0,0,,", "force_N", 3),
    ("blocked-force,4,2,100,0,1.5,0.004,", "repetition", 3),
])
def test_a_malformed_point_row_names_file_line_and_column(tmp_path, bad, column, line):
    path = tmp_path / "bad.csv"
    path.write_text(",".join(POINT_COLUMNS) + "\nblocked-force,4,2,100,0,0,0.004,\n" + bad + "\n")
    with pytest.raises(ConfigError) as exc:
        import_points(path, tmp_path / "out.mcap")
    message = str(exc.value)
    assert f"{path}:{line}" in message and f"column {column}" in message and "\n" not in message


def test_cli_prints_one_line_for_a_malformed_file(tmp_path):
    path = tmp_path / "bad.csv"
    path.write_text("time_s,voltage_V,stage_position_m,force_N,displacement_m\n0,0,0,0,\n0.001,x,0,0,\n")
    proc = subprocess.run([sys.executable, "-m", "hamr_bench", "import", "trace", str(path), "--protocol",
                           "blocked-force", "--design", "4", "--out", str(tmp_path / "t.mcap")],
                          capture_output=True, text=True)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"{path}:3" in lines[0] and "column voltage_V" in lines[0]
    assert "Traceback" not in proc.stderr


def _trace_rows(volts, sag_m, p, rate=1000.0, seed=0):
    """A blocked-force time series: for each voltage, 2 trapezoid cycles with the bias held at V."""
    rng = np.random.default_rng(seed)
    rows, t0 = [], 0.0
    for v in volts:
        wave = trapezoid_V(v, 0.05, 0.4, 0.4, 2, rate)
        t = t0 + np.arange(wave.size) / rate
        f = np.maximum(p.foot_force_N(np.full(wave.size, v), wave, np.full(wave.size, sag_m)), 0.0)
        f = f + rng.normal(0, 0.2e-3, wave.size)
        rows += [(ti, vi, 1e-3 + sag_m, fi, "") for ti, vi, fi in zip(t, wave, f)]
        t0 = t[-1] + 0.3
    return rows


def test_trace_import_finds_steps_and_reduces_like_a_run(tmp_path):
    p = powertrain(3)
    volts = [100.0, 150.0, 200.0, 250.0, 250.0]
    path = tmp_path / "trace.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m"])
        w.writerows(_trace_rows(volts, 0.0, p))
    n = import_trace(path, tmp_path / "trace.mcap", "blocked-force", design=3)
    assert n == 4   # the repeated 250 V block joins the one before (same peak, same stage): one step of 4 cycles
    ds = load_dataset([tmp_path / "trace.mcap"])
    obs = ds.observations
    assert [o.voltage_V for o in obs] == [100.0, 150.0, 200.0, 250.0]
    assert [o.n_cycles for o in obs] == [2, 2, 2, 4]
    for o in obs:
        assert o.sag_m == 0.0 and o.design == 3
        # 2 cycles x 0.2 s at 1 kHz of 0.2 mN noise
        assert abs(o.value - float(p.foot_force_N(o.voltage_V, o.voltage_V, 0.0))) < 5 * 0.2e-3 / np.sqrt(400)


def test_static_trace_import_uses_stage_plateaus(tmp_path):
    p = powertrain(4)
    rng = np.random.default_rng(2)
    rows, t = [], 0.0
    sags = [0.0, 0.5e-3, 1.0e-3, 1.5e-3]
    for s in sags:
        for _ in range(400):   # 0.4 s per plateau at 1 kHz
            f = max(float(p.foot_force_N(0.0, 0.0, s)), 0.0) + rng.normal(0, 0.1e-3)
            rows.append((t, 0.0, 2e-3 + s, f, ""))
            t += 1e-3
    path = tmp_path / "static.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m"])
        w.writerows(rows)
    assert import_trace(path, tmp_path / "static.mcap", "static", design=4) == 4
    obs = load_dataset([tmp_path / "static.mcap"]).observations
    assert [round(o.sag_m, 9) for o in obs] == sags
    for o in obs:
        assert abs(o.value - max(float(p.foot_force_N(0.0, 0.0, o.sag_m)), 0.0)) < 5 * 0.1e-3 / np.sqrt(200)


def test_cli_import_points_then_fit(tmp_path, capsys):
    table = table_dataset(3, seed=4)
    csv_path = tmp_path / "p.csv"
    _write_points(csv_path, table.observations)
    assert main(["import", "points", str(csv_path), "--out", str(tmp_path / "p.mcap")]) == 0
    assert main(["fit", str(tmp_path / "p.mcap"), "--no-intervals", "--json"]) == 0
    out = capsys.readouterr().out
    import json

    report = json.loads(out[out.index("{"):])
    assert report["designs"]["3"]["k_ser"]["value"] == pytest.approx(2600.0, rel=0.02)


def test_points_with_specimens_fit_per_specimen_with_the_population(tmp_path, capsys):
    # three actuators of one build, each measured at three voltages (blocked force and stroke), scatter of +-5 %
    import json

    from hamr_bench.model import actuator as act
    from hamr_bench.model import actuator_preset

    a = actuator_preset(2, "effective")
    c, s = act.force_per_volt(a), act.displacement_per_volt(a)
    scale = {"s1": 1.0, "s2": 1.05, "s3": 0.96}
    rng = np.random.default_rng(3)
    path = tmp_path / "points.csv"
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh, delimiter=";")
        w.writerow(POINT_COLUMNS + ("specimen",))
        for label, k in scale.items():
            for rep in range(2):
                for v in (100.0, 150.0, 200.0, 250.0):
                    f = k * c * v + rng.normal(0, 0.3e-3)
                    d = 2 * k * s * v + rng.normal(0, 0.2e-6)
                    w.writerow(["actuator", "", 2, str(v).replace(".", ","), 0, rep, str(f).replace(".", ","),
                                str(d).replace(".", ","), label])
    assert main(["import", "points", str(path), "--out", str(tmp_path / "p.mcap")]) == 0
    capsys.readouterr()
    assert main(["fit", str(tmp_path / "p.mcap"), "--json", "--jobs", "1"]) == 0
    group = json.loads(capsys.readouterr().out)["actuators"]["2"]
    assert set(group["specimens"]) == set(scale)
    for label, k in scale.items():
        got = group["specimens"][label]["derived"]["force_per_volt"]["value"]
        assert got == pytest.approx(k * c, rel=0.01)
    pop = group["derived"]["force_per_volt"]
    assert pop["between_specimen_sd"] == pytest.approx(np.std([k * c for k in scale.values()], ddof=1), rel=0.1)
    assert pop["ci95"][0] <= np.mean([k * c for k in scale.values()]) <= pop["ci95"][1]


def test_sessions_group_files_by_default_and_split_by_name(tmp_path):
    # the same specimen's 150 V and 250 V blocked steps in two files: by default one session (one offset); with
    # --session each file its own
    from analysis.dataset import load_dataset

    p = powertrain(3)
    paths = []
    for v in (150.0, 250.0):
        path = tmp_path / f"t{int(v)}.csv"
        with open(path, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(["time_s", "voltage_V", "stage_position_m", "force_N", "displacement_m"])
            w.writerows(_trace_rows([v], 0.0, p))
        paths.append(path)
    for i, path in enumerate(paths):
        assert main(["import", "trace", str(path), "--protocol", "blocked-force", "--design", "3", "--out",
                     str(tmp_path / f"d{i}.mcap")]) == 0
        assert main(["import", "trace", str(path), "--protocol", "blocked-force", "--design", "3", "--session",
                     f"day{i}", "--out", str(tmp_path / f"s{i}.mcap")]) == 0
    grouped = load_dataset([tmp_path / "d0.mcap", tmp_path / "d1.mcap"])
    assert len({r.info.session for r in grouped.runs}) == 1
    assert {r.info.session_rule for r in grouped.runs} == {"default"}
    named = load_dataset([tmp_path / "s0.mcap", tmp_path / "s1.mcap"])
    assert [r.info.session for r in named.runs] == ["session=day0|specimen=", "session=day1|specimen="]
