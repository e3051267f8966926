"""Replaying a simulated recording: the same seed and parameters give back the same data (sample times and values,
to floating-point tolerance), another seed differs only within noise, changed model parameters differ beyond it,
and the twin names its source and the parameters it used."""

from __future__ import annotations

import json

import numpy as np
import pytest

from analysis.compare import compare_recordings
from analysis.replay import model_overrides_from_fit, read_replay_source, replay_recording
from hamr_bench.errors import ConfigError
from hamr_bench.model import design_preset
from hamr_bench.recording import RecordingReader
from tests.replay.conftest import SOURCE_EFFECTS, SOURCE_SEED, record

TIME_TOL_S = 1e-9


def scalar_topics(reader):
    """Every topic but events, serial traffic and the foxglove.* views (/log repeats the events with absolute
    stamps, /step the step events: both are compared through the events below; images are not data here)."""
    return sorted(t for t, info in reader.topics().items()
                  if info.schema_name not in ("hamr_bench.Event", "hamr_bench.SerialTraffic",
                                              "hamr_bench.StepCondition")
                  and not info.schema_name.startswith("foxglove."))


def assert_same_data(path_a, path_b):
    a, b = RecordingReader(path_a), RecordingReader(path_b)
    assert scalar_topics(a) == scalar_topics(b)
    for topic in scalar_topics(a):
        sa, sb = a.scalars(topic), b.scalars(topic)
        assert sa.keys() == sb.keys()
        assert len(sa["time_s"]) == len(sb["time_s"]), topic
        for field in sa:
            np.testing.assert_allclose(sb[field], sa[field], rtol=1e-12, atol=TIME_TOL_S if field == "time_s" else 0,
                                       err_msg=f"{topic}.{field}")
    ea = [(e.kind, e.step, e.data) for e in a.events() if e.kind not in ("run_start", "run_end")]
    eb = [(e.kind, e.step, e.data) for e in b.events() if e.kind not in ("run_start", "run_end")]
    assert ea == eb
    ta = np.array([e.time_s for e in a.events()])
    tb = np.array([e.time_s for e in b.events()])
    np.testing.assert_allclose(tb, ta, atol=TIME_TOL_S)


def test_same_seed_gives_back_the_same_data(source_run, tmp_path):
    twin = tmp_path / "twin.mcap"
    result, source = replay_recording(source_run, twin)  # seed and effects default to the source's
    assert result.ok
    assert source.seed == SOURCE_SEED and source.effects == SOURCE_EFFECTS
    assert_same_data(source_run, twin)


def test_dwell_protocol_twin_is_the_same(tmp_path):
    # static holds the stage in dwells (the runner's sampling passes), a different timing path from the drives
    src = record(tmp_path / "static.mcap", "static", options=["max_sag_m=0.0005", "step_m=0.00025", "hold_s=0.3", "settle_s=0.2"])
    twin = tmp_path / "twin.mcap"
    assert replay_recording(src, twin)[0].ok
    assert_same_data(src, twin)


def test_another_seed_differs_only_within_noise(source_run, tmp_path):
    twin = tmp_path / "seed.mcap"
    assert replay_recording(source_run, twin, seed=SOURCE_SEED + 11)[0].ok
    result = compare_recordings(source_run, twin)
    force = result["channels"]["force_N"]
    assert force["steps_compared"] >= 4
    assert force["max_abs_diff"] > 0  # the noise did change
    beyond = {name: s for name, s in result["channels"].items() if s["exceeds_noise"]}
    assert beyond == {}


def test_changed_parameters_show_beyond_noise(source_run, tmp_path):
    # Half the serial stiffness: the blocked force falls by a large fraction, far above the sensor noise.
    fit = tmp_path / "fit.json"
    k = design_preset(4).k_ser_N_per_m
    fit.write_text(json.dumps({"designs": {"4": {"k_ser": {"value": k / 2, "ci95": None, "unit": "N/m"}}}}))
    twin = tmp_path / "soft.mcap"
    assert replay_recording(source_run, twin, params_path=fit)[0].ok
    result = compare_recordings(source_run, twin)
    assert result["channels"]["force_N"]["exceeds_noise"]
    assert not result["channels"]["stage_position_m"]["exceeds_noise"]  # the commands are the same
    md = RecordingReader(twin).metadata()
    assert md["replay"]["model_params"] == "fit" and md["replay"]["params_file"].endswith("fit.json")
    assert json.loads(md["design"]["model_params"])["design"]["k_ser_N_per_m"] == pytest.approx(k / 2)


