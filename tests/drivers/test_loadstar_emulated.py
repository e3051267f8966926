"""The real Loadstar driver against the Loadstar emulator over both transports (in-process on a virtual clock,
pty on a real clock), both command sets, and every fault the emulator can inject. Expected forces come from
the force the test applies and the sensor's resolution, not from earlier runs."""

import itertools

import numpy as np
import pytest

from drivers.loadstar import LoadstarSensor
from hamr_bench.clock import RealClock, VirtualClock
from hamr_bench.errors import DeviceFault, DeviceProtocolError, DeviceTimeout
from sim_devices.loadstar_emulator import LoadstarEmulator, LoadstarParams
from sim_devices.pty_server import PtyServer
from sim_devices.serial_link import register_endpoint, unregister_endpoint

LBF_N = 4.4482216152605
RESOLUTION_N = 0.001 * LBF_N
_names = itertools.count()


class Load:
    """A force the test sets; the emulator reads it as the true force."""

    def __init__(self, force_N: float = 0.0) -> None:
        self.force_N = force_N

    def __call__(self, time_s: float) -> float:
        return self.force_N


@pytest.fixture(params=["inprocess", "pty"])
def transport(request):
    """Factory: make(params, load, streaming) -> (sensor, emulator, clock) on one transport."""
    opened = []

    def make(params=LoadstarParams(), load=None, streaming=False, **driver_kwargs):
        load = load or Load()
        driver_kwargs.setdefault("timeout_s", 0.3)
        if request.param == "inprocess":
            clock = VirtualClock()
            emulator = LoadstarEmulator(clock, load, np.random.default_rng(7), params)
            emulator.streaming = streaming
            name = f"loadstar-test-{next(_names)}"
            url = register_endpoint(name, emulator)
            opened.append(lambda: unregister_endpoint(name))
        else:
            clock = RealClock()
            emulator = LoadstarEmulator(clock, load, np.random.default_rng(7), params)
            emulator.streaming = streaming
            server = PtyServer(emulator).start()
            url = server.path
            opened.append(server.close)
        sensor = LoadstarSensor(url, clock, command_set=params.command_set, **driver_kwargs)
        opened.append(sensor.close)
        return sensor, emulator, clock

    yield make
    for close in reversed(opened):
        close()


@pytest.mark.parametrize("command_set", ["di1000", "iload"])
def test_identify_read_tare(transport, command_set):
    load = Load(2.0)
    sensor, emulator, clock = transport(LoadstarParams(command_set=command_set), load)
    # MODEL / SS0 as the emulator answers them
    model = {"di1000": "FCM DI-1000", "iload": "ILOAD"}[command_set]
    assert sensor.identify() == (model, "LS-HAMRSIM-0001")
    assert sensor.capacity_N == pytest.approx(10 * LBF_N)
    assert sensor.read_N() == pytest.approx(2.0, abs=5 * RESOLUTION_N)
    sensor.tare()
    assert sensor.read_N() == pytest.approx(0.0, abs=5 * RESOLUTION_N)
    load.force_N = 3.0
    assert sensor.read_N() == pytest.approx(1.0, abs=5 * RESOLUTION_N)


def test_drains_a_sensor_left_streaming(transport):
    sensor, emulator, clock = transport(streaming=True, load=Load(1.0))
    assert not emulator.streaming
    assert sensor.read_N() == pytest.approx(1.0, abs=5 * RESOLUTION_N)


def test_stream_rate_and_clean_stop(transport):
    load = Load(0.5)
    sensor, emulator, clock = transport(load=load)
    sensor.start_stream()
    start_s = clock.now_s()
    samples = []
    while clock.now_s() - start_s < 0.4:
        clock.sleep(0.05)
        samples += sensor.read_stream()
    elapsed_s = clock.now_s() - start_s
    # 150 lines per second unless the wire is slower: 0.5 N = 0.112 lb, 7 bytes a line at 9600 baud
    rate_Hz = min(150.0, 9600 / (10 * len(b"0.112\r\n")))
    assert abs(len(samples) - rate_Hz * elapsed_s) <= 4
    assert all(abs(s.force_N - 0.5) < 5 * RESOLUTION_N for s in samples)
    times = [s.time_s for s in samples]
    assert times == sorted(times)
    sensor.stop_stream()
    assert not emulator.streaming
    load.force_N = 0.7
    assert sensor.read_N() == pytest.approx(0.7, abs=5 * RESOLUTION_N)


def test_an_overload_that_begins_during_the_tare_is_caught_then_and_ever_after(transport):
    # The sensor's own tare would have zeroed at the saturation level and read ~0 from then on.
    sensor, emulator, clock = transport(tare_readings=16)
    emulator.faults.inject("overload", at_s=clock.now_s() + 0.05)  # ~16 readings take ~0.2 s at 9600 baud
    with pytest.raises(DeviceFault, match="overload"):
        sensor.tare()
    with pytest.raises(DeviceFault, match="overload"):
        sensor.read_N()


@pytest.mark.parametrize(
    "fault,error",
    [("no_reply", DeviceTimeout), ("garbage_bytes", DeviceProtocolError), ("dropped_bytes", DeviceTimeout),
     ("disconnect", DeviceFault), ("overload", DeviceFault)],
)
def test_faults_on_single_readings(transport, fault, error):
    sensor, emulator, clock = transport()
    emulator.faults.inject(fault)
    start_s = clock.now_s()
    with pytest.raises(error) as info:
        sensor.read_N()
    assert clock.now_s() - start_s <= 0.3 + 0.05
    message = str(info.value)
    assert message.startswith("force_sensor: ") and "\n" not in message
    if fault == "overload":
        assert "overload" in message


@pytest.mark.parametrize(
    "fault,error",
    [
        ("no_reply", DeviceTimeout),
        ("garbage_bytes", DeviceProtocolError),
        ("dropped_bytes", DeviceProtocolError),
        ("disconnect", DeviceFault),
        ("overload", DeviceFault),
    ],
)
def test_faults_while_streaming(transport, fault, error):
    sensor, emulator, clock = transport()
    sensor.start_stream()
    clock.sleep(0.05)
    sensor.read_stream()
    emulator.faults.inject(fault, at_s=clock.now_s())
    start_s = clock.now_s()
    with pytest.raises(error):
        while clock.now_s() - start_s < 2.0:
            clock.sleep(0.02)
            sensor.read_stream()
    # dropped bytes: lines merge until the line buffer overflows (256 bytes at 150 lines/s, ~0.3 s)
    assert clock.now_s() - start_s <= 0.3 + 0.1
