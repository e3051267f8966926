"""Serving recorded serial traffic back as the device: a run recorded on the emulators with its traffic tapped is
re-run with the real SMC100 and Loadstar drivers talking to the recording instead of the emulators, and gives the
same data; a driver that deviates from the recorded conversation is stopped at its first differing command."""

from __future__ import annotations


import numpy as np
import pytest

from analysis.replay import replay_recording
from drivers.loadstar import LoadstarSensor
from drivers.newport_smc100 import NewportSMC100
from hamr_bench.clock import VirtualClock
from hamr_bench.errors import DeviceError
from hamr_bench.protocols.session import RunRequest, run_protocol
from hamr_bench.recording import RecordingReader
from sim_devices.traffic_replay import TrafficMismatch, close_served, serve_traffic, traffic_topics
from tests.replay.test_twin import assert_same_data

OPTIONS = ["repetitions=1", "voltages_V=150,250", "drive.cycles=1"]


@pytest.fixture(scope="module")
def tapped_run(tmp_path_factory):
    """blocked-force on the simulated bench with every serial byte recorded: `run --record-traffic`."""
    out = tmp_path_factory.mktemp("traffic") / "run.mcap"
    result = run_protocol(RunRequest(protocol="blocked-force", out=out, design=4, layers=2, seed=7,
                                     set_options=OPTIONS, record_traffic=True))
    assert result.ok, result.reason
    return out


def test_run_against_recorded_traffic_gives_the_same_data(tapped_run, tmp_path):
    assert traffic_topics(tapped_run) == ["/traffic/force_sensor", "/traffic/stage"]
    twin = tmp_path / "twin.mcap"
    result, _ = replay_recording(tapped_run, twin, serve_traffic=True)
    assert result.ok, result.reason
    assert RecordingReader(twin).metadata()["replay"]["serial_devices"] == "recorded traffic"
    assert_same_data(tapped_run, twin)


def test_smc100_driver_that_deviates_is_stopped_at_the_first_differing_command(tapped_run):
    clock = VirtualClock()
    url, endpoint = serve_traffic(tapped_run, "/traffic/stage", clock)
    try:
        stage = NewportSMC100(url, clock)  # opening makes the same exchange as in the recorded run
        opened = endpoint.writes
        assert 0 < opened < endpoint.recorded_writes
        with pytest.raises(DeviceError) as info:
            stage.move_to(1e-3)  # the recorded run homed first
        message = str(info.value)
        assert isinstance(info.value, TrafficMismatch) or "differs from the recording" in message
        assert f"write #{opened + 1} differs from the recording" in endpoint.mismatch
        recorded_tx = [t.data for t in RecordingReader(tapped_run).traffic("/traffic/stage")
                       if t.direction == "tx"]
        assert repr(recorded_tx[opened]) in endpoint.mismatch  # the command the recording holds there is named
        assert "1PA" in endpoint.mismatch  # and the one the driver sent
    finally:
        close_served(url)


def test_loadstar_driver_reads_the_recorded_stream(tapped_run):
    clock = VirtualClock()
    url, endpoint = serve_traffic(tapped_run, "/traffic/force_sensor", clock)
    try:
        sensor = LoadstarSensor(url, clock)
        # the runner's calls: stream from the start of the run, pause it to tare, stream again
        sensor.start_stream()
        sensor.stop_stream()
        sensor.tare()
        sensor.start_stream()
        values = []
        for _ in range(15):
            clock.sleep(0.02)
            values += [s.force_N for s in sensor.read_stream()]
        recorded = RecordingReader(tapped_run).scalars("/force")["force_N"]
        assert len(values) > 10
        np.testing.assert_array_equal(values, recorded[:len(values)])  # the sensor's own numbers, in order
    finally:
        close_served(url)


def test_loadstar_driver_that_deviates_is_named(tapped_run):
    clock = VirtualClock()
    url, endpoint = serve_traffic(tapped_run, "/traffic/force_sensor", clock)
    try:
        sensor = LoadstarSensor(url, clock)
        sensor.start_stream()
        with pytest.raises(DeviceError):
            sensor.tare()  # without stopping the stream first: not what the recorded run sent
        assert "differs from the recording" in endpoint.mismatch
    finally:
        close_served(url)
