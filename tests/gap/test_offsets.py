"""The residual map's view of a run's zero offset (contact shift) comes from its undriven stiffness sweep when it
has one: a drive effect must not move it, or the map shows the drive effect's gap on the sweep, where data and
model agree. Attribution keeps the offset over all force rows (docs/gap.md, Method 2)."""

import numpy as np
import pytest

from analysis.gap.attribution import diagnose
from analysis.gap.features import load_gap_data
from analysis.gap.problem import Problem, offset_rows
from hamr_bench.protocols.session import RunRequest, run_protocol

ACTUATOR = ["voltages_V=100,250", "repetitions=1", "drive.cycles=2"]


# The drive effect: d31 rising 50 % from 100 V to 250 V. (Until the bench's hysteresis became a Preisach form
# whose loop closes at the dwells, these tests used hysteresis 0.12, which then lowered every plateau.)
DRIVE_EFFECT = {"field_dependent_d31": 0.5}


@pytest.fixture(scope="module")
def hysteresis_run(tmp_path_factory):
    path = tmp_path_factory.mktemp("hysteresis") / "actuator.mcap"
    run_protocol(RunRequest(protocol="actuator", out=path, layers=2, effects=DRIVE_EFFECT, seed=5,
                            set_options=ACTUATOR, overwrite=True))
    return load_gap_data([path])


def test_a_drive_effect_leaves_the_sweep_and_the_contact_alone(hysteresis_run):
    p = Problem(hysteresis_run, offsets_from_undriven=True)
    # the contact search finds the tip within a fraction of a um (tests/integration): so must the nominal fit
    assert abs(p.contact_shift[0]) < 1e-6
    z, _ = p.residual({})
    sweep = np.array([r.mode == "stiffness" for r in p.rows])
    blocked_high = np.array([r.mode == "blocked" and r.phase.startswith("high") for r in p.rows])
    # the d31 curve moves the blocked plateaus by ~10-40 mN against ~0.3 mN of noise; the sweep is undriven
    assert np.sqrt(np.mean(z[sweep] ** 2)) < 5
    assert np.sqrt(np.mean(z[blocked_high] ** 2)) > 20
    (engine,) = p.engines
    assert offset_rows(engine, True).sum() == sum(r.mode == "stiffness" for r in engine.rows) >= 2
    assert offset_rows(engine).sum() == engine.is_force_row.sum()


@pytest.mark.xfail(reason="issue 16 item 4: the bench's generator forms (Preisach hysteresis, d31 curves) share no formula with this candidate library any more; naming them is the rebuilt library's job (gap helper)", strict=False)
def test_the_map_puts_the_gap_on_the_driven_rows_and_names_the_effect(hysteresis_run):
    result = diagnose(hysteresis_run, candidates=["field_dependent_d31", "width_loss", "sensor_compliance"])
    significant = [g for g in result["where"] if g["p_value"] < 0.01]
    assert significant and all("stiffness" not in g["condition"] for g in significant[:3])
    assert result["best"] == "field_dependent_d31"