def test_twin_names_its_source_and_nominal_parameters(source_run, tmp_path):
    twin = tmp_path / "twin.mcap"
    replay_recording(source_run, twin)
    md = RecordingReader(twin).metadata()
    assert md["replay"]["source"] == str(source_run.resolve())
    assert md["replay"]["model_params"] == "nominal" and md["replay"]["params_file"] == ""
    assert md["protocol"]["name"] == "blocked-force"
    assert md["design"]["model_params"] == RecordingReader(source_run).metadata()["design"]["model_params"]


def test_commands_come_from_the_recording_not_the_protocol_defaults(source_run):
    source = read_replay_source(source_run)
    reader = RecordingReader(source_run)
    steps = [e for e in reader.events() if e.kind == "step"]
    assert len(steps) == 4 and source.steps == 4  # 2 voltages x 2 repetitions, not the default 4 x 5
    from hamr_bench.protocols.plan import SetVoltages, Step
    from hamr_bench.protocols.replay_plan import ReplayDrive, StageCommand

    assert [m.condition for m in source.items if isinstance(m, Step)] == [e.data for e in steps]
    assert sum(isinstance(m, StageCommand) for m in source.items) == len(reader.scalars("/stage/command")["time_s"])
    drives = [m for m in source.items if isinstance(m, ReplayDrive)]
    starts = [e for e in reader.events() if e.kind == "drive_start"]
    assert [len(d.waveform_V) for d in drives] == [e.data["n_samples"] for e in starts]
    assert [m.bias_V for m in source.items if isinstance(m, SetVoltages)] == \
        [e.data["bias_V"] for e in reader.events() if e.kind == "set_voltages"]


def test_fit_json_maps_onto_model_fields(tmp_path):
    fit = tmp_path / "fit.json"
    fit.write_text(json.dumps({
        "actuators": {"2": {"E_p": {"value": 40e9}, "d31": {"value": 2e-10}, "rms_N": 1e-4}},
        "designs": {"4": {"k_ser": {"value": 900.0}, "kappa_2": {"value": 1e-5}, "bias": {"value": 1.5e-4}}}}))
    out = model_overrides_from_fit(fit, design=4, layers=2)
    assert out["actuator"] == {"pzt_modulus_Pa": 40e9, "d31_m_per_V": 2e-10}
    preset = design_preset(4).kappa_N_m_per_rad
    assert out["design"]["k_ser_N_per_m"] == 900.0 and out["design"]["bias_m"] == 1.5e-4
    assert out["design"]["kappa_N_m_per_rad"] == [preset[0], 1e-5, preset[2]]
    with pytest.raises(ConfigError, match="designs.3"):
        model_overrides_from_fit(fit, design=3, layers=1)
    fit.write_text(json.dumps({"designs": {"4": {"k_ser": {"value": "stiff"}}}}))
    with pytest.raises(ConfigError, match=r"designs\.4\.k_ser"):
        model_overrides_from_fit(fit, design=4, layers=2)


def test_steady_offset_of_a_missing_effect_is_beyond_noise(source_run, tmp_path):
    # The source's actuator gets 12 % less voltage than its amplifier's monitor reads; its nominal twin does not.
    # That lowers every driven step's force by one to two samples' noise, steadily: the RMS test alone does not see
    # it, the steady-offset test must. (The source used hysteresis until the bench's hysteresis became a Preisach
    # operator, whose loop closes at the dwells: it no longer lowers a dwell's force. A parameter effect such as
    # width loss would not do either: the twin replays the source's recorded parameters.)
    nominal = tmp_path / "nominal.mcap"
    replay_recording(source_run, nominal, effects={}, seed=SOURCE_SEED + 1)
    comparison = compare_recordings(source_run, nominal)
    force_steps = [s["channels"]["force_N"] for s in comparison["steps"] if s["index"] >= 0]
    offsets = [f for f in force_steps if f["steady_offset"]]
    assert len(offsets) >= len(force_steps) // 2
    assert all(f["mean_diff"] < 0 and abs(f["mean_diff"]) >= f["noise_diff"] for f in offsets)
    for channel in ("stage_position_m", "bias_monitor_V", "drive_monitor_V"):
        assert not comparison["channels"][channel]["exceeds_noise"], channel
