"""The nidaqmx DAQ backend: import guard without the package, and the DAQmx calls it makes, against a stand-in
`nidaqmx` module that records them (the real package needs NI hardware and drivers)."""

from __future__ import annotations

import enum
import importlib
import sys
import types

import numpy as np
import pytest

from hamr_bench.clock import VirtualClock
from hamr_bench.errors import ConfigError, DeviceFault, DeviceTimeout


def test_module_imports_without_nidaqmx_and_constructing_names_the_extra(monkeypatch) -> None:
    monkeypatch.setitem(sys.modules, "nidaqmx", None)  # makes `import nidaqmx` fail
    module = importlib.import_module("drivers.daq_nidaqmx")
    with pytest.raises(ConfigError, match=r"pip install hamr-bench\[nidaq\]"):
        module.NidaqmxDaq("Dev1", clock=VirtualClock())


class DaqError(Exception):
    def __init__(self, message: str, error_code: int) -> None:
        super().__init__(message)
        self.error_code = error_code


def fake_nidaqmx(log: list, fail: dict):
    class AcquisitionType(enum.Enum):
        FINITE = 1
        CONTINUOUS = 2

    class TerminalConfiguration(enum.Enum):
        DIFF = 10
        RSE = 11

    class Channels:
        def __init__(self, kind: str, task) -> None:
            self.kind, self.task = kind, task

        def add_ao_voltage_chan(self, name, **kw):
            self.task.channels.append(name)
            log.append(("add_ao", name, kw))

        def add_ai_voltage_chan(self, name, **kw):
            self.task.channels.append(name)
            log.append(("add_ai", name, kw["terminal_config"].name))

    class Timing:
        def __init__(self, task) -> None:
            self.task = task

        def cfg_samp_clk_timing(self, rate, sample_mode, samps_per_chan):
            self.task.n = samps_per_chan
            log.append(("timing", rate, sample_mode.name, samps_per_chan))

    class Task:
        def __init__(self) -> None:
            self.channels: list[str] = []
            self.ao_channels = Channels("ao", self)
            self.ai_channels = Channels("ai", self)
            self.timing = Timing(self)
            self.n = 1

        def write(self, data, auto_start):
            log.append(("write", np.array(data, dtype=float).tolist(), auto_start))

        def start(self):
            log.append(("start",))

        def stop(self):
            log.append(("stop",))

        def close(self):
            log.append(("close",))

        def wait_until_done(self, timeout):
            if "wait" in fail:
                raise DaqError("Wait Until Done did not indicate all samples were generated", fail["wait"])
            log.append(("wait", timeout))

        def read(self, number_of_samples_per_channel, timeout):
            if "read" in fail:
                raise DaqError("Some or all of the samples requested have not yet been acquired.\nmore",
                               fail["read"])
            n = self.n if number_of_samples_per_channel == -1 else number_of_samples_per_channel
            log.append(("read", number_of_samples_per_channel, timeout))
            return [[float(i)] * n for i in range(len(self.channels))]

    root = types.ModuleType("nidaqmx")
    root.Task = Task
    constants = types.ModuleType("nidaqmx.constants")
    constants.AcquisitionType = AcquisitionType
    constants.TerminalConfiguration = TerminalConfiguration
    constants.READ_ALL_AVAILABLE = -1
    errors = types.ModuleType("nidaqmx.errors")
    errors.DaqError = DaqError
    return {"nidaqmx": root, "nidaqmx.constants": constants, "nidaqmx.errors": errors}


@pytest.fixture
def backend(monkeypatch):
    log: list = []
    fail: dict = {}
    for name, module in fake_nidaqmx(log, fail).items():
        monkeypatch.setitem(sys.modules, name, module)
    from drivers.daq_nidaqmx import NidaqmxDaq

    clock = VirtualClock()
    return NidaqmxDaq("Dev1", clock=clock), log, fail, clock


def test_the_rig_clock_is_required(backend, monkeypatch) -> None:
    from drivers.daq_nidaqmx import NidaqmxBackend

    with pytest.raises(ConfigError, match="clock"):
        NidaqmxBackend("Dev1")


def test_waveform_is_a_finite_clocked_task_started_after_loading(backend) -> None:
    daq, log, _, clock = backend
    clock.advance_to(2.0)
    t0 = daq.write_ao_waveform("Dev1/ao0", np.array([0.0, 0.5, 1.0]), 1000.0)
    assert t0 == 2.0
    assert log == [
        ("add_ao", "Dev1/ao0", {"min_val": -10.0, "max_val": 10.0}),
        ("timing", 1000.0, "FINITE", 3),
        ("write", [0.0, 0.5, 1.0], False),
        ("start",),
    ]
    clock.advance_to(2.0015)
    assert daq.stop_ao("Dev1/ao0") == 0.5  # sample 1 is being generated 1.5 ms in
    assert log[-2:] == [("stop",), ("close",)]
    daq.write_ao_scalar("Dev1/ao0", 0.25)
    assert log[-1] == ("write", 0.25, True)


def test_ai_read_reshapes_per_channel_and_maps_timeouts(backend) -> None:
    daq, log, fail, clock = backend
    block = daq.read_ai(["Dev1/ai0", "ai1"], 4, 500.0, timeout_s=0.5)  # short names are on the device
    assert block.data_V.shape == (2, 4) and block.data_V[1, 0] == 1.0
    assert ("add_ai", "Dev1/ai0", "DIFF") in log and ("add_ai", "Dev1/ai1", "DIFF") in log
    assert ("read", 4, 0.5) in log
    fail["read"] = -200284
    with pytest.raises(DeviceTimeout) as info:
        daq.read_ai(["Dev1/ai0"], 4, 500.0)
    assert "\n" not in str(info.value) and "-200284" in str(info.value)
    fail["read"] = -201003  # device not available (unplugged)
    with pytest.raises(DeviceFault):
        daq.read_ai(["Dev1/ai0"], 4, 500.0)


def test_trek_amplifier_runs_on_the_nidaqmx_backend(backend) -> None:
    from drivers.trek_amplifier import TrekAmplifier

    daq, log, _, clock = backend
    amp = TrekAmplifier(daq, clock, ao_channel="Dev1/ao0", monitor_channel="Dev1/ai0", gain_V_per_V=35.0,
                        monitor_scale_V_per_V=100.0, slew_rate_V_per_s=1e5, check_monitor_after_set=False)
    amp.set_voltage(35.0)
    writes = [entry[1] for entry in log if entry[0] == "write"]
    assert writes[0] == 0.0 and writes[-1] == pytest.approx(1.0)
    assert max(np.diff(writes)) <= 1e5 * 1e-3 / 35.0 * (1 + 1e-9)
