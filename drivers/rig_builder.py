"""The real drivers as a backend (`drivers`): a checked rig file's device tables -> driver objects. The same function
builds the drivers for a real rig (ports from the file) and for the simulated bench (ports handed over by
`sim_devices`), which is what keeps the driver code path identical in both. The tables and their keys are
`hamr_bench.rig_file`'s (documented in docs/rig-file.md)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from hamr_bench.backends import Devices, MarkerTracker, TrafficSink
from hamr_bench.clock import Clock
from hamr_bench.errors import ConfigError
from hamr_bench.interfaces import Amplifier, Camera, DaqBackend, ForceSensor, Stage
from hamr_bench.rig_file import (
    CameraTable,
    LoadstarTable,
    Nano17Table,
    RigFile,
    SafetyLimits,
    Smc100Table,
    TrekTable,
)
from drivers.serial_line import PortOpener


@contextlib.contextmanager
def _blamed_on(where: str) -> Iterator[None]:
    """A device that refuses a setting (a DAQ channel it does not have, say) reports it in its own words; say
    where in the rig file the setting came from."""
    try:
        yield
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from None


def _serial_opener(device: str, clock: Clock, traffic: TrafficSink | None) -> PortOpener:
    import serial

    if traffic is None:
        return serial.serial_for_url
    from drivers.traffic import tapped_opener

    return tapped_opener(serial.serial_for_url, device, clock, traffic)


def _port(rig_file: RigFile, table: str, given: str | None, from_file: str | None) -> str:
    port = given or from_file
    if not port:
        raise ConfigError(f"{rig_file.where(table, 'port')} is missing")
    return port


def build_stage(rig_file: RigFile, t: Smc100Table, clock: Clock, port: str | None,
                traffic: TrafficSink | None) -> Stage:
    from drivers.newport_smc100 import NewportSMC100

    return NewportSMC100(_port(rig_file, "stage", port, t.port), clock, address=t.address, timeout_s=t.timeout_s,
                         poll_interval_s=t.poll_interval_s, command_gap_s=t.command_gap_s, limits_m=t.limits_m,
                         port_opener=_serial_opener("stage", clock, traffic))


def build_force_sensor(rig_file: RigFile, table: str, t: LoadstarTable | Nano17Table, clock: Clock,
                       ports: Mapping[str, Any], traffic: TrafficSink | None) -> ForceSensor:
    if isinstance(t, LoadstarTable):
        from drivers.loadstar import LoadstarSensor

        return LoadstarSensor(_port(rig_file, table, ports.get("force_sensor"), t.port), clock,
                              command_set=t.command_set, baudrate=t.baudrate, timeout_s=t.timeout_s,
                              stream_rate_Hz=t.stream_rate_Hz, tare_readings=t.tare_readings,
                              port_opener=_serial_opener("force_sensor", clock, traffic))
    from drivers.ati_nano17 import AtiNano17

    cal = Path(t.calibration_file)
    if not cal.is_absolute():
        cal = rig_file.path.resolve().parent / cal
    if not cal.exists():
        raise ConfigError(f"{rig_file.where(table, 'calibration_file')}: {cal} not found")
    daq = ports.get("daq") or _real_daq(t.daq_device, clock)
    with _blamed_on(rig_file.where(table, "gauge_channels")):
        return AtiNano17(daq, clock, cal, gauge_channels=t.channels(), axis=t.axis, sign=t.sign,
                         sample_rate_Hz=t.sample_rate_Hz)


def _real_daq(device: str, clock: Clock) -> DaqBackend:
    from drivers.daq_nidaqmx import NidaqmxBackend

    # The DAQ shares the rig clock: the amplifier's trip check compares its times with the rig's.
    return NidaqmxBackend(device, clock=clock)


def build_amplifiers(rig_file: RigFile, t: TrekTable, clock: Clock, daq: DaqBackend,
                     limits: SafetyLimits) -> tuple[Amplifier, Amplifier]:
    from drivers.trek_amplifier import TrekAmplifier

    def channel(output: str, monitor: str, name: str) -> Amplifier:
        with _blamed_on(rig_file.where("amplifier", f"{name}_output/{name}_monitor")):
            return TrekAmplifier(daq, clock, ao_channel=output, monitor_channel=monitor, name=f"{name} amplifier",
                                 gain_V_per_V=t.gain_V_per_V, monitor_scale_V_per_V=t.monitor_scale_V_per_V,
                                 slew_rate_V_per_s=limits.slew_rate_V_per_s, max_voltage_V=limits.max_voltage_V)

    bias = channel(t.bias_output, t.bias_monitor, "bias")
    return bias, channel(t.drive_output, t.drive_monitor, "drive")


def build_camera(t: CameraTable, clock: Clock, ports: Mapping[str, Any]) -> tuple[Camera | None,
                                                                                   MarkerTracker | None]:
    if t.backend == "none":
        return None, None
    from drivers.tracking import MarkerTracker as Tracker

    tracker = Tracker(sigma_px=t.marker_sigma_px)
    camera: Camera
    if t.backend == "pixelink":
        from drivers.camera_pixelink import PixelinkCamera

        camera = PixelinkCamera(clock)
    else:
        from drivers.camera_opencv import OpenCvCamera

        source = ports.get("camera")
        if source is None:
            source = t.device_path if t.device_path is not None else t.device
        camera = OpenCvCamera(source, clock, frame_rate_Hz=t.frame_rate_Hz,
                              device_time_is_rig_time="camera" in ports)

    def track_px(image: Any) -> tuple[float, float]:
        fix = tracker.update(image)
        return fix.x_px, fix.y_px

    track_px.reset = tracker.reset  # type: ignore[attr-defined]  # a new run starts tracking afresh
    return camera, track_px


def build_devices(rig_file: RigFile, clock: Clock, ports: Mapping[str, Any], fixture: str,
                  traffic: TrafficSink | None) -> Devices:
    """Every device of the rig (the `drivers` backend's device factory). Whatever was built is closed again if a
    later device cannot be."""
    built: list[Any] = []
    try:
        daq = ports.get("daq")
        if daq is None:  # one DAQ device serves the amplifiers and a DAQ-read force sensor
            daq = _real_daq(rig_file.amplifier.daq_device, clock)
            built.append(daq)
        ports = {**ports, "daq": daq}
        stage = build_stage(rig_file, rig_file.stage, clock, ports.get("stage"), traffic)
        built.append(stage)
        sensor_table, sensor = rig_file.force_sensor_for(fixture)
        force_sensor = build_force_sensor(rig_file, sensor_table, sensor, clock, ports, traffic)
        built.append(force_sensor)
        amp_bias, amp_drive = build_amplifiers(rig_file, rig_file.amplifier, clock, daq, rig_file.rig.limits())
        built += [amp_bias, amp_drive]
        camera, track_px = build_camera(rig_file.camera, clock, ports) if rig_file.camera else (None, None)
    except BaseException:
        for device in built:
            with contextlib.suppress(Exception):  # already failing: the first error is the one reported
                device.close()
        raise
    return Devices(stage=stage, force_sensor=force_sensor, amp_bias=amp_bias, amp_drive=amp_drive, camera=camera,
                   track_px=track_px)
