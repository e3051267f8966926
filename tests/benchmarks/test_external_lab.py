"""The external-lab generator (benchmarks/external_lab): independent of the project's code, deterministic
under a seed, and right in the limits that can be derived without it. The closed form below is written here
from the physics notes (section 1), not taken from the generator or from hamr_bench.model; the comparison with
hamr_bench.model is a second, separate check that the two implementations agree where they must (at zero
effect the other lab's actuator IS the project's nominal model, so a null case is a null)."""

from __future__ import annotations

import ast
import hashlib
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from benchmarks.external_lab import effects as fx
from benchmarks.external_lab import physics, score
from benchmarks.external_lab import simulate as sim
from benchmarks.external_lab.cases import draw_case
from benchmarks.external_lab.generate import write_case

PACKAGE = Path(__file__).resolve().parents[2] / "benchmarks" / "external_lab"
FORBIDDEN = ("analysis", "sim_devices", "drivers", "hamr_bench")


def _imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0, f"{path.name}: relative import"
            names.add(node.module or "")
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__"):
            raise AssertionError(f"{path.name}: dynamic import")
    return names


def test_the_generator_imports_nothing_from_the_project():
    files = sorted(PACKAGE.glob("*.py"))
    assert len(files) >= 8
    for path in files:
        bad = [m for m in _imports(path) if m.split(".")[0] in FORBIDDEN]
        assert not bad, f"{path.name} imports {bad}"


# ------------------------------------------------------------------------- the closed form, derived here
def _closed_form(layers: int) -> tuple[float, float]:
    """(F_b, delta) per volt, one plate driven, from the physics notes' laminate closed form with Table I's
    effective values (E_c = 340 GPa)."""
    tp, tc, l_act, w = 155e-6, layers * 30e-6, 9.6e-3, 3.4e-3
    lr, wr, d31, ep, ec = 0.0063, 1.5, 0.36e-9, 34e9, 340e9
    d = ep * tp / 3 * (1.5 * tc**2 + 3 * tc * tp + 2 * tp**2) + ec * tc**3 / 12
    gf = 8 * (1 - wr) ** 3 * (1 + 2 * lr) / (-6 * (wr - 1) * (-3 + 4 * lr * (wr - 1) + 2 * wr)
                                             + 3 * (-2 + 2 * lr * (wr - 1) + wr) ** 2
                                             * math.log((2 - wr) / wr))
    gd = 1 + 2 * lr
    return 0.75 * d31 * ep * w * (tp + tc) * gf / l_act, 0.25 * d31 * ep * (tp + tc) * l_act**2 * gd / d


def test_the_closed_form_gf_is_the_tapered_cantilever_integral():
    """G_F from its definition (tip compliance of the tapered beam against a uniform one, with the rigid
    extension), by quadrature: the closed form the test uses is the right one (no |ln| sign bug)."""
    wr, lr = 1.5, 0.0063
    lp = 1 + lr
    num = quad(lambda x: lp - x, 0, 1)[0]
    den = quad(lambda x: (lp - x) ** 2 / (wr + 2 * (1 - wr) * x), 0, 1)[0]
    gf_integral = num / den / 1.5
    gf_closed = 8 * (1 - wr) ** 3 * (1 + 2 * lr) / (-6 * (wr - 1) * (-3 + 4 * lr * (wr - 1) + 2 * wr)
                                                    + 3 * (-2 + 2 * lr * (wr - 1) + wr) ** 2
                                                    * math.log((2 - wr) / wr))
    assert gf_closed == pytest.approx(gf_integral, rel=1e-9)
    assert gf_closed == pytest.approx(1.204, abs=1e-3)   # the physics notes' figure


@pytest.mark.parametrize("layers", [1, 2, 3])
def test_zero_effect_fem_matches_the_closed_form(layers):
    c = physics.solve_cantilever(physics.nominal_build(layers))
    fb, delta = _closed_form(layers)
    fem_fb = c.free_bottom_m_per_V / c.compliance_m_per_N
    assert fem_fb == pytest.approx(fb, rel=1e-6)
    assert c.free_bottom_m_per_V == pytest.approx(delta, rel=1e-6)
    # blocked force x free displacement (the paper's half-cycle energy) at 250 V
    assert fem_fb * c.free_bottom_m_per_V * 250**2 == pytest.approx(fb * delta * 250**2, rel=2e-6)


