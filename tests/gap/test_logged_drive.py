"""A drive column that holds no noise is a logged command (`steps.LOGGED`): read as the staircase it is. A lab's
logger that writes the last command on every row (one per sensor sample as well as one per command step) hands
over the steps the amplifier played; a sensor sampled at its own clock sees the step in force at a phase of its
own in every waveform, and a smooth trapezoid through the corners lost that phase (on the self-check's
effect-free trials, the fast ramps' blocked-force rows sat 2-3 noise widths off, a different way in each
repetition). A camera frame, exposed over an interval, reads the steps averaged over the command step around it.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from analysis.gap.engine import RunEngine, command_step_s
from analysis.gap.heldout import determined, heldout_errors
from analysis.importer import import_trace
from hamr_bench.recording.steps import INFERRED, LOGGED, read_run

CMD_DT_S = 1e-3
FORCE_DT_S = 2e-3
N_PER_V = 6e-4


def _trapezoids(t: np.ndarray, level_V: float, ramp_s: float) -> np.ndarray:
    """Four cycles: 0.3 s low, ramp, 0.3 s high, ramp."""
    period = 0.6 + 2 * ramp_s
    u = np.mod(t - 0.1, period)
    up = np.clip((u - 0.3) / ramp_s, 0.0, 1.0)
    down = np.clip((u - 0.6 - ramp_s) / ramp_s, 0.0, 1.0)
    v = level_V * (up - down)
    return np.where((t >= 0.1) & (t < 0.1 + 4 * period), v, 0.0)


def _write_trace(path, noise_V: float, phase_s: float, seed: int = 0) -> np.ndarray:
    """A blocked-force trace as a logger writes it: a row at every 1 kHz command step and at every 500 Hz force
    sample (taken `phase_s` after a step), the voltage column the command held at each row (plus `noise_V` of
    monitor noise where it is a monitor), the force what the sensor saw at its sample. Returns the command's
    step times."""
    rng = np.random.default_rng(seed)
    span = 0.2 + 4 * (0.6 + 2 * 0.05)
    t_cmd = np.round(np.arange(0.0, span, CMD_DT_S), 9)
    v_cmd = np.round(_trapezoids(t_cmd, 200.0, 0.05), 9)
    t_force = np.round(np.arange(0.0, span - 0.01, FORCE_DT_S) + phase_s, 9)
    times = np.union1d(t_cmd, t_force)
    held = v_cmd[np.searchsorted(t_cmd, times, "right") - 1]
    volts = held + rng.normal(0.0, noise_V, times.size) if noise_V else held
    force_at = dict(zip(t_force.tolist(), (N_PER_V * v_cmd[np.searchsorted(t_cmd, t_force, "right") - 1]
                                           + rng.normal(0.0, 2e-5, t_force.size)).tolist(), strict=True))
    lines = ["time_s,voltage_V,stage_position_m,force_N"]
    for t, v in zip(times.tolist(), volts.tolist(), strict=True):
        f = force_at.get(t)
        lines.append(f"{t!r},{v!r},{'0.0' if t == times[0] else ''},{'' if f is None else repr(f)}")
    path.write_text("\n".join(lines) + "\n")
    return t_cmd


@pytest.mark.parametrize("phase_s", [0.3e-3, 0.0])
def test_a_noise_free_drive_column_is_the_logged_command_kept_where_it_changed(tmp_path, phase_s):
    csv_path = tmp_path / "blocked.csv"
    t_cmd = _write_trace(csv_path, 0.0, phase_s)
    out = tmp_path / "blocked.mcap"
    import_trace(csv_path, out, "actuator", layers=2)
    timelines = read_run(out).timelines
    assert timelines.sources["drive"] == LOGGED
    t, v = timelines.drive
    v_cmd = np.round(_trapezoids(t_cmd, 200.0, 0.05), 9)
    changed = np.r_[True, v_cmd[1:] != v_cmd[:-1]]
    # the staircase's steps at the command's own times: the repeats written at the force samples add nothing
    assert t == pytest.approx(t_cmd[changed], abs=1e-9)
    assert v == pytest.approx(v_cmd[changed], abs=1e-9)


def test_a_noisy_monitor_is_still_inferred(tmp_path):
    csv_path = tmp_path / "blocked.csv"
    _write_trace(csv_path, 0.05, 0.3e-3)
    out = tmp_path / "blocked.mcap"
    import_trace(csv_path, out, "actuator", layers=2)
    assert read_run(out).timelines.sources["drive"] == INFERRED


def _run(quantity: str, samples: np.ndarray, t_cmd: np.ndarray, v_cmd: np.ndarray) -> SimpleNamespace:
    row = SimpleNamespace(quantity=quantity, eval_times_s=samples, eval_cycle=None, ref_times_s=None,
                          ref_cycle=None)
    return SimpleNamespace(rows=[row], layers=2, params_set="effective", fixture="actuator", design=None,
                           bias_cmd=(t_cmd, v_cmd), drive_cmd=(t_cmd, v_cmd), force_reads_pull=False,
                           timelines={"drive": LOGGED})


def test_a_force_sample_reads_the_logged_step_in_force_and_a_camera_frame_the_step_around_it():
    t_cmd = 10.0 + np.arange(0.0, 0.2, CMD_DT_S)
    v_cmd = np.clip((t_cmd - t_cmd[0]) / 0.05, 0.0, 1.0) * 250.0
    samples = t_cmd[0] + 0.7e-3 + np.arange(0.0, 0.06, FORCE_DT_S)
    held = v_cmd[np.searchsorted(t_cmd, samples, "right") - 1]

    force = RunEngine(_run("force_N", samples, t_cmd, v_cmd))
    read = force._played_at("t", force.t, (0.0, 0.0))
    assert read == pytest.approx(held, abs=1e-6)        # net 2 V_drive - V_bias = the held command

    camera = RunEngine(_run("displacement_m", samples, t_cmd, v_cmd))
    assert command_step_s(t_cmd) == pytest.approx(CMD_DT_S)
    read = camera._played_at("t", camera.t, (0.0, 0.0))
    fine = np.linspace(-0.5e-3, 0.5e-3, 2001)
    around = np.array([v_cmd[np.searchsorted(t_cmd, s + fine, "right") - 1].mean() for s in samples])
    assert read == pytest.approx(around, abs=0.2)
    on_ramp = (samples > t_cmd[0] + 2e-3) & (samples < t_cmd[0] + 0.048)
    # on the ramp, the steps averaged around a frame are the ramp half a step behind, whatever the frame's phase
    ramp = (samples[on_ramp] - 0.5e-3 - t_cmd[0]) / 0.05 * 250.0
    assert read[on_ramp] == pytest.approx(ramp, abs=1e-6)


def test_a_held_out_step_leaves_a_direction_the_training_rows_do_not_see():
    """A lag read on a logged staircase moves a row only where a sample's settling window holds a step edge: on
    the training rows its column can be ~0 but for one finite difference, on the left-out rows large. Stepping
    along it by what that one entry says put held-out errors at 10^7 noise widths."""
    rng = np.random.default_rng(2)
    n = 40
    jac = np.zeros((n + 1, 2))
    jac[:n, 0] = rng.normal(1.0, 0.2, n)
    jac[5, 1] = 1e-7                 # the one training row whose difference caught an edge
    jac[30:n, 1] = 50.0              # the left-out rows, which see the lag
    jac[n, 0] = 1.0                  # a prior row
    residual = rng.normal(0.0, 1.0, n + 1)
    layout = SimpleNamespace(n_rows=n, scales=lambda: np.ones(2))
    fit = SimpleNamespace(layout=layout, residual=residual, jac=jac)
    held = np.zeros(n, bool)
    held[30:] = True
    out, spreads, _ = heldout_errors(fit, [held])   # type: ignore[arg-type]
    assert np.abs(out[held]).max() < 10.0
    assert spreads[held] == pytest.approx(np.sqrt(1.0 + (jac[30:n, 0] / np.linalg.norm(jac[~np.r_[held, False], 0]))
                                                  ** 2), rel=0.05)
    assert determined(np.array([5.0, 1e-2, 1e-4])).tolist() == [True, True, False]


def test_a_lag_column_is_the_staircase_envelope_slope_wherever_the_lag_sits(tmp_path):
    """Force samples taken in step with a logged staircase read it the same way until a lag carries them across
    the next update: the rows are flat in the lag, then steep. A fine finite difference reads 0 or several times
    the envelope's slope depending on where the fit's lag sits; the fit's Jacobian takes the secant over one update
    interval instead, the same wherever in the interval the lag is."""
    from analysis.gap.features import load_gap_data
    from analysis.gap.problem import Problem

    csv_path = tmp_path / "blocked.csv"
    _write_trace(csv_path, 0.0, 0.3e-3)
    import_trace(csv_path, tmp_path / "blocked.mcap", "actuator", layers=2)
    p = Problem(load_gap_data([tmp_path / "blocked.mcap"]))
    (chain,) = p.chains
    assert p.lag_resolution_s[chain] == pytest.approx(CMD_DT_S)
    lay = p.layout(())
    i = lay.index[("lag",) + chain]
    ramps = np.array([r.phase in ("rise", "fall") for r in p.rows])
    assert ramps.any()
    fine, secant = [], []
    for lag_s in np.arange(0.0, 1.0e-3, 0.1e-3):
        x = lay.vector()
        x[i] = lag_s
        r = p.residual(lay, x)
        x_fd = x.copy()
        x_fd[i] += 1e-5
        fine.append(((p.residual(lay, x_fd) - r) / 1e-5)[:p.y.size][ramps])
        secant.append(p._lag_secants(lay, x, np.zeros((r.size, x.size)))[:p.y.size, i][ramps])
    fine_a, secant_a = np.abs(np.array(fine)), np.abs(np.array(secant))
    # the premise: the fine difference is 0 at some lags and far above the envelope at others
    assert fine_a.min(axis=0).max() == pytest.approx(0.0, abs=1e-6 * secant_a.max())
    assert (fine_a.max(axis=0) > 2.5 * secant_a.mean(axis=0)).all()
    # the secant: the same slope within 15 % across the interval, on every ramp row
    assert (secant_a.min(axis=0) > 0.85 * secant_a.max(axis=0)).all()
    fit = p.solve((), p.initial_nuisances(), max_nfev=30)
    expected = p._lag_secants(fit.layout, fit.x, np.zeros_like(fit.jac))[:, i]
    assert fit.jac[:, i] == pytest.approx(expected)
