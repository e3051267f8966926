"""Two effects entered together when neither passes alone (analysis.gap.joint_entry): the rule's parts on stand-in
fits and a stand-in judge whose held-out figures are set by hand, so each condition can be switched off alone.
The five-effect campaign that needs it is regenerated and diagnosed in test_five_effect_campaign.py."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

import analysis.gap.joint_entry as je
from analysis.gap.results import HeldOut, StepCandidate


@dataclass
class _Effect:
    strength: float


@dataclass
class _Fit:
    names: tuple[str, ...]
    objective: float
    effects: dict[str, _Effect] = field(default_factory=dict)


class _Judge:
    """Held-out RMS by the set of effects in a fit; a reduction's interval is the ratio +- 0.05."""

    def __init__(self, rms: dict[frozenset, float]) -> None:
        self.rms = rms

    def heldout(self, fit: _Fit) -> HeldOut:
        r = self.rms[frozenset(fit.names)]
        return HeldOut(r, (0.9 * r, 1.1 * r))

    def reduction_ci(self, base: _Fit, new: _Fit) -> tuple[float, float]:
        red = 1.0 - self.heldout(new).rms / self.heldout(base).rms
        return red - 0.05, red + 0.05


def _row(name: str, improvement: float) -> StepCandidate:
    return StepCandidate(name, improvement, HeldOut(0.0, (0.0, 0.0)), (-0.1, 0.2), 1.0)


@pytest.fixture(autouse=True)
def _one_parameter_each(monkeypatch):
    monkeypatch.setattr(je, "n_params", lambda p, name: 1)
    monkeypatch.setattr(je, "carried_start", lambda base, other, name: {})
    # the improvement of a fit over another is their objectives' difference (over-dispersion 1)
    monkeypatch.setattr(je, "improvement", lambda before, after, scale2: before.objective - after.objective)


def _pair_fitter(objectives: dict[frozenset, float]):
    def add_onto(tasks, max_nfev):
        out = []
        for base, n, _start in tasks:
            key = frozenset(base.names + (n,))
            out.append(_Fit(base.names + (n,), objectives[key], {m: _Effect(0.5) for m in key}))
        return out
    return add_onto


NOMINAL = _Fit((), 10_000.0)
SINGLES = {"a": _Fit(("a",), 6_000.0, {"a": _Effect(1.0)}), "b": _Fit(("b",), 7_000.0, {"b": _Effect(1.0)}),
           "c": _Fit(("c",), 9_000.0, {"c": _Effect(1.0)})}
ROWS = [_row("a", 4_000.0), _row("b", 3_000.0), _row("c", 1_000.0)]
PAIRS = {frozenset("ab"): 500.0, frozenset("ac"): 5_900.0, frozenset("bc"): 6_900.0}


def _enter(rms: dict[frozenset, float], rows=ROWS, pairs=PAIRS):
    return je.joint_entry(None, NOMINAL, rows, SINGLES, _Judge(rms), _pair_fitter(pairs), lambda n: 50.0,
                          0.01, 1.0)


def _rms(**over: float) -> dict[frozenset, float]:
    base = {"": 20.0, "a": 22.0, "b": 19.0, "c": 20.5, "ab": 4.0, "ac": 21.0, "bc": 19.5}
    base |= over
    return {frozenset(k): v for k, v in base.items()}


def test_two_effects_that_fail_alone_enter_together_the_lower_alone_first():
    entry = _enter(_rms())
    assert entry is not None
    assert (entry.first, entry.second) == ("b", "a")        # b alone left the lower held-out gap
    assert entry.row.name == "a" and entry.row.heldout.rms == 4.0
    assert entry.row.improvement == SINGLES["b"].objective - 500.0


def test_no_pair_when_the_pair_does_not_lower_the_held_out_gap():
    assert _enter(_rms(ab=19.5)) is None


def test_no_pair_when_dropping_one_member_would_not_raise_the_held_out_gap():
    # with a alone as good as the pair, b is not needed held out
    assert _enter(_rms(a=4.1)) is None


def test_no_pair_without_two_candidates_past_the_in_sample_bar():
    rows = [_row("a", 4_000.0), _row("b", 40.0), _row("c", 10.0)]
    assert _enter(_rms(), rows=rows) is None


def test_a_pair_must_pass_the_in_sample_bar_for_both_members_parameters():
    pairs = PAIRS | {frozenset("ab"): NOMINAL.objective - 5.0}
    assert _enter(_rms(), pairs=pairs) is None


def test_of_several_pairs_that_enter_the_lowest_held_out_gap_is_taken():
    entry = _enter(_rms(ac=3.0))
    assert entry is not None and {entry.first, entry.second} == {"a", "c"}
