"""ATI Nano17 driver: calibration-file parsing (against hand-written files whose matrix is known), 6-axis
conversion, tare, streaming, overload and faults, run through the simulated DAQ."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivers.ati_nano17 import AtiNano17, load_ati_calibration
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout
from hamr_bench.interfaces import ForceSensor
from sim_devices.daq_sim import SimDaq, SimNano17Spec, load_calibration_SI

SIM_CAL = Path(__file__).resolve().parents[2] / "sim_devices" / "data" / "nano17_sim.cal"
CHANNELS = tuple(f"Dev1/ai{i}" for i in range(6))


def write_cal(tmp_path: Path, rows: list[list[float]], torque_units: str = "N-mm",
              maxes=(12, 12, 17, 120, 120, 120), drop: str | None = None) -> Path:
    names = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
    user = "\n".join(
        f'<UserAxis Name="{n}" values="{" ".join(map(str, r))}" max="{m}"/>'
        for n, r, m in zip(names, rows, maxes) if n != drop
    )
    text = (f'<?xml version="1.0"?><FTSensor Serial="T1" BodyStyle="Nano17"><Calibration PartNumber="X" '
            f'ForceUnits="N" TorqueUnits="{torque_units}">{user}</Calibration></FTSensor>')
    path = tmp_path / "t.cal"
    path.write_text(text)
    return path


def test_parse_userAxis_rows_and_convert_torque_units(tmp_path: Path) -> None:
    rows = np.diag([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).tolist()
    cal = load_ati_calibration(write_cal(tmp_path, rows))
    # forces stay in N; N-mm rows become N m: 4 N mm per volt = 0.004 N m per volt
    np.testing.assert_allclose(np.diag(cal.matrix_SI), [1, 2, 3, 0.004, 0.005, 0.006])
    np.testing.assert_allclose(cal.max_SI, [12, 12, 17, 0.12, 0.12, 0.12])


def test_the_shipped_synthetic_file_parses_the_same_in_driver_and_sim() -> None:
    cal = load_ati_calibration(SIM_CAL)
    np.testing.assert_allclose(cal.matrix_SI, load_calibration_SI(SIM_CAL))
    assert cal.serial == "SIM00017" and cal.max_SI[2] == 17.0


@pytest.mark.parametrize("case", ["missing_row", "not_xml", "no_file", "bad_units"])
def test_bad_calibration_files_are_one_line_config_errors(tmp_path: Path, case: str) -> None:
    rows = np.eye(6).tolist()
    if case == "missing_row":
        path = write_cal(tmp_path, rows, drop="Tz")
    elif case == "not_xml":
        path = tmp_path / "x.cal"
        path.write_text("not xml <")
    elif case == "no_file":
        path = tmp_path / "absent.cal"
    else:
        path = write_cal(tmp_path, rows, torque_units="furlong")
    with pytest.raises(ConfigError) as info:
        load_ati_calibration(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def rig(wrench, *, seed=3, noise_V=1e-3, **kw):
    clock = VirtualClock()
    spec = SimNano17Spec(CHANNELS, load_calibration_SI(SIM_CAL), noise_V=noise_V)
    daq = SimDaq(clock, np.random.default_rng(seed), nano17=spec, wrench_source=wrench)
    sensor = AtiNano17(daq, clock, SIM_CAL, gauge_channels=CHANNELS, timeout_s=0.5, **kw)
    return clock, daq, sensor


def test_six_axis_round_trip_after_tare() -> None:
    load = {"on": False}
    applied = np.array([0.5, -1.0, 6.0, 0.01, -0.02, 0.005])  # N, N m

    def wrench(t: float):
        return applied if load["on"] else np.zeros(6)

    clock, daq, sensor = rig(wrench)
    assert isinstance(sensor, ForceSensor)
    sensor.tare()
    np.testing.assert_allclose(sensor.bias_V, SimNano17Spec.bias_V, atol=2e-4)  # 1 mV noise / sqrt(500)
    load["on"] = True
    got = sensor.read_wrench()
    # independent expectation: noise 1 mV per gauge through C, averaged over 50 samples
    sigma = np.sqrt(np.sum(load_calibration_SI(SIM_CAL) ** 2, axis=1)) * 1e-3 / np.sqrt(50)
    assert np.all(np.abs(got - applied) < 5 * sigma + 1e-12)
    assert sensor.read_N() == pytest.approx(6.0, abs=0.02)
    assert sensor.capacity_N == 17.0


def test_sign_and_axis_are_configurable() -> None:
    _, _, sensor = rig(lambda t: [0.0, 2.0, 0.0, 0.0, 0.0, 0.0], axis="Fy", sign=-1)
    sensor.tare()  # tare under load: the bias absorbs it
    assert sensor.read_N() == pytest.approx(0.0, abs=0.02)
    _, _, sensor = rig(lambda t: [0.0, 2.0, 0.0, 0.0, 0.0, 0.0], axis="Fy", sign=-1)
    bias_N = (load_calibration_SI(SIM_CAL) @ np.array(SimNano17Spec.bias_V))[1]  # untared: gauge offsets stay
    assert sensor.read_N() == pytest.approx(-(2.0 + bias_N), abs=0.02)


def test_stream_is_time_stamped_on_the_clock() -> None:
    clock, daq, sensor = rig(lambda t: [0, 0, 2.0 * t, 0, 0, 0], noise_V=0.0)
    sensor.start_stream()
    clock.sleep(0.1)
    samples = sensor.read_stream()
    clock.sleep(0.05)
    samples += sensor.read_stream()
    sensor.stop_stream()
    times = np.array([s.time_s for s in samples])
    assert len(samples) == 751  # 5 kHz over [0, 0.15] s inclusive
    np.testing.assert_allclose(np.diff(times), 1 / 5000.0)
    bias_N = (load_calibration_SI(SIM_CAL) @ np.array(SimNano17Spec.bias_V))[2]  # untared offset
    np.testing.assert_allclose([s.force_N for s in samples], 2.0 * times + bias_N, atol=1e-9)
    assert sensor.read_stream() == []


def test_overload_beyond_calibrated_range_is_device_fault() -> None:
    _, _, sensor = rig(lambda t: [0, 0, 18.0, 0, 0, 0])
    with pytest.raises(DeviceFault, match="overload: Fz") as info:
        sensor.read_N()
    assert "\n" not in str(info.value)


def test_gauge_saturation_is_device_fault() -> None:
    _, _, sensor = rig(lambda t: [0, 0, 0, 0.0, 0.2, 0])  # 0.2 N m on Ty: a gauge pins at the 10 V range
    with pytest.raises(DeviceFault, match="gauge"):
        sensor.read_N()


def test_disconnect_and_no_reply() -> None:
    clock, daq, sensor = rig(lambda t: np.zeros(6))
    daq.inject_fault("no_reply")
    t0 = clock.now_s()
    with pytest.raises(DeviceTimeout):
        sensor.read_N()
    assert clock.now_s() - t0 <= 0.5 + 1e-9
    daq.clear_fault("no_reply")
    daq.inject_fault("disconnect")
    with pytest.raises(DeviceFault, match="disconnected"):
        sensor.read_N()


def test_injected_overload_fault_is_device_fault() -> None:
    clock, daq, sensor = rig(lambda t: np.zeros(6))
    sensor.tare()
    daq.inject_fault("overload", at_s=clock.now_s() + 0.001)
    with pytest.raises(DeviceFault, match="overload"):
        sensor.read_N()  # 50 samples at 5 kHz: the last 40 are overloaded
