"""The diagnosis end to end on another lab's data: CSVs from tests/analysis/lab_traces.py (a generator that shares
no code or formula with analysis/: Duhem hysteresis, a two-term Prony creep, a lagging monitor, a push-only force
sensor, three specimens per file) imported as a user would, then `gap`. Plus the CLI's JSON and report."""

import json

import numpy as np
import pytest

from analysis.gap.diagnose import diagnose
from analysis.gap.engine import EffectValue
from analysis.gap.families import FAMILIES
from analysis.gap.features import load_gap_data
from analysis.gap.problem import Problem
from hamr_bench.cli import main
from tests.analysis.lab_traces import Effects, Lab, LabFile, Specimen, specimen_rows

SPECIMENS = (Specimen("A", 1.02, 0.99), Specimen("B", 0.97, 1.01), Specimen("C", 1.0, 1.0))


def write_lab(directory, effects: Effects, seed: int, volts=(120.0, 250.0), lab: Lab | None = None,
              specimens: tuple[Specimen, ...] = SPECIMENS) -> list:
    lab = lab or Lab()
    rng = np.random.default_rng(seed)
    out = []
    for test in ("blocked", "free"):
        for v in volts:
            f = LabFile()
            for sp in specimens:
                f.rows += specimen_rows(sp, 2, test, v, lab, effects, rng)
            out.append(import_lab_file(f, directory / f"{test}_{int(v)}V.csv"))
    return out


def import_lab_file(f: LabFile, csv_path) -> object:
    """Write one of the lab's CSVs (2-layer actuators) and import it as a user would; the recording's path."""
    f.write(csv_path)
    mcap = csv_path.with_suffix(".mcap")
    assert main(["import", "trace", str(csv_path), "--protocol", "actuator", "--layers", "2", "--out", str(mcap)]) == 0
    return mcap


@pytest.fixture(scope="module")
def null_lab(tmp_path_factory):
    return write_lab(tmp_path_factory.mktemp("null"), Effects(), seed=3)


def test_strength_zero_is_the_nominal_model_exactly(null_lab):
    p = Problem(load_gap_data(null_lab))
    lay0 = p.layout(())
    x0 = lay0.vector()
    nominal = p.model(lay0, x0)
    for name, fam in FAMILIES.items():
        if fam.kind == "baseline":
            continue
        lay = p.layout((name,))
        x = lay.vector(lay0.values(x0))
        assert np.array_equal(p.model(lay, x), nominal), name
        e = p.engines[0]
        assert e.effective_drive({name: EffectValue(0.0)}, e.actuator.pzt_thickness_m).tolist() == \
            e.effective_drive({}, e.actuator.pzt_thickness_m).tolist()


def test_plate_thickness_is_fitted_only_with_d31_and_moves_where_a_voltage_lands_on_its_curve(null_lab):
    p = Problem(load_gap_data(null_lab))
    assert not any(q.kind == "plate" for q in p.layout(("hysteresis",)).params)
    lay = p.layout(("field_dependent_d31",))
    plates = [q.key[0] for q in lay.params if q.kind == "plate"]
    assert sorted(plates) == sorted(p.groups)
    e = p.engines[0]
    t_p = e.actuator.pzt_thickness_m
    step = {"field_dependent_d31": EffectValue(0.5, {"log10_knee_V_per_um": 0.0, "steepness": 6.0})}
    # a sharp step at 1 V/um: 5 % thicker plates put each voltage lower on it (2 % of the peak drive here)
    thin, thick = e.effective_drive(step, t_p), e.effective_drive(step, t_p * 1.05)
    assert np.max(np.abs(thin - thick)) > 0.01 * np.max(np.abs(thin))
    assert e.effective_drive({}, t_p).tolist() == e.effective_drive({}, t_p * 1.05).tolist()


@pytest.mark.slow
def test_a_null_stays_null_on_another_labs_data(null_lab):
    d = diagnose(load_gap_data(null_lab))
    assert d.best is None
    assert all(e.verdict != "attributed" for e in d.named)
    # specimens are fitted within their tolerances, not reported as effects
    assert set(d.specimens) == {"layers=2|specimen=A", "layers=2|specimen=B", "layers=2|specimen=C"}
    # what it could have named, whether or not a gap was found: actuator effects, no leg or stage effect
    assert {"hysteresis", "creep", "width_loss", "sensor_drift"} <= set(d.candidates)
    assert not {"bias_error", "stage_backlash"} & set(d.candidates)