@pytest.mark.parametrize("layers", [1, 2, 3])
def test_zero_effect_agrees_with_the_projects_model(layers):
    from hamr_bench.model import actuator_preset

    a = actuator_preset(layers, "effective")
    c = physics.solve_cantilever(physics.nominal_build(layers))
    assert c.free_bottom_m_per_V / c.compliance_m_per_N * 250 == pytest.approx(float(a.blocked_force_N(250)),
                                                                                rel=1e-6)
    assert c.free_bottom_m_per_V * 250 == pytest.approx(float(a.free_displacement_m(250)), rel=1e-6)


def test_bias_drive_ground_zero_sits_at_half_bias_only_for_equal_plates():
    c = physics.solve_cantilever(physics.nominal_build(2))
    vb = 200.0
    assert c.free_deflection_m(np.array(vb / 2), np.array(vb / 2)) == pytest.approx(0.0, abs=1e-15)
    # one-sided ends: +delta at V_drive = V_bias, -delta at ground
    assert c.free_deflection_m(np.array(vb), np.array(0.0)) == pytest.approx(c.free_bottom_m_per_V * vb)
    assert c.free_deflection_m(np.array(0.0), np.array(vb)) == pytest.approx(-c.free_bottom_m_per_V * vb)
    uneven = physics.solve_cantilever(replace(physics.nominal_build(2), pzt_top_m=1.2 * 155e-6))
    assert abs(uneven.free_deflection_m(np.array(vb / 2), np.array(vb / 2))) > 1e-7


def test_a_compliant_clamp_lengthens_the_actuator_as_asked():
    b = physics.nominal_build(2)
    rigid = physics.solve_cantilever(b)
    held = physics.solve_cantilever(physics.clamp_for_lengthening(b, 0.05, 1.2e-3))
    assert held.free_bottom_m_per_V / rigid.free_bottom_m_per_V == pytest.approx(1.05, rel=1e-4)
    assert held.compliance_m_per_N > rigid.compliance_m_per_N


# ------------------------------------------------------------------------------------------ effect forms
def test_kp_hysteresis_grows_with_amplitude_and_closes_its_loops():
    h = fx.KPHysteresis(share=0.3, width_scale=1.0, width_skew=0.0, ramp=0.03)
    small, large = h.loop_width(50.0), h.loop_width(250.0)
    assert 0.01 < small < 0.06 and 0.08 < large < 0.16 and large > 2 * small
    cycle = np.r_[np.linspace(0, 200, 201), np.linspace(200, 0, 201)[1:]]
    out = h.apply(np.r_[cycle, cycle[1:], cycle[1:]])
    n = cycle.size - 1
    # after the first cycle (the poling history) every cycle retraces the same loop
    assert np.allclose(out[n:2 * n + 1], out[2 * n:3 * n + 1], atol=1e-9)


def test_kohlrausch_creep_matches_its_drawn_rate_per_decade():
    case = next(c for c in (draw_case(s) for s in range(1, 200)) if c.effect("creep"))
    creep = sim.creep_of(case)
    assert creep is not None
    assert creep.per_decade() == pytest.approx(case.effect("creep")["params"]["per_decade"], rel=1e-9)


# ------------------------------------------------------------------------------ a null block, end to end
def test_a_null_blocked_block_reads_the_specimens_blocked_force():
    """No effect: the mean force over the high dwells is the specimen's own blocked force at the bias (minus
    the contact gap's share), within the sensor noise; the drive level on the voltage column is V_bias."""
    case = next(c for c in (draw_case(s) for s in range(1, 400)) if c.kind == "null")
    blocks = [b for b in sim.schedule(case) if b.test == "blocked"]
    blk = blocks[-1]
    data, _ = sim.simulate_block(case, blk, None, 0.0)
    v = data.voltage_V
    high = v > 0.995 * blk.bias_V - 3 * case.monitor["noise_V"]
    f = data.force_N[high]
    f = f[np.isfinite(f)]
    c = sim.coefficients(blk.specimen.build)
    expected = (c.free_bottom_m_per_V * blk.bias_V - blk.specimen.gap_m) / c.compliance_m_per_N
    expected /= 1 + 1 / (c.compliance_m_per_N * 1.8e7)   # the Nano17's own spring in series
    tolerance = 4 * case.force_sensor["noise_N"] / math.sqrt(f.size) + 2e-4
    assert np.mean(f) == pytest.approx(expected, abs=tolerance)
    assert np.median(v[high]) == pytest.approx(blk.bias_V, abs=0.5)


