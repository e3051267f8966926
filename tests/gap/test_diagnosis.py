"""The diagnosis on short simulated recordings: nominal recovered at strength 0, no attribution without an
effect, an effect the data cannot separate reported ambiguous with the other named, the CLI's JSON, and one blind
self-check trial."""

import json

import numpy as np
import pytest

from analysis.gap.attribution import diagnose
from analysis.gap.features import load_gap_data
from analysis.gap.library import CANDIDATES
from analysis.gap.problem import Problem
from analysis.gap.selfcheck import Trial, run_trial, score
from hamr_bench.cli import main
from hamr_bench.protocols.session import RunRequest, run_protocol
from tests.dask_cluster import in_process_cluster

BLOCKED = ["voltages_V=100,150,200,250", "repetitions=2", "drive.cycles=2"]


def _record(path, effects, seed=3):
    run_protocol(RunRequest(protocol="blocked-force", out=path, design=4, layers=2, effects=effects, seed=seed,
                            set_options=BLOCKED, overwrite=True))
    return path


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("gap")
    return {"null": _record(d / "null.mcap", {}), "base": _record(d / "base.mcap", {"base_compliance": 0.2})}


def test_strength_zero_is_the_nominal_model_exactly(recordings):
    p = Problem(load_gap_data([recordings["null"]]))
    nominal = p.model({})
    for name in CANDIDATES:
        assert np.array_equal(p.model({name: 0.0}), nominal), name


def test_no_effect_means_no_attribution(recordings):
    result = diagnose(load_gap_data([recordings["null"]]))
    assert result["best"] is None
    assert all(e["verdict"] != "attributed" for e in result["ranking"])


def test_base_compliance_without_the_actuator_test_is_ambiguous_with_width_loss(recordings):
    # On leg blocked force alone both lower A k_act: the data cannot tell them apart (physics notes section 4)
    result = diagnose(load_gap_data([recordings["base"]]), candidates=["width_loss", "base_compliance"])
    assert result["gap_above_noise"]
    assert result["best"] is None
    verdicts = {e["effect"]: e for e in result["ranking"]}
    assert verdicts["base_compliance"]["verdict"] == "ambiguous"
    assert "width_loss" in verdicts["base_compliance"]["confusable_with"] + verdicts["width_loss"]["confusable_with"]


