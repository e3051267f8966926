"""The stage carriage (play + stick-slip drive) against a sample-by-sample simulation written here, the drift
process's statistics, the specimen and scenario draws' distributions, and the bench's exactness properties:
strength 0 is the bench without the effect bit for bit, and the grid's values do not depend on how the bench was
asked."""

import math

import numpy as np
import pytest

from hamr_bench.model import actuator_preset, design_preset
from sim_devices.bench import BenchSettings, SimBench
from sim_devices.bench_effects import EFFECTS, REALISTIC
from sim_devices.scenarios import DECOY_EFFECTS, LEG_ONLY, STRENGTH_DRAWS, draw_scenario
from sim_devices.sensor_drift import DriftModel, DriftProcess
from sim_devices.specimens import ACTUATOR_TOLERANCES, DESIGN_TOLERANCES, draw_specimen
from sim_devices.stage_carriage import CarriageModel, CarriageState, positioning_error_bound_m


def _carriage_by_steps(motor, play, lag, rho):
    """Independent: the nut and the carriage stepped one motor sample at a time. The nut follows the motor through
    the play; the carriage slips whenever the drive spring's deflection e = nut - carriage reaches rho lag, each
    slip leaving lag (2 - rho) (repeated while the nut has gone further: the slips happen in between samples)."""
    nut = carriage = motor[0]
    out = []
    for x in motor:
        nut = min(max(nut, x - play / 2), x + play / 2)
        if lag == 0:
            carriage = nut
        elif rho == 1.0:
            e = nut - carriage
            if abs(e) > lag:
                carriage = nut - math.copysign(lag, e)
        else:
            step = 2 * lag * (rho - 1)
            while abs(nut - carriage) >= rho * lag:
                carriage += math.copysign(step, nut - carriage)
        out.append(carriage)
    return np.array(out)


@pytest.mark.parametrize("play, lag, rho", [(10e-6, 0.0, 1.3), (10e-6, 0.5e-6, 1.0), (8e-6, 0.6e-6, 1.4)])
def test_carriage_matches_a_sample_by_sample_simulation(play, lag, rho):
    # knots at irrational positions: no motor sample lands exactly on a slip threshold
    k = [0.0, 60e-6 * math.pi / 3, 10e-6 * math.e / 3, 30e-6 * math.sqrt(2) / 1.5, -20e-6 * math.sqrt(3) / 2]
    path = np.concatenate([np.linspace(k[0], k[1], 3001), np.full(50, k[1]), np.linspace(k[1], k[2], 2501),
                           np.linspace(k[2], k[3], 1001), np.linspace(k[3], k[4], 2501)])
    model = CarriageModel(play, lag, rho)
    state = CarriageState.at_rest(0.0)
    got = np.concatenate([model.run(path[i:i + 700], state) for i in range(0, path.size, 700)])   # in blocks
    np.testing.assert_allclose(got, _carriage_by_steps(path, play, lag, rho), rtol=0, atol=1e-12)
    moving_back = np.abs(path - got)[-1]
    assert moving_back <= positioning_error_bound_m(model) + 1e-12


def test_drift_is_a_random_walk_of_its_rate_plus_a_warm_up():
    rate, h = 2e-5, 2.5e-4
    model = DriftModel(rate, warmup_N=3e-4, warmup_tau_s=60.0, reversion_s=1e6)
    walks = []
    for seed in range(40):
        proc = DriftProcess(model, h, seed)
        n = 40_000                                     # 10 s
        walks.append(proc.run(0, n, h * np.arange(n)))
    walks = np.array(walks)
    t = h * np.arange(n)
    warm = 3e-4 * -np.expm1(-t / 60.0)
    increments = (walks[:, -1] - warm[-1]) - (walks[:, 0] - warm[0])
    # the variance of a random walk of rate sigma over T is sigma^2 T (40 walks: chi^2 with 40 dof, +-45 %)
    assert np.var(increments) == pytest.approx(rate ** 2 * (t[-1] - t[0]), rel=0.45)
    assert abs(np.mean(walks[:, -1]) - warm[-1]) < 3 * rate * math.sqrt(t[-1]) / math.sqrt(40)