# ----------------------------------------------------------------------------------------- determinism
def test_cases_are_drawn_deterministically():
    assert draw_case(7).to_json() == draw_case(7).to_json()
    assert draw_case(7).to_json() != draw_case(8).to_json()


@pytest.mark.slow
def test_a_case_is_written_byte_identically_under_its_seed(tmp_path):
    seed = 6   # one layer count, three voltages at 1 kHz: seconds
    digests = []
    for run in ("a", "b"):
        write_case(draw_case(seed), tmp_path / run)
        files = sorted((tmp_path / run).rglob("*.csv"))
        digests.append({f.relative_to(tmp_path / run): hashlib.sha256(f.read_bytes()).hexdigest()
                        for f in files})
    assert digests[0] == digests[1] and len(digests[0]) > 4


# ------------------------------------------------------------------------------------------ the scorer
def test_the_scorer_reads_names_pairs_and_refusals():
    out = {"best": "hysteresis+creep", "ranking": [
        {"effect": "hysteresis+creep", "verdict": "attributed"},
        {"effect": "width_loss", "verdict": "unexplained"}, {"effect": "creep", "verdict": "unexplained"}]}
    r = score.CaseResult("c", "multi", ["hysteresis", "creep", "pzt_thickness"])
    score.read_answer(r, out)
    assert r.named == ["creep", "hysteresis"]
    assert score.judge(r) == "named 2/2"           # pzt_thickness has no candidate in this library
    null = score.CaseResult("n", "null", [])
    score.read_answer(null, {"best": None, "ranking": [{"effect": "creep", "verdict": "ambiguous",
                                                        "confusable_with": ["hysteresis"]}]})
    assert score.judge(null) == "ambiguous" and null.ambiguous_set == ["creep", "hysteresis"]
    line = "hamr-bench: error: f.csv:3: bad"
    assert score._reason(f"Traceback...\n  x\n{line}\n") == line
    # the issue-16 shape: a `named` list with verdicts, `best` the first that explains the gap
    single = score.CaseResult("s", "single", ["grounding"])
    score.read_answer(single, {"best": "grounding_lengthening", "named": [
        {"effect": "grounding_lengthening", "verdict": "attributed"},
        {"effect": "width_loss", "verdict": "within tolerance"},
        {"effect": "creep", "verdict": "ambiguous", "confusable_with": ["timing_lag"]}],
        "ranking": [{"effect": "grounding_lengthening"}, {"effect": "width_loss"}, {"effect": "creep"}]})
    assert single.named == ["grounding_lengthening"] and single.ambiguous_set == ["creep", "timing_lag"]
    assert score.judge(single) == "top1-correct"
    refused = score.CaseResult("r", "single", ["creep"], refused="gap: hamr-bench: error: no steps")
    assert score.judge(refused) == "refused"
    figures = score.summary([r, null, single, refused])
    assert figures["refused"] == 1 and figures["multi_effects_named"] == [2, 2]
    assert figures["single_top1"] == [1, 1] and figures["null_false_attributions"] == [0, 1]


def test_the_scorer_counts_an_effect_the_diagnosis_found_no_gap_for_as_missed():
    """With no gap above the noise the ranking is empty; the case's effect was still in the library (the gap JSON's
    `candidates`), so it is a miss, not a case without a candidate."""
    no_gap = {"best": None, "named": [], "ranking": [], "candidates": ["creep", "grounding_lengthening"]}
    single = score.CaseResult("s", "single", ["length"])
    score.read_answer(single, no_gap)
    assert score.judge(single) == "missed"
    multi = score.CaseResult("m", "multi", ["grounding", "creep"])
    score.read_answer(multi, no_gap)
    assert score.judge(multi) == "named 0/2"
    figures = score.summary([single, multi])
    assert figures["single_top1"] == [0, 1] and figures["multi_effects_named"] == [0, 2]
    older = score.CaseResult("o", "single", ["length"])      # a checkout whose JSON has no `candidates`
    score.read_answer(older, {"best": None, "named": [], "ranking": []})
    assert score.judge(older).startswith("no-candidate")
