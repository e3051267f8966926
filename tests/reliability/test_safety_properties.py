"""Safety limits as properties (hypothesis). What is checked is what reaches the simulated hardware, not what the
software says it did:

- the DAQ analog outputs (`SimDaq` segments: every value it was told to output and when) times the amplifier gain
  never exceed the configured maximum voltage, and never change faster than the configured slew rate;
- the SMC100 emulator's motion history never leaves the stage's soft limits;
- once a force sample above the force limit has been taken, the stage starts no further move toward the leg, the
  run is aborted and both outputs end at 0 V.

Command sequences go straight to the real amplifier driver on the simulated DAQ (cheap, many examples); protocol
parameters and rig limits go through whole runs on the simulated bench (a few examples each, to keep the suite
fast).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from drivers.trek_amplifier import TrekAmplifier
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import HamrBenchError
from hamr_bench.recording import RecordingReader
from hamr_bench.rig import sim_rig_path
from sim_devices.daq_sim import SimAmplifierSpec, SimDaq
from tests.reliability.harness import AO_CHANNELS, daq_output_staircase, run_cli

GAIN = 35.0
RAMP_STEP_S = 1e-3  # TrekAmplifier's default ramp_update_rate_Hz = 1 kHz


def daq_staircase(daq: SimDaq, channel: str) -> tuple[np.ndarray, np.ndarray]:
    return daq_output_staircase(daq, channel)


def check_staircase(times: np.ndarray, daq_V: np.ndarray, max_V: float, slew_V_per_s: float, gain: float,
                    step_s: float = RAMP_STEP_S) -> None:
    hv = daq_V * gain
    assert np.all(hv <= max_V * (1 + 1e-12)) and np.all(hv >= -1e-9), f"output {hv.max():.3f} V beyond {max_V} V"
    change = np.flatnonzero(np.diff(hv) != 0) + 1
    if change.size == 0:
        return
    # A step to a new level must be no larger than the slew rate allows over the time since the previous level
    # began, and no larger than one update interval's worth (a long hold does not license a jump).
    t_prev = np.concatenate([[times[0]], times[change[:-1]]])
    held_s = np.minimum(times[change] - t_prev, step_s)
    step_V = np.abs(np.diff(hv)[change - 1])
    allowed_V = slew_V_per_s * held_s * (1 + 1e-9) + 1e-9
    worst = int(np.argmax(step_V - allowed_V))
    assert np.all(step_V <= allowed_V), (
        f"step of {step_V[worst]:.4f} V at t={times[change][worst]:.6f} s after {held_s[worst] * 1e3:.3f} ms: "
        f"faster than {slew_V_per_s} V/s")


def test_the_checks_catch_a_jump_an_overshoot_and_a_long_hold_licensing_a_jump():
    with pytest.raises(AssertionError, match="faster"):  # 10 V in 1 ms is 10 kV/s
        check_staircase(np.array([0.0, 1e-3]), np.array([0.0, 10.0 / GAIN]), 250.0, 1000.0, GAIN)
    with pytest.raises(AssertionError, match="beyond"):
        check_staircase(np.array([0.0, 1.0]), np.array([0.0, 251.0 / GAIN]), 250.0, 1e9, GAIN)
    with pytest.raises(AssertionError, match="faster"):  # held 1 s, then 5 V at once: still a 5 kV/s edge
        check_staircase(np.array([0.0, 1.0]), np.array([0.0, 5.0 / GAIN]), 250.0, 1000.0, GAIN)
    check_staircase(np.array([0.0, 1e-3, 2e-3]), np.array([0.0, 1.0, 2.0]) / GAIN, 250.0, 1000.0, GAIN)


# ------------------------------------------------------------------------------------ driver + simulated DAQ
command = st.one_of(
    st.tuples(st.just("set"), st.one_of(st.floats(-1e3, 1e3), st.sampled_from([math.nan, math.inf, -math.inf]))),
    st.tuples(st.just("wave"), st.lists(st.floats(-500, 800), min_size=1, max_size=300),
              st.sampled_from([10.0, 1e3, 1e4, 1e5])),
    st.tuples(st.just("zero")),
    st.tuples(st.just("wait"), st.floats(0, 0.05)),
    st.tuples(st.just("wait_done")),
)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(max_V=st.floats(10.0, 350.0), slew=st.floats(100.0, 1e5), commands=st.lists(command, max_size=12))
def test_no_command_sequence_exceeds_max_voltage_or_slew_rate(max_V, slew, commands):
    clock = VirtualClock()
    spec = SimAmplifierSpec(ao_channel="ao0", monitor_channel="ai6", gain_V_per_V=GAIN, bandwidth_Hz=2000.0,
                            monitor_scale_V_per_V=100.0, monitor_noise_V=0.0)
    daq = SimDaq(clock, np.random.default_rng(0), amplifiers=[spec])
    amp = TrekAmplifier(daq, clock, ao_channel="ao0", monitor_channel="ai6", gain_V_per_V=GAIN,
                        monitor_scale_V_per_V=100.0, slew_rate_V_per_s=slew, max_voltage_V=max_V)
    for cmd in commands:
        try:
            if cmd[0] == "set":
                amp.set_voltage(cmd[1])
            elif cmd[0] == "wave":
                amp.play_waveform(np.asarray(cmd[1]), cmd[2])
            elif cmd[0] == "zero":
                amp.zero()
            elif cmd[0] == "wait":
                clock.sleep(cmd[1])
            else:
                amp.wait_done()
        except HamrBenchError:
            pass  # refusing a command (NaN, bad rate) is allowed; what reached the DAQ is checked below
    amp.zero()
    times, daq_V = daq_staircase(daq, "ao0")
    check_staircase(times, daq_V, max_V, slew, GAIN)
    assert daq_V[-1] == 0.0
    # the amplifier's own output (first-order lag on the staircase) stays within the limit too
    t = np.linspace(0.0, clock.now_s(), 2000)
    assert np.all(np.asarray(daq.output_voltage_V("ao0", t)) <= max_V * (1 + 1e-9))


# ------------------------------------------------------------------------------------ whole runs
def write_rig(tmp: Path, max_V: float, slew: float, force_limit_N: float, step_m: float,
              limits_m: tuple[float, float]) -> Path:
    """The shipped simulated rig with other [rig] limits and stage soft limits."""
    text = sim_rig_path().read_text()
    for key, value in (("max_voltage_V", max_V), ("slew_rate_V_per_s", slew), ("force_limit_N", force_limit_N),
                       ("max_stage_step_m", step_m)):
        lines = [ln for ln in text.splitlines() if not ln.startswith(f"{key} ")]
        text = "\n".join(lines)
        text = text.replace("[rig]\n", f"[rig]\n{key} = {value!r}\n", 1)
    text = text.replace("toward_leg_sign = 1", f"toward_leg_sign = 1\nlimits_m = [{limits_m[0]!r}, {limits_m[1]!r}]")
    text = text.replace('calibration_file = "../sim_devices', f'calibration_file = "{sim_rig_path().parent}/'
                        '../sim_devices')
    path = tmp / "rig.toml"
    path.write_text(text)
    return path


def stage_motions(bench) -> list:
    return list(bench.stage._history)


def check_run(run, rig_max_V: float, slew: float, limits_m: tuple[float, float], force_limit_N: float) -> None:
    bench = run.bench
    if bench is None:
        # Refused before any device was built (parameter checks): nothing moved, one line says why.
        assert run.code == 2 and len(run.stderr.strip().splitlines()) == 1, run.stderr
        return
    for channel in AO_CHANNELS.values():
        times, daq_V = daq_staircase(bench.daq, channel)
        check_staircase(times, daq_V, rig_max_V, slew, GAIN)
        assert daq_V[-1] == 0.0 or run.code != 0
    low, high = limits_m
    for motion in stage_motions(bench):
        for x in (motion.x0, motion.x_end):
            assert low - 1e-9 <= x <= high + 1e-9, f"stage moved to {x} m outside soft limits {limits_m}"
    reader = RecordingReader(run.out, validate_crcs=True)
    force = reader.scalars("/force") if "/force" in reader.topics() else {"time_s": np.array([]),
                                                                           "force_N": np.array([])}
    over = np.flatnonzero(np.abs(force["force_N"]) > force_limit_N)
    if over.size:
        t_over = float(force["time_s"][over[0]])
        if t_over < wind_down_start_s(bench, run.end_s):
            assert reader.exit_status == "aborted" and "safety limit" in reader.exit_reason
        # else the run was already ending for another reason (its outputs only falling from then on): lowering
        # the bias with the leg pressed in can raise the force; nothing is left to abort, but the rest holds.
        # The runner learns of a sample when it reads the stream (it polls every 20 ms between and after steps);
        # a move it began before that may still run, but none may start toward the leg afterwards.
        later = [m for m in stage_motions(bench) if m.t0 > t_over + 0.05 and m.x_end > m.x0 + 1e-9]
        assert not later, f"stage moved toward the leg after the force limit was exceeded at {t_over:.3f} s"
        for channel in AO_CHANNELS.values():
            assert bench.daq.ao_value_V(channel, run.end_s) == 0.0


def wind_down_start_s(bench, end_s: float) -> float:
    """When the final ramp to 0 V began: on each channel the first fall of its last stretch without a rise; the
    earliest over the channels that fall (end_s if none does)."""
    start = end_s
    for channel in AO_CHANNELS.values():
        times, daq_V = daq_staircase(bench.daq, channel)
        steps = np.diff(daq_V)
        rises = np.flatnonzero(steps > 0)
        tail = rises[-1] + 1 if rises.size else 0
        falls = np.flatnonzero(steps[tail:] < 0)
        if falls.size:
            start = min(start, float(times[tail + falls[0]]))
    return start


@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(
    max_V=st.floats(50.0, 250.0),
    slew=st.floats(500.0, 2e4),
    force_limit_N=st.floats(0.002, 0.05),
    voltages=st.lists(st.floats(1.0, 400.0), min_size=1, max_size=2),
    ramp_s=st.floats(0.0, 0.05),
    sags_mm=st.lists(st.floats(0.0, 20.0), min_size=1, max_size=2),
    high_m=st.floats(0.0025, 0.012),
)
@example(max_V=200.0, slew=1000.0, force_limit_N=0.002, voltages=[400.0], ramp_s=0.0, sags_mm=[1.0, 20.0],
         high_m=0.004)  # asks for more than the limit, an instant ramp and a sag beyond the soft limit
def test_sag_sweep_with_random_parameters_and_limits_stays_inside_every_limit(
        tmp_path_factory, max_V, slew, force_limit_N, voltages, ramp_s, sags_mm, high_m):
    tmp = tmp_path_factory.mktemp("prop")
    limits = (-0.005, high_m)
    rig = write_rig(tmp, max_V, slew, force_limit_N, 0.25e-3, limits)
    settings_ = [f"sags_m={','.join(f'{s * 1e-3!r}' for s in sags_mm)}", "repetitions=1", "drive.cycles=1",
                 f"drive.ramp_s={ramp_s!r}", f"voltage_V={voltages[0]!r}"]
    run = run_cli("sag-sweep", tmp / "run.mcap", settings=settings_, rig=rig)
    assert len(run.stderr_lines) <= 1
    check_run(run, max_V, slew, limits, force_limit_N)


@settings(max_examples=5, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(
    force_limit_N=st.floats(0.001, 0.03),
    max_sag_mm=st.floats(0.2, 8.0),
    step_mm=st.floats(0.05, 1.0),
    high_m=st.floats(0.0025, 0.012),
)
@example(force_limit_N=0.003, max_sag_mm=3.0, step_mm=0.25, high_m=0.012)  # the leg pushes past 3 mN by 1 mm
def test_static_loading_stops_pushing_at_the_force_limit(tmp_path_factory, force_limit_N, max_sag_mm, step_mm,
                                                          high_m):
    tmp = tmp_path_factory.mktemp("prop")
    limits = (-0.005, high_m)
    rig = write_rig(tmp, 250.0, 1e4, force_limit_N, 0.25e-3, limits)
    settings_ = [f"max_sag_m={max_sag_mm * 1e-3!r}", f"step_m={step_mm * 1e-3!r}", "hold_s=0.1", "settle_s=0.05"]
    run = run_cli("static", tmp / "run.mcap", settings=settings_, rig=rig)
    assert len(run.stderr_lines) <= 1
    check_run(run, 250.0, 1e4, limits, force_limit_N)
