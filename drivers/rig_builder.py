"""Rig file device tables -> driver objects. The same function builds the drivers for a real rig (ports from the
file) and for the simulated bench (ports handed over by `sim_devices`), which is what keeps the driver code path
identical in both. Backend names and their settings are documented in docs/rig-file.md."""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import Any, Callable

from hamr_bench.clock import Clock
from hamr_bench.config import Section, section
from hamr_bench.errors import ConfigError

TrafficSink = Callable[[str, float, str, bytes], None]


@contextlib.contextmanager
def _blamed_on(table: Section, keys: str):
    """A device that refuses a setting (a DAQ channel it does not have, say) reports it in its own words; say
    where in the rig file the setting came from."""
    try:
        yield
    except ConfigError as exc:
        raise ConfigError(f"{table.where(keys)}: {exc}") from None


def _serial_opener(device: str, clock: Clock, traffic: TrafficSink | None):
    import serial

    if traffic is None:
        return serial.serial_for_url
    from drivers.traffic import tapped_opener

    return tapped_opener(serial.serial_for_url, device, clock, traffic)


def build_stage(table: Section, clock: Clock, port: str | None, traffic: TrafficSink | None):
    table.str("backend", choices=("smc100",))
    from drivers.newport_smc100 import NewportSMC100

    settings = dict(
        address=table.int("address", 1, lo=1, hi=31),
        timeout_s=table.float("timeout_s", 0.5, positive=True),
        poll_interval_s=table.float("poll_interval_s", 0.05, positive=True),
        command_gap_s=table.float("command_gap_s", 0.0, lo=0.0),
        limits_m=table.float_pair("limits_m", None) if table.has("limits_m") else None,
    )
    table.mark_used("port", "toward_leg_sign")
    table.check_no_unknown_keys()
    return NewportSMC100(port or table.str("port"), clock, **settings,
                         port_opener=_serial_opener("stage", clock, traffic))


def build_force_sensor(table: Section, clock: Clock, ports: dict[str, Any], traffic: TrafficSink | None,
                       rig_dir: Path):
    backend = table.str("backend", choices=("loadstar", "nano17"))
    table.mark_used("port", "daq_device")
    if backend == "loadstar":
        from drivers.loadstar import LoadstarSensor

        settings = dict(
            command_set=table.str("command_set", "di1000", choices=("di1000", "iload")),
            baudrate=table.int("baudrate", 9600, lo=1),
            timeout_s=table.float("timeout_s", 0.5, positive=True),
            stream_rate_Hz=table.float("stream_rate_Hz", 150.0, positive=True),
        )
        table.check_no_unknown_keys()
        return LoadstarSensor(ports.get("force_sensor") or table.str("port"), clock, **settings,
                              port_opener=_serial_opener("force_sensor", clock, traffic))
    from drivers.ati_nano17 import AtiNano17

    cal = Path(table.str("calibration_file"))
    if not cal.is_absolute():
        cal = rig_dir / cal
    if not cal.exists():
        raise ConfigError(f"{table.where('calibration_file')}: {cal} not found")
    settings = dict(
        gauge_channels=tuple(c.strip() for c in table.str("gauge_channels").split(",")),
        axis=table.str("axis", "Fz", choices=("Fx", "Fy", "Fz")),
        sign=table.float("sign", 1.0),
        sample_rate_Hz=table.float("sample_rate_Hz", 1000.0, positive=True),
    )
    table.check_no_unknown_keys()
    daq = ports.get("daq") or _real_daq(table, clock)
    with _blamed_on(table, "gauge_channels"):
        return AtiNano17(daq, clock, cal, **settings)


def _real_daq(table: Section, clock: Clock):
    from drivers.daq_nidaqmx import NidaqmxBackend

    # The DAQ shares the rig clock: the amplifier's trip check compares its times with the rig's.
    return NidaqmxBackend(table.str("daq_device", "Dev1"), clock=clock)


