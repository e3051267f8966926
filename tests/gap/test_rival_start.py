"""Two effects that explain much the same misfit (analysis.gap.ranking, a rival's carried start): after the lead
is named, the rival's joint fit started only from the lead's fit can stay in the lead's basin. Data: one case of
the external-lab generator (benchmarks/external_lab: a Krasnosel'skii-Pokrovskii hysteresis, a form this project
does not code, whose amplitude-dependent gain a field-dependent d31 also fits), imported as a user would."""

from __future__ import annotations

import csv

import pytest

from analysis.gap.diagnose import diagnose
from analysis.gap.features import load_gap_data
from analysis.gap.screening import fit_added
from benchmarks.external_lab.cases import draw_case
from benchmarks.external_lab.generate import write_case
from hamr_bench.cli import main

CASE_SEED = 4316          # a single hysteresis; the d31 curve fits it a little better alone


@pytest.fixture(scope="module")
def hysteresis_case(tmp_path_factory):
    out = tmp_path_factory.mktemp("kp")
    case = draw_case(CASE_SEED)
    assert [e["name"] for e in case.effects] == ["hysteresis"]
    write_case(case, out)
    d = out / "cases" / case.case_id
    mcaps = []
    with open(d / "files.csv", newline="") as fh:
        for row in csv.DictReader(fh):
            mcap = d / (row["file"].removesuffix(".csv") + ".mcap")
            assert main(["import", "trace", str(d / row["file"]), "--protocol", "actuator",
                         "--layers", row["layers"], "--out", str(mcap)]) == 0
            mcaps.append(mcap)
    return diagnose(load_gap_data(mcaps), seed=0, jobs=2)


def test_the_rival_named_after_the_lead_is_fitted_out_of_the_leads_basin(hysteresis_case):
    r = hysteresis_case
    steps = [s.added for s in r.waterfall[1:]]
    assert steps[:2] == ["field_dependent_d31", "hysteresis"], steps
    p, after_lead, joint = r.fits["problem"], r.fits["steps"][1], r.fits["steps"][2]
    # From the lead's fit alone (the grid start) the joint fit stops short, in the d31 curve's basin: where
    # exactly depends on the machine's floating point (274 on one CPU, 190 on another, against 161 kept), so the
    # test asks only that the fit kept is lower than that start's by more than solver noise; without the rival's
    # second start the two would be one fit.
    from_lead = fit_added(p, after_lead, "hysteresis", None, 40)
    assert joint.objective < from_lead.objective - 1.0, (joint.objective, from_lead.objective)
    hyst = next(e for e in r.named if e.name == "hysteresis")
    assert hyst.verdict == "attributed"
    assert r.unexplained["at_noise_floor"]
