"""A sample reads the drive as it was played (`RunEngine`): the command's staircase, whatever the phase of the
waveform's start in the engine's 1 ms dense grid. Reading the drive from that grid put each waveform's start at
its own phase within a cell, a per-step timing error of up to a cell on fast blocked-force ramps."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from analysis.gap.engine import RunEngine, _Staircase


def test_the_staircase_mean_is_the_held_commands_mean_over_any_interval():
    rng = np.random.default_rng(3)
    t_cmd = np.cumsum(rng.uniform(0.2e-3, 2e-3, 60))
    v_cmd = rng.uniform(-50.0, 250.0, 60)
    stair = _Staircase(t_cmd, v_cmd, before=0.0)
    fine = np.linspace(t_cmd[0] - 1e-3, t_cmd[-1] + 1e-3, 400_001)
    held = np.where(fine >= t_cmd[0], v_cmd[np.clip(np.searchsorted(t_cmd, fine, "right") - 1, 0, None)], 0.0)
    for start, width in zip(rng.uniform(t_cmd[0], t_cmd[-1] - 5e-3, 20), rng.uniform(1e-4, 4e-3, 20), strict=True):
        inside = (fine >= start) & (fine < start + width)
        assert stair.mean(np.array([start]), width)[0] == pytest.approx(held[inside].mean(), abs=0.05)


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
