"""Every recorded conversation in tests/drivers/traffic/ (made with `hamr-bench run --record-traffic`,
exported
with `hamr-bench traffic export`) replayed two ways:

- against the real driver, PyMeasure style: the driver makes the recorded calls on a scripted port that checks
  every byte it writes and serves every reply from the file (a driver change that alters a byte fails here);
- against the emulator: each recorded write sent at its recorded time, every reply compared (byte for byte
for the
  SMC100, line shape for the Loadstar whose readings follow the force on it); every disagreement is listed.

The files shipped now were recorded from the emulators themselves, so the second check only shows the
emulators
are deterministic; a file recorded on a real rig (docs/hardware.md, "Contributing recorded traffic") makes it
the
independent check it is meant to be."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from drivers.traffic_tests import load_driver_test, loadstar_calls, replay_driver_test
from hamr_bench.errors import RecordingError
from hamr_bench.clock import VirtualClock
from sim_devices.loadstar_emulator import LoadstarEmulator, LoadstarParams
from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
from sim_devices.smc100_protocol import Smc100Protocol
from sim_devices.traffic_replay import emulator_disagreements

FILES = sorted((Path(__file__).parent / "traffic").glob("*.json"))


def test_there_is_recorded_traffic_to_replay():
    assert {load_driver_test(path).driver for path in FILES} == {"smc100", "loadstar"}


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_the_driver_makes_the_recorded_conversation(path):
    test = load_driver_test(path)
    results = list(replay_driver_test(test))  # raises AssertionError at the first byte that differs
    assert [call.method for call, _ in results] == [call.method for call in test.calls]


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_a_changed_byte_is_caught(path):
    test = load_driver_test(path)
    call = next(c for c in test.calls if c.method not in ("open", "read_stream"))
    sent, reply = call.exchanges[0]
    assert sent is not None
    call.exchanges[0] = (sent[:-2] + b"X" + sent[-2:], reply)
    with pytest.raises(AssertionError, match="expected"):
        list(replay_driver_test(test))


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
def test_the_emulator_answers_as_the_recorded_device(path):
    test = load_driver_test(path)
    clock = VirtualClock()
    if test.driver == "smc100":
        endpoint = Smc100Protocol(Smc100Emulator(clock, Smc100Params(**test.emulator)))
    else:
        params = LoadstarParams(**test.emulator)
        endpoint = LoadstarEmulator(clock, lambda time_s: 0.0, np.random.default_rng(0), params)
    exact = test.driver == "smc100"
    problems = emulator_disagreements(test.exchanges, test.times_s, endpoint, clock, exact=exact)
    assert not problems, f"{path.name}: {len(problems)} disagreements:\n" + "\n".join(problems)


def test_emulator_settings_in_the_files_are_real_parameters():
    fields = {"smc100": {f.name for f in dataclasses.fields(Smc100Params)},
              "loadstar": {f.name for f in dataclasses.fields(LoadstarParams)}}
    for path in FILES:
        test = load_driver_test(path)
        assert set(test.emulator) <= fields[test.driver], path.name


def test_a_conversation_with_a_sensor_tare_is_refused_with_the_exchange_named():
    # an earlier driver tared in the sensor (a reading, then CT0); this one cannot make that conversation
    exchanges = [(b"\r", b"A\r\n"), (b"UNITS\r", b"KG\r\n"), (b"LC\r", b"0.100\r\n"), (b"W\r", b"0.00001\r\n"),
                 (b"CT0\r", b"Tared\r\n")]
    with pytest.raises(RecordingError, match=r"exchange 4 is a sensor tare \(b'CT0\\r'\).*re-record"):
        loadstar_calls(exchanges)
