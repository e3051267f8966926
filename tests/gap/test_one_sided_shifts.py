"""Mechanisms that act one way only (analysis.gap.families, `_one_sided`): a laser kerf only takes width away,
imperfect grounding only lengthens the actuator. Data: one self-check trial (the simulated bench's own effect
forms, through the trace export and the importer, as `selfcheck` runs it) whose three 2-layer actuators have PZT
plates 21 % thicker than the nominal. A thicker plate and a shorter active length both stiffen the actuator and
shorten its stroke, so with the lengthening free to run backwards the diagnosis answered this trial as grounding
lengthening of about -15 %, the set's leader, with the thickness beside it. Bounded at the tolerance band on its
far side, the lengthening can no longer take a shortening far beyond tolerance."""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from analysis.gap import tolerances as tol
from analysis.gap.diagnose import diagnose
from analysis.gap.families import FAMILIES
from analysis.gap.features import load_gap_data
from analysis.gap.selfcheck import draw_trial, trial_recordings

TRIAL_SEED = 204900021     # a single-effect trial of the self-check's seed 2049
CANDIDATES = ("width_loss", "pzt_thickness", "pzt_modulus", "grounding_lengthening", "cf_thickness")


@pytest.fixture(scope="module")
def thicker_plates():
    sc = draw_trial(TRIAL_SEED)
    truth = {e.library_name: e.library_strength for e in sc.effects if not e.decoy}
    assert set(truth) == {"pzt_thickness"} and truth["pzt_thickness"] > 0.15, truth   # the trial drawn is this one
    with tempfile.TemporaryDirectory(prefix="hamr-one-sided-") as tmp:
        paths = trial_recordings(sc, TRIAL_SEED, Path(tmp))
        return diagnose(load_gap_data(paths), candidates=CANDIDATES, seed=TRIAL_SEED, jobs=2)


@pytest.mark.parametrize("name", ["width_loss", "grounding_lengthening"])
def test_a_one_way_mechanism_reaches_back_only_to_its_tolerance_band(name):
    f = FAMILIES[name]
    assert f.bounds[0] == pytest.approx(-tol.band(name, f.tolerance)) and f.bounds[1] > 0


def test_the_thicker_plates_are_not_read_as_a_shorter_actuator(thicker_plates):
    r = thicker_plates
    explained = {r.best} | {m for e in r.named if e.name == r.best for m in e.ambiguous_with}
    assert "pzt_thickness" in explained, (r.best, [(e.name, e.verdict, e.ambiguous_with) for e in r.named])
    assert "grounding_lengthening" not in explained
    grounding = next(s for s in r.screening if s.name == "grounding_lengthening")
    thickness = next(s for s in r.screening if s.name == "pzt_thickness")
    assert grounding.improvement < 0.5 * thickness.improvement, (grounding, thickness)
