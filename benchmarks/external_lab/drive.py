"""The other lab's drive: trapezoids between ground and V_bias with the lab's own timing (dwells, ramps, cycle
counts, repetitions, possibly two ramp rates), the bias switched on before the recording starts, and a
high-voltage amplifier that rounds the corners (first order) and, as a decoy, droops as it warms."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import lfilter


@dataclass(frozen=True)
class DriveTiming:
    """One specimen block: `pre_roll_s` with the bias on before the first recorded sample, then `repetitions`
    runs of `cycles` trapezoids (low dwell, ramp up, high dwell, ramp down) separated by `pause_s` at ground;
    repetition k uses ramp_s[k % len(ramp_s)] (two entries: two ramp rates, alternating)."""

    dwell_low_s: float
    dwell_high_s: float
    ramp_s: tuple[float, ...]
    cycles: int
    repetitions: int
    pause_s: float
    lead_s: float          # recorded time at ground before the first cycle
    tail_s: float          # recorded time at ground after the last cycle
    pre_roll_s: float      # bias on, not recorded

    def duration_s(self) -> float:
        reps = [self.cycles * (self.dwell_low_s + self.dwell_high_s + 2 * self.ramp_s[k % len(self.ramp_s)])
                for k in range(self.repetitions)]
        return self.lead_s + sum(reps) + self.pause_s * (self.repetitions - 1) + self.tail_s


def drive_command(timing: DriveTiming, bias_V: float, rate_Hz: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, V_drive command, driven mask) on a uniform grid from -pre_roll to the block's end (t = 0: first
    recorded sample). Driven = inside a trapezoid cycle."""
    corners_t = [-timing.pre_roll_s, 0.0, timing.lead_s]
    corners_v = [0.0, 0.0, 0.0]
    t0 = timing.lead_s
    for k in range(timing.repetitions):
        ramp = timing.ramp_s[k % len(timing.ramp_s)]
        for _ in range(timing.cycles):
            t0 += timing.dwell_low_s
            corners_t += [t0, t0 + ramp, t0 + ramp + timing.dwell_high_s, t0 + 2 * ramp + timing.dwell_high_s]
            corners_v += [0.0, bias_V, bias_V, 0.0]
            t0 += 2 * ramp + timing.dwell_high_s
        if k < timing.repetitions - 1:
            t0 += timing.pause_s
    end = t0 + timing.tail_s
    corners_t.append(end)
    corners_v.append(0.0)
    n_pre = int(round(timing.pre_roll_s * rate_Hz))
    n = int(round(end * rate_Hz)) + 1
    t = np.arange(-n_pre, n) / rate_Hz
    v = np.interp(t, corners_t, corners_v)
    driven = v > 1e-9 * max(bias_V, 1.0)
    return t, v, driven


def bias_waveform(t: np.ndarray, bias_V: float, ramp_s: float = 0.2) -> np.ndarray:
    """The bias supply comes up over `ramp_s` at the start of the pre-roll and stays on."""
    return bias_V * np.clip((t - t[0]) / ramp_s, 0.0, 1.0)


@dataclass(frozen=True)
class Amplifier:
    """First-order output stage: rounded corners on fast ramps (a TREK-class amplifier slews far faster than
    any ramp here, so no slew limit)."""

    tau_s: float

    def output(self, t: np.ndarray, v_cmd: np.ndarray, gain: np.ndarray | float = 1.0) -> np.ndarray:
        dt = float(t[1] - t[0])
        a = np.exp(-dt / self.tau_s)
        return lfilter([1.0 - a], [1.0, -a], v_cmd * gain)


@dataclass(frozen=True)
class AmplifierDroop:
    """Decoy: the amplifier's gain sags as its output stage warms. While a block runs, the thermal state
    relaxes with tau_s toward (V_bias / 250 V)^2 (the dissipation of a high-voltage stage grows with the
    output swing squared); between blocks it cools toward 0. Gain = 1 - max_droop x state. The state carries
    over the session, so the files measured later, and at higher bias, droop more."""

    max_droop: float
    tau_s: float

    def gain(self, t_session: np.ndarray, bias_V: float, state0: float) -> tuple[np.ndarray, float]:
        target = (bias_V / 250.0) ** 2
        state = target + (state0 - target) * np.exp(-(t_session - t_session[0]) / self.tau_s)
        return 1.0 - self.max_droop * state, float(state[-1])