@pytest.mark.slow
def test_gap_cli_json_and_report(null_lab, tmp_path, capsys):
    capsys.readouterr()
    assert main(["gap", *map(str, null_lab), "--json", "--jobs", "1", "--effects", "hysteresis,creep",
                 "--report", str(tmp_path / "rep")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"best", "ranking", "named", "waterfall", "unexplained", "cannot_separate", "where",
                        "specimens", "recordings"}
    assert out["waterfall"][0]["added"] is None and out["waterfall"][0]["heldout_rms"] > 0
    assert {e["effect"] for e in out["ranking"]} == {"hysteresis", "creep"}
    assert out["candidates"] == ["hysteresis", "creep"]
    assert (tmp_path / "rep" / "waterfall.png").stat().st_size > 0
    assert "## Which" in (tmp_path / "rep" / "gap.md").read_text()


def test_gap_cli_unknown_effect_is_one_line(null_lab, capsys):
    assert main(["gap", str(null_lab[0]), "--effects", "gremlins"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gremlins" in err[0]


def test_gap_cli_bad_params_file_is_one_line(null_lab, tmp_path, capsys):
    bad = tmp_path / "fit.json"
    bad.write_text("{not json", encoding="utf-8")
    assert main(["gap", str(null_lab[0]), "--params", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fit.json" in err[0]


def test_fit_params_move_the_nominal_model(null_lab):
    # a fit that says the plates are 10 % wider is the nominal model with a kerf of -10 %... of the mean width
    # only when the taper is kept: compare the actuator the engine builds with the preset's scaled width
    from hamr_bench.model import actuator_preset

    a = actuator_preset(2, "effective")
    fit = {"actuators": {"2": {"width": {"value": a.width_nom_m * 1.1, "unit": "m"}}}}
    data = load_gap_data(null_lab[:1])
    with_fit, nominal = Problem(data, fit), Problem(data)
    assert with_fit.engines[0].actuator.width_nom_m == pytest.approx(1.1 * nominal.engines[0].actuator.width_nom_m)
    lay = nominal.layout(())
    assert not np.allclose(with_fit.model(lay, lay.vector()), nominal.model(lay, lay.vector()), rtol=1e-3)


@pytest.mark.slow
def test_the_diagnosis_does_not_depend_on_jobs(tmp_path):
    """Candidate fits side by side in forked workers give the same diagnosis as in one process."""
    data = load_gap_data(write_lab(tmp_path, Effects(creep=0.05), seed=11))
    one = diagnose(data, jobs=1).to_json()
    two = diagnose(data, jobs=2).to_json()
    assert one["gap_above_noise"] and one["screening"]      # the candidate fits did run
    one.pop("elapsed_s")
    two.pop("elapsed_s")
    assert json.dumps(one, sort_keys=True, default=float) == json.dumps(two, sort_keys=True, default=float)


def test_presets_far_off_get_the_wide_gain_bound_and_the_nominal_fit_reaches_the_data(null_lab, tmp_path):
    from analysis.gap.diagnose import nominal_fit
    from analysis.gap.problem import GAIN_BOUND, WIDE_GAIN_BOUND

    near = Problem(load_gap_data(null_lab))
    nominal_fit(near)
    assert near.gain_bound == GAIN_BOUND          # an ordinary lab keeps the narrow bound (and its solver path)

    # plates a quarter of the preset width: the stiffness gain is log(1/4) = -1.39, beyond the narrow bound
    narrow = tuple(Specimen(s.label, s.d31_scale, 0.25 * s.width_scale) for s in SPECIMENS)
    far = Problem(load_gap_data(write_lab(tmp_path, Effects(), seed=5, specimens=narrow)))
    fit = nominal_fit(far)
    assert far.gain_bound == WIDE_GAIN_BOUND
    stiffness = [fit.value("gain", g, 1) for g in far.groups]
    assert all(-1.6 < b < -1.2 for b in stiffness), stiffness
    assert fit.chi2_rows < 3.0 * far.y.size       # the rows fit; at the narrow bound they could not


def test_the_plate_loops_on_the_drive_changes_alone_are_the_loops_on_every_sample(null_lab):
    """A play is rate-independent: evaluating the loops only where a plate's drive changes and spreading them back
    (to the drive segments, then to the dense grid) gives every dense sample the loops of the full drive (the
    staircase repeats itself in most samples)."""
    from analysis.gap import operators as op
    from analysis.gap.engine import FULL_SCALE_V

    e = Problem(load_gap_data(null_lab)).engines[0]
    loops = e._plate_loops(0.12, 0.5, 0.3)[:, e._segments.of]
    kept = 0
    for k, v in enumerate((e.dense_vd, e.dense_vb - e.dense_vd)):
        x = v / FULL_SCALE_V
        every = FULL_SCALE_V * op.plate_hysteresis(x, op.plate_memory(x), op.plate_weights(0.12, 0.5, 0.3), 0.3)
        np.testing.assert_allclose(loops[k], every, rtol=0, atol=1e-12 * FULL_SCALE_V)
        kept += e._plate_drives()[k].above.size
    assert kept < 0.8 * 2 * e.dense_t.size     # the repeats were left out