def test_drift_values_do_not_depend_on_how_the_grid_was_split():
    model = DriftModel(2e-5)
    one = DriftProcess(model, 2.5e-4, 7).run(0, 10_000, np.zeros(10_000))
    proc = DriftProcess(model, 2.5e-4, 7)
    parts = [proc.run(k, min(997, 10_000 - k), np.zeros(min(997, 10_000 - k))) for k in range(0, 10_000, 997)]
    np.testing.assert_allclose(np.concatenate(parts), one, rtol=1e-12, atol=1e-18)


def test_specimen_scatter_has_its_tolerances_distribution():
    a = actuator_preset(2, "effective")
    d = design_preset(4)
    draws = [draw_specimen(s, a.__dict__, d.__dict__) for s in range(3000)]
    for name, tol in ACTUATOR_TOLERANCES.items():
        rel = np.array([x["actuator"][name] for x in draws]) / getattr(a, name) - 1.0
        assert abs(np.mean(rel)) < 4 * tol.sigma / math.sqrt(len(draws))
        # a normal truncated at 2.5 sigma has a standard deviation of 0.9657 sigma
        assert np.std(rel) == pytest.approx(0.9657 * tol.sigma, rel=0.05)
        assert np.max(np.abs(rel)) <= 2.5 * tol.sigma + 1e-12
    bias = np.array([x["design"]["bias_m"] for x in draws]) - d.bias_m
    assert np.std(bias) == pytest.approx(0.9657 * DESIGN_TOLERANCES["bias_m"].sigma, rel=0.05)
    kappa2 = np.array([x["design"]["kappa_N_m_per_rad"][1] for x in draws]) / d.kappa_N_m_per_rad[1] - 1
    assert np.std(kappa2) == pytest.approx(0.9657 * DESIGN_TOLERANCES["kappa_N_m_per_rad"].sigma, rel=0.05)


def test_scenario_draws_follow_the_proportions_and_ranges_asked():
    n = 1500
    cases = [draw_scenario(s, null_fraction=0.2, decoy_fraction=0.1, multi_fraction=0.4, n_specimens=2)
             for s in range(n)]
    kinds = {k: sum(c.kind == k for c in cases) / n for k in ("null", "decoy", "single", "multi")}
    assert kinds["null"] == pytest.approx(0.2, abs=4 * math.sqrt(0.2 * 0.8 / n))
    assert kinds["decoy"] == pytest.approx(0.1, abs=4 * math.sqrt(0.1 * 0.9 / n))
    library = 1 - 0.2 - 0.1
    assert kinds["multi"] / library == pytest.approx(0.4, abs=0.06)
    for c in cases:
        assert (c.kind == "null") == (not c.effects)
        assert len({e.name for e in c.effects}) == len(c.effects) <= 3
        assert (c.kind == "decoy") == any(e.decoy for e in c.effects)
        for e in c.effects:
            low, high, _, signed = STRENGTH_DRAWS[e.name]
            size = abs(e.strength) if e.name != "field_dependent_d31" or e.strength > 0 else \
                -e.strength / (1 + e.strength)
            assert low * (1 - 1e-12) <= size <= high * (1 + 1e-12)
            assert EFFECTS[e.name].low <= e.strength <= EFFECTS[e.name].high
        assert len(c.specimens) == 2 and c.specimens[0].seed != c.specimens[1].seed
    actuator_only = [draw_scenario(s, fixtures=("actuator",)) for s in range(300)]
    assert not any(e.name in LEG_ONLY for c in actuator_only for e in c.effects)
    assert {e.name for c in cases for e in c.effects if e.decoy} <= set(DECOY_EFFECTS)


