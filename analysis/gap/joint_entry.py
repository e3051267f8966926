"""Stage 3, rank, when no single effect passes: two effects entered together. Forward selection adds one effect at a
time, and two effects that each pull the nominal fit's shared parameters (a specimen's gains, the plates, a
timing lag) their own way can each fail held out alone while together they close most of the gap: fitted alone,
a leg's bias error bends the actuator parameters the legs share to absorb what a field-dependent d31 does to the
actuators, and the actuator conditions held out get worse.

So, when nothing passes at a step, the JOINT_POOL candidates with the largest in-sample improvements that each
passed the step's likelihood-ratio bar are fitted in pairs (each pair from one member's fit with the other's own
parameters carried over). A pair enters when its in-sample improvement passes the bar for both members' parameters
together, its held-out reduction's bootstrap interval is above 0, and dropping either member raises the held-out
gap (the interval of the reduction over that member alone is above 0 too): each is needed held out. Of the
pairs that enter, the lowest held-out gap is taken."""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

from analysis.gap.heldout import Judge
from analysis.gap.problem import Fit, Problem
from analysis.gap.results import StepCandidate
from analysis.gap.screening import AddOnto, carried_start, improvement, lr_bar, n_params

JOINT_POOL = 3           # candidates paired when nothing passes alone (3 pairs)


@dataclass
class JointEntry:
    """The pair that entered: `first` is the member whose fit alone left the lower held-out gap (the waterfall's
    intermediate bar), `second` the other; `row` is the second's addition to the first, judged."""

    first: str
    second: str
    fit: Fit
    row: StepCandidate


def joint_entry(p: Problem, current: Fit, rows: list[StepCandidate], tried: dict[str, Fit], judge: Judge,
                add_onto: AddOnto, bar: Callable[[str], float], alpha: float, scale2: float) -> JointEntry | None:
    """`rows`: the step's candidates as judged (none passed); `tried`: their fits; `bar(name)`: the step's
    likelihood-ratio threshold for one candidate. None when no pair enters."""
    strong = sorted((c for c in rows if c.improvement > bar(c.name)), key=lambda c: -c.improvement)[:JOINT_POOL]
    names = [c.name for c in strong]
    pairs = list(itertools.combinations(names, 2))
    if not pairs:
        return None
    fits = add_onto([(tried[a], b, carried_start(tried[a], tried[b], b)) for a, b in pairs], 40)
    entered: list[JointEntry] = []
    for (a, b), f in zip(pairs, fits, strict=True):
        pair_bar = lr_bar(n_params(p, a) + n_params(p, b), scale2, len(pairs), alpha)
        if improvement(current, f, scale2) <= pair_bar or judge.reduction_ci(current, f)[0] <= 0:
            continue
        over_alone = {n: judge.reduction_ci(tried[n], f) for n in (a, b)}   # each dropped in turn
        if min(ci[0] for ci in over_alone.values()) <= 0:
            continue
        first, second = sorted((a, b), key=lambda n: judge.heldout(tried[n]).rms)
        row = StepCandidate(second, improvement(tried[first], f, scale2), judge.heldout(f), over_alone[first],
                            float(f.effects[second].strength))
        entered.append(JointEntry(first, second, f, row))
    return min(entered, key=lambda e: e.row.heldout.rms, default=None)