def build_amplifiers(table: Section, clock: Clock, ports: dict[str, Any], max_voltage_V: float,
                     slew_rate_V_per_s: float):
    table.str("backend", choices=("trek",))
    from drivers.trek_amplifier import TrekAmplifier

    common = dict(
        gain_V_per_V=table.float("gain_V_per_V", positive=True),
        monitor_scale_V_per_V=table.float("monitor_scale_V_per_V", positive=True),
        slew_rate_V_per_s=slew_rate_V_per_s,
        max_voltage_V=max_voltage_V,
    )
    channels = {key: table.str(key) for key in ("bias_output", "bias_monitor", "drive_output", "drive_monitor")}
    table.mark_used("daq_device")
    table.check_no_unknown_keys()
    daq = ports.get("daq") or _real_daq(table, clock)
    with _blamed_on(table, "bias_output/bias_monitor"):
        bias = TrekAmplifier(daq, clock, ao_channel=channels["bias_output"],
                             monitor_channel=channels["bias_monitor"], name="bias amplifier", **common)
    with _blamed_on(table, "drive_output/drive_monitor"):
        drive = TrekAmplifier(daq, clock, ao_channel=channels["drive_output"],
                              monitor_channel=channels["drive_monitor"], name="drive amplifier", **common)
    return bias, drive


def build_camera(table: Section, clock: Clock, ports: dict[str, Any]):
    backend = table.str("backend", choices=("opencv", "pixelink", "none"))
    if backend == "none":
        return None, None
    from drivers.tracking import MarkerTracker

    tracker = MarkerTracker(sigma_px=table.float("marker_sigma_px", 2.0, positive=True))
    frame_rate_Hz = table.float("frame_rate_Hz", 60.0, positive=True)
    table.mark_used("device", "device_path", "metres_per_pixel", "displacement_sign")
    table.check_no_unknown_keys()
    if backend == "pixelink":
        from drivers.camera_pixelink import PixelinkCamera

        camera = PixelinkCamera(clock)
    else:
        from drivers.camera_opencv import OpenCvCamera

        source = ports.get("camera")
        if source is None:
            source = table.int("device", 0) if not table.has("device_path") else table.str("device_path")
        camera = OpenCvCamera(source, clock, frame_rate_Hz=frame_rate_Hz, device_time_is_rig_time="camera" in ports)

    def track_px(image):
        fix = tracker.update(image)
        return fix.x_px, fix.y_px

    track_px.reset = tracker.reset
    return camera, track_px


def build_devices(doc: dict[str, Any], source: str, clock: Clock, ports: dict[str, Any], fixture: str,
                  limits: Any, traffic: TrafficSink | None) -> dict[str, Any]:
    """Every device of the rig, as a dict of role -> driver (and the camera's tracker)."""
    rig_dir = Path(source).resolve().parent
    devices: dict[str, Any] = {}
    built = []
    try:
        if "daq" not in ports:  # one DAQ device serves the amplifiers and a DAQ-read force sensor
            ports = {**ports, "daq": _real_daq(section(doc, source, "amplifier"), clock)}
            built.append(ports["daq"])
        stage_table = section(doc, source, "stage")
        devices["stage"] = build_stage(stage_table, clock, ports.get("stage"), traffic)
        built.append(devices["stage"])
        sensor_table_name = "actuator_force_sensor" if fixture == "actuator" and "actuator_force_sensor" in doc \
            else "force_sensor"
        devices["force_sensor"] = build_force_sensor(section(doc, source, sensor_table_name), clock, ports,
                                                     traffic, rig_dir)
        built.append(devices["force_sensor"])
        amp_table = section(doc, source, "amplifier")
        devices["amp_bias"], devices["amp_drive"] = build_amplifiers(
            amp_table, clock, ports, limits.max_voltage_V, limits.slew_rate_V_per_s)
        built += [devices["amp_bias"], devices["amp_drive"]]
        camera_table = section(doc, source, "camera", required=False)
        devices["camera"], devices["track_px"] = (None, None) if camera_table is None else build_camera(
            camera_table, clock, ports)
        devices["metres_per_pixel"] = camera_table.float("metres_per_pixel", 1e-5, positive=True) \
            if camera_table else 1.0
        devices["displacement_sign"] = camera_table.float("displacement_sign", 1.0) if camera_table else 1.0
        devices["stage_toward_leg_sign"] = stage_table.float("toward_leg_sign", 1.0)
        if devices["stage_toward_leg_sign"] not in (1.0, -1.0):
            raise ConfigError(f"{stage_table.where('toward_leg_sign')}: expected 1 or -1")
    except BaseException:
        for device in built:
            try:
                device.close()
            except Exception:  # noqa: BLE001 - already failing; report the first error
                pass
        raise
    return devices
