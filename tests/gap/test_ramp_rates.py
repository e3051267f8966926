"""The diagnosis reads the ramp rates a lab drove per cycle: an imported step can hold repetitions at both rates,
and a step-level mean ramp would be neither (it made the diagnosis call hysteresis ambiguous with a timing lag on
data that had two rates); and its rows are per rate, since a mean over both reads one combination of a lag and
hysteresis (the lag fitted twice its size and the hysteresis 17 % low on a self-check trial)."""

from types import SimpleNamespace

import numpy as np
import pytest

from analysis.gap.features import RunTrace, _driven_rows, ramp_groups
from analysis.gap.problem import Problem
from hamr_bench.recording.drive_timing import Cycle
from hamr_bench.recording.steps import DriveTiming


def _engine(*steps):
    timing = {k: SimpleNamespace(ramp_up_s=sum(r) / len(r), cycles=[SimpleNamespace(ramp_up_s=x) for x in r])
              for k, r in enumerate(steps)}
    return SimpleNamespace(run=SimpleNamespace(step_timing=timing))


def test_two_ramp_rates_inside_one_imported_step_are_two_rates():
    fake = SimpleNamespace(engines=[_engine([0.05, 0.05, 0.15, 0.15])])
    assert Problem._ramp_rates(fake) == pytest.approx([0.05, 0.15])


def test_one_ramp_rate_with_timing_jitter_is_one_rate():
    fake = SimpleNamespace(engines=[_engine([0.100, 0.102, 0.099]), _engine([0.101])])
    assert len(Problem._ramp_rates(fake)) == 1


# ---------------------------------------------------------------- rows per ramp rate
LAG_S = 0.004
LEVEL_V = 100.0


def _cycle(t0: float, ramp_s: float, dwell_s: float = 0.4) -> Cycle:
    return Cycle(t0, t0 + dwell_s, t0 + dwell_s + ramp_s, t0 + 2 * dwell_s + ramp_s, t0 + 2 * dwell_s + 2 * ramp_s,
                 LEVEL_V)


def _step_of(cycles: list[Cycle]) -> SimpleNamespace:
    return SimpleNamespace(drive=DriveTiming("inferred", LEVEL_V, tuple(cycles)), tracked=False)


def _lagged_force(cycles: list[Cycle], gain_N_per_V: float = 1e-3) -> tuple:
    """A force that follows the trapezoid LAG_S late: on a ramp it sits below the drive by slope x lag, so a
    fast ramp's rise row reads lower than a slow one's."""
    t = np.arange(cycles[0].low_start_s, cycles[-1].fall_end_s, 1e-4)
    v = np.zeros_like(t)
    for c in cycles:
        tt = t - LAG_S
        up = (tt >= c.rise_start_s) & (tt < c.high_start_s)
        v[up] = LEVEL_V * (tt[up] - c.rise_start_s) / c.ramp_up_s
        v[(tt >= c.high_start_s) & (tt < c.fall_start_s)] = LEVEL_V
        down = (tt >= c.fall_start_s) & (tt < c.fall_end_s)
        v[down] = LEVEL_V * (1 - (tt[down] - c.fall_start_s) / c.ramp_down_s)
    return t, gain_N_per_V * v


def _run() -> RunTrace:
    e = (np.empty(0), np.empty(0))
    return RunTrace(0, "x.mcap", "actuator", "actuator", None, 2, "effective", {}, e, e, e, None, 0.0, 0.0)


def test_ramp_groups_split_two_rates_and_keep_jitter_together():
    fast = [_cycle(k * 1.0, 0.05) for k in range(3)] + [_cycle(3.0, 0.051)]
    slow = [_cycle(10.0 + k * 1.2, 0.15) for k in range(4)]
    assert ramp_groups(fast + slow) == [[0, 1, 2, 3], [4, 5, 6, 7]]
    assert ramp_groups(fast) == [[0, 1, 2, 3]]


def test_an_imported_step_at_two_ramp_rates_gives_one_row_per_rate():
    cycles = [_cycle(k * 1.0, 0.05) for k in range(3)] + [_cycle(10.0 + k * 1.2, 0.15) for k in range(3)]
    run = _run()
    base = dict(run=0, protocol="actuator", mode="blocked", voltage_V=LEVEL_V, sag_m=0.0, repetition=0,
                direction="", step=0)
    _driven_rows(run, _step_of(cycles), base, {"force_N": _lagged_force(cycles)})
    rise = {round(r.ramp_s, 3): r for r in run.rows if r.phase == "rise"}
    assert sorted(rise) == [0.05, 0.15]
    assert rise[0.05].n == 3 and rise[0.15].n == 3
    # the lag lowers the rise by slope x lag: 4 ms on a 50 ms ramp is 8 % of the level, on 150 ms 2.7 %
    slope_lag = {ramp: LEVEL_V * 1e-3 * LAG_S / ramp for ramp in rise}
    for ramp, row in rise.items():
        ideal = 1e-3 * LEVEL_V * 0.75      # the second half of the ramp without a lag
        assert row.value == pytest.approx(ideal - slope_lag[ramp], rel=0.02)
    # the cycles each row's model is evaluated on are its own (labels within the step)
    assert set(np.unique(rise[0.05].eval_cycle)) == {0, 1, 2}
    assert set(np.unique(rise[0.15].eval_cycle)) == {3, 4, 5}
