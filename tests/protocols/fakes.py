"""Minimal in-memory devices and recorder for testing the runner's logic without drivers or emulators.

The physics is deliberately trivial (a linear spring leg and an ideal amplifier): these fakes test what the
runner does with devices, not the devices."""

from __future__ import annotations

import numpy as np

from hamr_bench.clock import VirtualClock
from hamr_bench.errors import DeviceFault, SafetyLimitError
from hamr_bench.interfaces import ForceSample
from hamr_bench.rig import Rig, SafetyLimits


class FakeStage:
    def __init__(self, clock, limits_m=(-0.01, 0.02), speed_m_per_s=0.002):
        self.clock, self._limits, self.speed = clock, limits_m, speed_m_per_s
        self.position, self.stopped, self.moves = 0.0, 0, []

    @property
    def limits_m(self):
        return self._limits

    def home(self):
        self.move_to(0.0)

    def move_to(self, position_m):
        if not self._limits[0] <= position_m <= self._limits[1]:
            raise SafetyLimitError("fake stage: outside limits")
        self.clock.sleep(abs(position_m - self.position) / self.speed)
        self.position = position_m
        self.moves.append(position_m)

    def position_m(self):
        return self.position

    def is_moving(self):
        return False

    def stop(self):
        self.stopped += 1

    def close(self):
        pass


class FakeAmp:
    def __init__(self, clock, max_voltage_V=250.0):
        self.clock, self.max_voltage_V, self.slew_rate_V_per_s = clock, max_voltage_V, 1e4
        self.value, self.waveform, self.zeroed = 0.0, None, 0

    def set_voltage(self, voltage_V):
        self.waveform = None
        self.value = min(max(voltage_V, 0.0), self.max_voltage_V)

    def play_waveform(self, voltage_V, sample_rate_Hz):
        self.waveform = (self.clock.now_s(), sample_rate_Hz, np.clip(voltage_V, 0, self.max_voltage_V))
        return self.waveform[0]

    def wait_done(self):
        start, rate, samples = self.waveform
        self.clock.advance_to(start + (len(samples) - 1) / rate)
        self.value = float(samples[-1])
        self.waveform = None

    def commanded_voltage_V(self):
        return self.voltage_at(self.clock.now_s())

    def voltage_at(self, time_s):
        if self.waveform is None:
            return self.value
        start, rate, samples = self.waveform
        i = int((time_s - start) * rate)
        return float(samples[min(max(i, 0), len(samples) - 1)])

    def monitor_voltage_V(self):
        return self.commanded_voltage_V()

    def zero(self):
        self.zeroed += 1
        self.waveform, self.value = None, 0.0

    def close(self):
        pass


class FakeSensor:
    """Contact at stage position `touch_m`; leg spring `k_N_per_m`; drive adds `gain_N_per_V` x drive voltage."""

    def __init__(self, clock, stage, drive, touch_m=0.002, k_N_per_m=2.0, gain_N_per_V=2e-5, rate_Hz=150.0,
                 fail_at_s=None, baseline_N=0.0, drift_after_touch_N=0.0):
        self.clock, self.stage, self.drive = clock, stage, drive
        self.touch_m, self.k, self.gain, self.period = touch_m, k_N_per_m, gain_N_per_V, 1 / rate_Hz
        self.capacity_N, self.next_s, self.streaming, self.fail_at_s = 1.0, 0.0, False, fail_at_s
        self.baseline_N = baseline_N  # a reading offset the tare did not remove (a drifted baseline)
        # a baseline step once the leg has first been touched: a load cell drifting during the contact search
        self.drift_after_touch_N, self.touched = drift_after_touch_N, False

    def force_now(self, time_s=None):
        sag = self.stage.position - self.touch_m
        self.touched = self.touched or sag > 0
        free = self.drive.voltage_at(self.clock.now_s() if time_s is None else time_s) * self.gain
        baseline = self.baseline_N + (self.drift_after_touch_N if self.touched else 0.0)
        return baseline + (max(0.0, self.k * sag + free) if sag > -free / self.k else 0.0)

    def tare(self):
        pass

    def read_N(self):
        return self.force_now()

    def start_stream(self):
        self.streaming, self.next_s = True, self.clock.now_s()

    def read_stream(self):
        if self.fail_at_s is not None and self.clock.now_s() >= self.fail_at_s:
            raise DeviceFault("fake sensor disconnected", device="force_sensor")
        out = []
        while self.streaming and self.next_s <= self.clock.now_s():
            out.append(ForceSample(self.next_s, self.force_now(self.next_s)))
            self.next_s += self.period
        return out

    def stop_stream(self):
        self.streaming = False

    def close(self):
        pass


class FakeRecorder:
    def __init__(self):
        self.scalars, self.events, self.images, self.closed = {}, [], [], None

    def write_scalar(self, topic, time_s, **fields):
        self.scalars.setdefault(topic, []).append((time_s, fields))

    def write_event(self, time_s, kind, step, message="", **data):
        self.events.append((time_s, kind, step, message, data))

    def write_image(self, topic, time_s, image, format="raw"):
        self.images.append((topic, time_s))

    def add_metadata(self, name, values):
        pass

    def close(self, exit_status, reason=""):
        if self.closed is None:
            self.closed = (exit_status, reason)


def fake_rig(force_limit_N=0.5, **sensor_kw):
    clock = VirtualClock()
    stage = FakeStage(clock)
    bias, drive = FakeAmp(clock), FakeAmp(clock)
    sensor = FakeSensor(clock, stage, drive, **sensor_kw)
    rig = Rig(name="fake", source_path="-", source_text="", clock=clock, stage=stage, force_sensor=sensor,
              amp_bias=bias, amp_drive=drive, limits=SafetyLimits(force_limit_N=force_limit_N))
    return rig
