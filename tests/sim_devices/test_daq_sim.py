"""Simulated DAQ: amplifier output against the closed-form first-order response, waveform timing on the clock,
monitor and gauge channels, faults, determinism."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from sim_devices.daq_sim import SimAmplifierSpec, SimDaq, SimNano17Spec

GAIN, BW = 35.0, 1_000.0
TAU = 1 / (2 * math.pi * BW)


def make(seed: int = 0, **kw):
    clock = VirtualClock()
    spec = SimAmplifierSpec("ao0", "ai0", gain_V_per_V=GAIN, bandwidth_Hz=BW, monitor_scale_V_per_V=100.0)
    return clock, SimDaq(clock, np.random.default_rng(seed), amplifiers=[spec], **kw)


def test_step_response_is_first_order() -> None:
    clock, daq = make()
    clock.advance_to(1.0)
    daq.write_ao_scalar("ao0", 2.0)
    t = 1.0 + np.array([0.0, TAU, 3 * TAU, 0.01])
    expected = 70.0 * (1 - np.exp(-(t - 1.0) / TAU))
    np.testing.assert_allclose(daq.output_voltage_V("ao0", t), expected, atol=1e-9)
    assert daq.output_voltage_V("ao0", 0.5) == 0.0
    # a second step starts from where the first had got to
    clock.advance_to(1.0 + TAU)
    daq.write_ao_scalar("ao0", 0.0)
    y1 = 70.0 * (1 - math.exp(-1))
    assert daq.output_voltage_V("ao0", 1.0 + 2 * TAU) == pytest.approx(y1 * math.exp(-1), rel=1e-9)


def test_sine_waveform_is_attenuated_as_a_first_order_low_pass() -> None:
    clock, daq = make()
    rate, f = 200_000.0, 1_000.0  # at the corner frequency: gain 1/sqrt(2), phase -45 deg
    n = int(0.02 * rate)
    t0 = daq.write_ao_waveform("ao0", 1.0 + np.sin(2 * np.pi * f * np.arange(n) / rate), rate)
    t = t0 + np.linspace(0.015, 0.02, 2001)
    y = daq.output_voltage_V("ao0", t) / GAIN - 1.0
    amplitude = (y.max() - y.min()) / 2
    # zero-order hold adds a half-sample delay but at 200 samples per period its magnitude effect is < 1e-4
    assert amplitude == pytest.approx(1 / math.sqrt(2), rel=2e-3)


def test_waveform_holds_last_sample_and_stop_truncates() -> None:
    clock, daq = make()
    t0 = daq.write_ao_waveform("ao0", np.array([1.0, 2.0, 3.0]), 1000.0)
    daq.wait_ao_done("ao0", timeout_s=1.0)
    assert clock.now_s() == pytest.approx(t0 + 0.003)
    assert daq.ao_value_V("ao0", 10.0) == 3.0
    t1 = daq.write_ao_waveform("ao0", np.arange(100.0) / 100, 1000.0)
    clock.sleep(0.0105)
    assert daq.stop_ao("ao0") == pytest.approx(0.10)
    assert daq.ao_value_V("ao0", t1 + 1.0) == pytest.approx(0.10)
    with pytest.raises(DeviceTimeout):
        daq.write_ao_waveform("ao0", np.zeros(10_000), 1000.0)
        daq.wait_ao_done("ao0", timeout_s=1.0)


def test_monitor_reads_output_over_scale_and_trip_collapses_it() -> None:
    clock, daq = make()
    daq.write_ao_scalar("ao0", 4.0)
    clock.sleep(0.05)
    block = daq.read_ai(["ai0"], 1000, 10_000.0)
    assert block.start_time_s == pytest.approx(0.05)
    assert clock.now_s() == pytest.approx(0.15)
    assert block.data_V.mean() == pytest.approx(1.40, abs=1e-3)
    daq.inject_fault("amp_trip")
    assert daq.output_voltage_V("ao0", clock.now_s()) == 0.0
    assert abs(daq.read_ai(["ai0"], 100, 10_000.0).data_V.mean()) < 1e-3


def test_gauges_are_inverse_calibration_plus_bias() -> None:
    clock = VirtualClock()
    cal = np.diag([2.0, 2.0, 4.0, 0.01, 0.01, 0.02])
    spec = SimNano17Spec(tuple(f"g{i}" for i in range(6)), cal, noise_V=0.0)
    daq = SimDaq(clock, np.random.default_rng(0), nano17=spec,
                 wrench_source=lambda t: [1, 0, 8.0 * t, 0, 0, 0.01])
    block = daq.read_ai([f"g{i}" for i in range(6)], 3, 10.0)
    t = np.array([0.0, 0.1, 0.2])
    np.testing.assert_allclose(block.data_V[0], 0.5 + spec.bias_V[0])
    np.testing.assert_allclose(block.data_V[2], 2.0 * t + spec.bias_V[2])
    np.testing.assert_allclose(block.data_V[5], 0.5 + spec.bias_V[5])


def test_same_seed_same_data() -> None:
    a = make(seed=7)[1].read_ai(["ai0"], 50, 1000.0).data_V
    b = make(seed=7)[1].read_ai(["ai0"], 50, 1000.0).data_V
    c = make(seed=8)[1].read_ai(["ai0"], 50, 1000.0).data_V
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_faults_and_bad_channels() -> None:
    clock, daq = make()
    with pytest.raises(ConfigError, match="ai9"):
        daq.read_ai(["ai9"], 1, 10.0)
    with pytest.raises(ConfigError):
        daq.inject_fault("smoke")
    daq.inject_fault("no_reply")
    with pytest.raises(DeviceTimeout):
        daq.read_ai(["ai0"], 1, 10.0, timeout_s=0.25)
    assert clock.now_s() == pytest.approx(0.25)
    daq.clear_fault("no_reply")
    daq.inject_fault("disconnect")
    for call in (lambda: daq.write_ao_scalar("ao0", 1.0), lambda: daq.read_ai(["ai0"], 1, 10.0)):
        with pytest.raises(DeviceFault):
            call()


def test_scheduled_trip_and_disconnect() -> None:
    clock, daq = make()
    daq.write_ao_scalar("ao0", 2.0)
    daq.inject_fault("amp_trip", "ao0", at_s=0.5)
    daq.inject_fault("disconnect", at_s=0.8)
    assert daq.output_voltage_V("ao0", 0.49) == pytest.approx(70.0)
    assert daq.output_voltage_V("ao0", 0.5) == 0.0
    clock.advance_to(0.79)
    daq.read_ai(["ai0"], 10, 1000.0)  # still connected until 0.8 s
    with pytest.raises(DeviceFault):
        daq.read_ai(["ai0"], 10, 1000.0)


def test_wait_after_a_scalar_returns_at_once_and_old_history_is_pruned() -> None:
    clock, daq = make()
    daq.write_ao_scalar("ao0", 1.0)
    daq.wait_ao_done("ao0", timeout_s=1.0)
    assert clock.now_s() == 0.0
    for k in range(1, 200):
        clock.advance_to(k * 1.0)
        daq.write_ao_scalar("ao0", k % 3)
    assert daq.output_voltage_V("ao0", 169.5) == pytest.approx(GAIN * (169 % 3))  # settled: tau = 0.16 ms
    with pytest.raises(ConfigError, match="history_s"):
        daq.output_voltage_V("ao0", 100.0)


def test_vectorised_wrench_source_is_called_once_per_block() -> None:
    calls = []

    def wrench(times_s):
        calls.append(np.size(times_s))
        times_s = np.atleast_1d(times_s)
        out = np.zeros((times_s.size, 6))
        out[:, 2] = 3.0 * times_s
        return out

    wrench.vectorised = True
    clock = VirtualClock()
    spec = SimNano17Spec(tuple(f"g{i}" for i in range(6)), np.eye(6), noise_V=0.0)
    daq = SimDaq(clock, np.random.default_rng(0), nano17=spec, wrench_source=wrench)
    block = daq.read_ai([f"g{i}" for i in range(6)], 5, 100.0)
    assert calls == [5]
    np.testing.assert_allclose(block.data_V[2], 3.0 * np.arange(5) / 100.0 + spec.bias_V[2])


def test_force_z_source_gives_the_full_products_volts_bit_for_bit() -> None:
    """A wrench that is Fz alone, given as `force_z_source`, reads the same gauge volts (noise included) as the same
    wrench through the 6x6 inverse calibration: the shortcut is exact, not an approximation."""
    from sim_devices.bench import NANO17_CAL, load_calibration_SI

    cal = load_calibration_SI(NANO17_CAL)  # a real, dense calibration: every gauge sees Fz

    def fz(times_s):
        return 0.004 * np.sin(40.0 * np.asarray(times_s)) + 0.002

    def wrench(times_s):
        out = np.zeros((np.size(times_s), 6))
        out[:, 2] = fz(times_s)
        return out

    wrench.vectorised = True
    spec = SimNano17Spec(tuple(f"g{i}" for i in range(6)), cal, noise_V=1e-3)
    reads = []
    for extra in ({}, {"force_z_source": fz}):
        clock = VirtualClock()
        daq = SimDaq(clock, np.random.default_rng(3), nano17=spec, wrench_source=wrench, **extra)
        reads.append(np.concatenate([daq.read_ai([f"g{i}" for i in range(6)], n, 1000.0).data_V
                                     for n in (1, 7, 64)], axis=1))
    assert np.array_equal(reads[0], reads[1])
