"""A real `hamr-bench run ... --sim` process killed with SIGKILL at a random moment: after `hamr-bench recover`, the
file reads back with CRC validation and with no warning, every message in it is the one the same seed run to
completion wrote (sample by sample, per topic), and every message the process had handed to its recorder at least
one flush interval before the kill is there.

The child is the real command line plus a witness thread that prints, every 10 ms of wall time, how many messages
per topic it has handed to the recorder (tests/reliability/kill_child.py). The 20-kill campaign across every
protocol is `python -m benchmarks.reliability_campaign --kills 20`.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.reliability.harness import kill_and_recover, make_reference

# Long enough (a few seconds of wall time) that a kill lands well after the first flush interval of data: the
# simulated bench got faster, and one repetition (~0.6 s) let a kill at 40 % land before the first flush.
SETTINGS = ["repetitions=12"]


@pytest.mark.slow
def test_sigkill_at_a_random_moment_then_recover_keeps_all_but_the_last_flush_interval(tmp_path):
    reference = make_reference("sag-sweep", tmp_path / "reference.mcap", seed=3, settings=SETTINGS)
    fraction = float(np.random.default_rng().uniform(0.4, 0.9))
    outcome = kill_and_recover("sag-sweep", tmp_path, reference, fraction, seed=3, settings=SETTINGS)
    print(f"killed at {fraction:.0%} of the run: {outcome.handed_at_kill} handed over, {outcome.recovered} "
          f"recovered, newest recovered handed over {outcome.lost_window_s:.3f} s before the kill")
    assert outcome.recovered > 0, "the kill came before anything was old enough to be required"
    assert not outcome.mismatched, f"recovered messages differ from the reference run: {outcome.mismatched}"
    assert not outcome.must_have_short, (
        f"samples handed over >= {outcome.flush_interval_s} s before the kill are missing: "
        f"{outcome.must_have_short}")
    assert outcome.recovered_status == "failed"  # recover's own run_end: the writer did not finish
    assert outcome.recovered < sum(len(v) for v in reference.values())  # it really was cut short