def test_gap_cli_json_keys(recordings, capsys):
    assert main(["gap", str(recordings["base"]), "--effects", "base_compliance,hysteresis", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert set(out) >= {"where", "ranking", "best"}
    assert set(out["where"][0]) >= {"protocol", "condition", "rms_gap", "noise_floor", "p_value"}
    assert set(out["ranking"][0]) >= {"effect", "verdict", "strength", "strength_ci95", "heldout_rms_before",
                                      "heldout_rms_after", "reduction", "reduction_ci95", "confusable_with"}
    top = out["ranking"][0]
    assert top["effect"] == "base_compliance" and out["best"] == "base_compliance"
    lo, hi = top["strength_ci95"]
    assert lo <= 0.2 <= hi   # the generator's blocked-force loss


def test_gap_cli_unknown_effect_is_one_line(recordings, capsys):
    assert main(["gap", str(recordings["null"]), "--effects", "gremlins"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gremlins" in err[0]


def test_score_counts_from_trials():
    def t(truth, best, ci=None, s=0.1):
        return Trial(0, truth, s, best, best, "attributed" if best else None, [], s, ci, 0.5, 0.5, 0.0, 0.0)

    out = score([t("creep", "creep", [0.0, 0.2]), t("creep", "hysteresis"), t("none", None), t("none", "creep"),
                 t("flexure_softening", None)])
    assert out["top1_accuracy"] == 0.5
    assert out["false_attribution_rate_null"] == 0.5
    assert out["decoys_unexplained"] == 1.0
    assert out["interval_coverage"] == 1.0
    assert out["confusion"]["creep"]["hysteresis"] == 1


@pytest.mark.xfail(reason="issue 16 item 4: the bench's generator forms (Preisach hysteresis, d31 curves) share no formula with this candidate library any more; naming them is the rebuilt library's job (gap helper)", strict=False)
def test_one_blind_trial_names_hysteresis():
    trial = run_trial(5, case=("hysteresis", 0.12))
    assert trial.best == "hysteresis"
    assert trial.strength_ci95[0] < trial.strength_ci95[1]


def test_fit_params_move_the_nominal_model(recordings):
    # a fit that says the bias is 30 um longer is the same model as the nominal plus a 30 um bias error
    from hamr_bench.model import design_preset

    data = load_gap_data([recordings["null"]])
    fit = {"designs": {"4": {"bias": {"value": design_preset(4).bias_m + 30e-6, "unit": "m"}}}}
    with_fit, nominal = Problem(data, fit), Problem(data)
    # same sensor lag and contact shifts (each Problem estimates its own nuisances against its nominal)
    with_fit.lag, with_fit.contact_shift = dict(nominal.lag), dict(nominal.contact_shift)
    assert np.allclose(with_fit.model({}), nominal.model({"bias_error": 30e-6}), rtol=1e-9, atol=0)
    assert not np.allclose(with_fit.model({}), nominal.model({}), rtol=1e-3, atol=0)


def test_gap_cli_bad_params_file_is_one_line(recordings, tmp_path, capsys):
    bad = tmp_path / "fit.json"
    bad.write_text("{not json", encoding="utf-8")
    assert main(["gap", str(recordings["null"]), "--params", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "fit.json" in err[0]


def test_creep_must_show_its_dwell_growth(tmp_path):
    # An amplifier gain loss lowers every amplitude (a log-creep law can fit that) but nothing grows during a
    # dwell at constant drive; real creep does. The hallmark check tells them apart (docs/gap.md, verdict rules).
    from analysis.gap.attribution import dwell_contrast, fit_single

    # On the bare actuator (DAQ-sampled force and camera, no sensor lag): the leg's serial load cell stamps lines
    # 15-35 ms late, so its early-dwell window still overlaps the ramp and an amplitude change leaks into the
    # contrast (docs/gap.md, known limits).
    out = {}
    for name, strength in (("amplifier_gain_error", 0.08), ("creep", 0.02)):
        path = tmp_path / f"{name}.mcap"
        run_protocol(RunRequest(protocol="actuator", out=path, design=4, layers=2, effects={name: strength},
                                seed=11, overwrite=True,
                                set_options=["voltages_V=100,175,250", "repetitions=1", "drive.cycles=4",
                                             "contact.coarse_step_m=2e-5", "contact.fine_step_m=1e-6"]))
        p = Problem(load_gap_data([path]))
        s, _ = fit_single(p, "creep")
        out[name] = (s, dwell_contrast(p, "creep", s))
    s_decoy, h_decoy = out["amplifier_gain_error"]
    s_creep, h_creep = out["creep"]
    assert s_decoy > 0.005                      # the log law does fit the gain loss in amplitude
    assert h_decoy["applicable"] and not h_decoy["supported"]
    assert h_creep["applicable"] and h_creep["supported"]
    assert 0.5 * s_creep <= h_creep["strength"]


def test_bootstrap_keeps_every_experiment():
    from analysis.gap.attribution import _boot

    cid = np.repeat(np.arange(10), 2)            # 10 conditions of 2 rows
    strata = np.where(cid < 3, 0, 1)              # a small experiment of 3 conditions, a large one of 7
    counts = _boot(cid, lambda r: float(np.sum(strata[r] == 0)), np.random.default_rng(0), n=300, strata=strata)
    assert np.all(counts == 6)                    # always 3 conditions x 2 rows from the small experiment
    unstratified = _boot(cid, lambda r: float(np.sum(strata[r] == 0)), np.random.default_rng(0), n=300)
    assert unstratified.min() < 6 < unstratified.max()


def test_blind_draw_covers_the_whole_library_and_the_backlash_span():
    from analysis.gap.selfcheck import DRAW_LOG_RANGE, EXCLUDED_FROM_DRAW, draw_case

    rng = np.random.default_rng(0)
    draws = [draw_case(rng, 0.0, 0.0) for _ in range(600)]
    assert {n for n, _ in draws} == set(CANDIDATES) - set(EXCLUDED_FROM_DRAW)
    lo, hi = DRAW_LOG_RANGE["stage_backlash"]
    b = np.array([s for n, s in draws if n == "stage_backlash"])
    assert b.min() >= lo and b.max() <= hi
    # log-uniform: about half the draws below the geometric middle
    assert 0.3 < np.mean(b < np.sqrt(lo * hi)) < 0.7


def test_recordings_read_in_parallel_give_the_same_rows(recordings):
    paths = [recordings["null"], recordings["base"]]
    serial = load_gap_data(paths, jobs=1)
    pooled = load_gap_data(paths, jobs=2)
    assert [r.path for r in pooled.runs] == [r.path for r in serial.runs]
    assert len(pooled.rows) == len(serial.rows) > 0
    for a, b in zip(serial.rows, pooled.rows):
        assert a.__dict__.keys() == b.__dict__.keys()
        for key, value in a.__dict__.items():
            if isinstance(value, np.ndarray):
                np.testing.assert_array_equal(value, b.__dict__[key])
            else:
                assert value == b.__dict__[key] or (value != value and b.__dict__[key] != b.__dict__[key]), key
    with in_process_cluster() as client:
        on_dask = load_gap_data(paths, scheduler=client.scheduler.address)
    assert len(on_dask.rows) == len(serial.rows)
