"""A sample reads the drive as it was played (`RunEngine`): the command's staircase, whatever the phase of the
waveform's start in the engine's 1 ms dense grid. Reading the drive from that grid put each waveform's start at
its own phase within a cell, a per-step timing error of up to a cell on fast blocked-force ramps."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from analysis.gap.engine import RunEngine
from analysis.gap.timebase import GridPlaces, Staircase, WindowMean


def test_the_staircase_mean_is_the_held_commands_mean_over_any_interval():
    rng = np.random.default_rng(3)
    t_cmd = np.cumsum(rng.uniform(0.2e-3, 2e-3, 60))
    v_cmd = rng.uniform(-50.0, 250.0, 60)
    stair = Staircase(t_cmd, v_cmd, before=0.0)
    fine = np.linspace(t_cmd[0] - 1e-3, t_cmd[-1] + 1e-3, 400_001)
    held = np.where(fine >= t_cmd[0], v_cmd[np.clip(np.searchsorted(t_cmd, fine, "right") - 1, 0, None)], 0.0)
    for start, width in zip(rng.uniform(t_cmd[0], t_cmd[-1] - 5e-3, 20), rng.uniform(1e-4, 4e-3, 20), strict=True):
        inside = (fine >= start) & (fine < start + width)
        assert stair.mean(np.array([start]), width)[0] == pytest.approx(held[inside].mean(), abs=0.05)


def test_a_window_mean_read_from_its_knot_table_is_the_held_commands_mean():
    """The played drive is read from a table of the window mean at its knots (`WindowMean`): checked against the
    held commands averaged on a fine grid, at window starts before, among and after the steps."""
    rng = np.random.default_rng(4)
    t_cmd = np.cumsum(rng.uniform(0.2e-3, 2e-3, 60))
    drive, bias = rng.uniform(0.0, 250.0, 60), rng.uniform(0.0, 250.0, 60)
    width = 1.3e-3
    table = WindowMean([(2.0, Staircase(t_cmd, drive, 10.0)), (-1.0, Staircase(t_cmd, bias, 20.0))], width)
    fine = np.linspace(t_cmd[0] - 5e-3, t_cmd[-1] + 5e-3, 800_001)
    k = np.searchsorted(t_cmd, fine, "right") - 1
    net = np.where(k >= 0, 2.0 * drive[np.clip(k, 0, None)] - bias[np.clip(k, 0, None)], 2.0 * 10.0 - 20.0)
    starts = np.r_[t_cmd[0] - 4e-3, rng.uniform(t_cmd[0] - width, t_cmd[-1], 30), t_cmd[-1] + 1e-3]
    for start in starts:
        inside = (fine >= start) & (fine < start + width)
        assert table(np.array([start]))[0] == pytest.approx(net[inside].mean(), abs=0.3)


def test_grid_places_interpolate_as_numpy_does_inside_and_beyond_the_grid():
    rng = np.random.default_rng(5)
    x0, dx, n = 3.0, 1e-3, 500
    y = rng.normal(size=n)
    x = np.r_[x0 - 0.01, rng.uniform(x0, x0 + dx * (n - 1), 200), x0 + dx * (n - 1), x0 + 2.0]
    got = GridPlaces.of(x, x0, dx, n).interp(y)
    assert got == pytest.approx(np.interp(x, x0 + dx * np.arange(n), y), abs=1e-9)


def _ramp_run(phase_s: float) -> SimpleNamespace:
    """A 1 kHz staircase ramp (0 -> 250 V in 50 ms, bias = drive as in a blocked-force step) starting at
    `phase_s` past a whole millisecond, and a 500 Hz force row whose samples sit 0.7 ms after the command's steps."""
    t_cmd = 10.0 + phase_s + np.arange(0, 0.2, 1e-3)
    v_cmd = np.clip((t_cmd - t_cmd[0]) / 0.05, 0.0, 1.0) * 250.0
    samples = t_cmd[0] + 0.7e-3 + np.arange(0, 0.06, 2e-3)
    row = SimpleNamespace(quantity="force_N", eval_times_s=samples, eval_cycle=None, ref_times_s=None,
                          ref_cycle=None)
    return SimpleNamespace(rows=[row], layers=2, params_set="effective", fixture="actuator", design=None,
                           bias_cmd=(t_cmd, v_cmd), drive_cmd=(t_cmd, v_cmd), force_reads_pull=False,
                           timelines={"drive": "commanded"})


def test_a_sample_reads_the_step_it_falls_on_whatever_the_waveforms_phase_in_the_grid():
    reads = []
    for phase_s in (0.0, 0.3e-3, 0.55e-3, 0.9e-3):
        run = _ramp_run(phase_s)
        engine = RunEngine(run)
        played = engine._played_at("t", engine.t, (0.0, 0.0))
        t_cmd, v_cmd = run.drive_cmd
        held = v_cmd[np.searchsorted(t_cmd, engine.t, "right") - 1]
        assert played == pytest.approx(held, abs=1e-6)      # net = 2 V_drive - V_bias = the held command
        reads.append(played)
    for other in reads[1:]:
        assert other == pytest.approx(reads[0], abs=1e-6)


def test_an_inferred_ramps_dense_cells_hold_the_ramp_the_samples_read():
    """An inferred drive is its ramp written as a staircase of samples, each at the ramp's value at its start: the
    samples read it a step ahead, so the ramp itself. The dense cells (the loops' and the gain's input) must hold
    the same ramp: a centred cell mean of that staircase trails it by half a step (1.25 V a cell on this ramp)."""
    t_ramp = 10.0 + np.arange(0, 0.051, 1e-3)                 # 0 -> 250 V in 50 ms, as `steps._trapezoids` writes
    v_ramp = (t_ramp - t_ramp[0]) / 0.05 * 250.0
    t_cmd, v_cmd = np.r_[t_ramp, 10.2], np.r_[v_ramp, 250.0]
    samples = 10.0 + 0.3e-3 + np.arange(0, 0.06, 2e-3)
    row = SimpleNamespace(quantity="force_N", eval_times_s=samples, eval_cycle=None, ref_times_s=None,
                          ref_cycle=None)
    bias = (np.array([9.0]), np.array([250.0]))
    run = SimpleNamespace(rows=[row], layers=2, params_set="effective", fixture="actuator", design=None,
                          bias_cmd=bias, drive_cmd=(t_cmd, v_cmd), force_reads_pull=False,
                          timelines={"drive": "inferred"})
    engine = RunEngine(run)
    on_ramp = (engine.dense_t > 10.002) & (engine.dense_t < 10.048)
    ramp = (engine.dense_t[on_ramp] - 10.0) / 0.05 * 250.0
    assert engine.dense_vd[on_ramp] == pytest.approx(ramp, abs=1e-6)
    # and what a sample reads at those times is the same ramp (net drive 2 V_drive - V_bias)
    read = engine._played_at("dense", engine.dense_t[on_ramp], (0.0, 0.0))
    assert read == pytest.approx(2.0 * ramp - 250.0, abs=1e-6)