def test_a_scenarios_rig_file_builds_the_bench_it_describes(tmp_path):
    from hamr_bench.rig import load_rig

    case = next(c for c in (draw_scenario(s) for s in range(100)) if c.kind == "multi")
    path = case.rig_file(tmp_path / "rig.toml", specimen=1)
    rig = load_rig(path, fixture="actuator")
    try:
        truth = rig.bench.truth()
    finally:
        rig.close()
    assert truth["effects"] == pytest.approx(case.effects_argument())
    assert truth["effect_shapes"] == case.shapes_argument()
    for name, value in case.specimens[1].actuator.items():
        base = truth["actuator"][name]
        if not any(e.name in ("width_loss", "pzt_thickness", "pzt_modulus", "grounding_lengthening")
                   for e in case.effects):
            assert base == pytest.approx(value, rel=1e-12)


def _short_run(tmp_path, name, effects, protocol="blocked-force", rig=None):
    from hamr_bench.protocols.session import RunRequest, run_protocol
    from hamr_bench.recording import RecordingReader

    out = tmp_path / f"{name}.mcap"
    options = ["voltages_V=150", "repetitions=1", "drive.cycles=1"] if protocol == "blocked-force" else \
        ["voltages_V=250", "repetitions=1", "drive.cycles=1", "stiffness.steps=2"]
    result = run_protocol(RunRequest(protocol=protocol, out=out, seed=2, effects=effects, set_options=options,
                                     rig_path=rig))
    assert result.ok, result.reason
    r = RecordingReader(out)
    return {t: r.scalars(t) for t in ("/force", "/amplifier/drive/monitor", "/stage/position")}


@pytest.mark.parametrize("protocol", ["blocked-force", "actuator"])
def test_strength_zero_is_the_bench_without_the_effect_bit_for_bit(tmp_path, protocol):
    base = _short_run(tmp_path, "base", {}, protocol)
    zeros = _short_run(tmp_path, "zeros", {name: 0.0 for name in EFFECTS}, protocol)
    for topic, cols in base.items():
        for field, values in cols.items():
            assert np.array_equal(values, zeros[topic][field]), (topic, field)


def test_the_same_seed_records_the_same_bits(tmp_path):
    effects = {"hysteresis": 0.12, "creep": 0.015, "sensor_drift": 2e-5, "stage_backlash": 5e-6}
    first = _short_run(tmp_path, "a", effects)
    second = _short_run(tmp_path, "b", effects)
    for topic, cols in first.items():
        for field, values in cols.items():
            assert np.array_equal(values, second[topic][field]), (topic, field)


def test_grid_values_do_not_depend_on_how_the_bench_was_asked():
    """Two benches, one drive: one asked densely, the other rarely; the plant's stored grid agrees where both
    computed it, to rounding (a block's values depend only on the inputs before them; the block-wise sums of the
    recursions round differently)."""
    effects = {"hysteresis": 0.1, "creep": 0.02, "field_dependent_d31": 0.4, "sensor_drift": 2e-5}
    benches = [SimBench(BenchSettings(fixture="leg", effects=effects, noise=False)) for _ in range(2)]
    try:
        for bench, step in zip(benches, (0.003, 0.21), strict=True):
            bench.daq.write_ao_scalar("ao0", 200.0 / 35)
            bench.daq.write_ao_waveform("ao1", np.concatenate([np.linspace(0, 200, 100), np.linspace(200, 0, 100),
                                                               np.zeros(300)]) / 35, 1000.0)
            t = 0.0
            while t < 1.0:
                bench.contact_forces_N(np.array([t]))
                t += step
                bench.clock.sleep(step)
        a, b = (bench.plant.cols for bench in benches)
        n = min(len(a["u"]), len(b["u"]), 4000)
        for name in ("u", "x", "free"):
            np.testing.assert_allclose(a[name][:n], b[name][:n], rtol=1e-11, atol=1e-18, err_msg=name)
    finally:
        for bench in benches:
            bench.close()


def test_realistic_strengths_are_inside_their_ranges():
    for name, spec in EFFECTS.items():
        assert spec.low <= REALISTIC[name] <= spec.high, name
