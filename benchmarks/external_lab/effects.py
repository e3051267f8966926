"""Material-side effects of the other lab's actuators, each in a form that is in neither column of the
project's effect-forms table (coord notes forms.md): they act on one plate's voltage and return the
"effective" voltage that, times the plate's nominal coefficient, gives its share of the tip deflection.

- hysteresis: a Krasnosel'skii-Pokrovskii operator, a weighted sum of relays with finite-slope (ramp)
  switching over a NON-separable density of (centre, width): loops close at the reversal points and widen with
  amplitude (wide kernels only switch under large swings); not a play/Prandtl-Ishlinskii sum, not Bouc-Wen,
  not a Preisach density through an Everett function.
- creep: Kohlrausch stretched exponential, each voltage increment relaxing as 1 - exp(-(t/tau)^beta).
- field-dependent d31: (a) Rayleigh-type amplitude law, the gain set by the largest field the plate has seen
  since the bias came on (not the instantaneous field); (b) a cubic law in the instantaneous field, either
  sign.

Decoys (no candidate in any diagnosis library): depolarisation of a plate by a reverse field between runs, and
a PZT modulus that falls as the actuator self-heats while it is driven.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

V_REF = 250.0            # V: the largest bias the paper uses; hysteresis inputs are plate voltage / V_REF
FIELD_REF_V_PER_UM = 2.0


# ------------------------------------------------------------------------------------------------- hysteresis
@dataclass(frozen=True)
class KPHysteresis:
    """Krasnosel'skii-Pokrovskii hysteresis of one plate's response. `share`: the fraction of the response
    that goes through the kernels (the rest is reversible); `width_scale`: mean kernel width in units of
    V_REF; `width_skew`: how the kernel widths grow with the kernel centre (the non-separable part of the
    density); `ramp`: switching width of a kernel (finite slope after a reversal)."""

    share: float
    width_scale: float
    width_skew: float
    ramp: float

    def _kernels(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        centres = np.linspace(-0.15, 1.15, 41)
        widths = np.geomspace(0.004, 0.9, 14)
        c_grid, r_grid = np.meshgrid(centres, widths, indexing="ij")
        c, r = c_grid.ravel(), r_grid.ravel()
        local_scale = self.width_scale * np.clip(1.0 + self.width_skew * (c - 0.5), 0.2, None)
        weight = np.exp(-r / local_scale) * r   # r: the geometric spacing of the width grid
        ramp = np.minimum(r, self.ramp)
        return c - r / 2.0, c + r / 2.0, ramp, weight / weight.sum()

    def _run(self, u: np.ndarray) -> np.ndarray:
        """Kernel sum for the input u (plate voltage / V_REF), from the state left by a fall from full drive
        to 0 (the poling history). Vectorised over monotone pieces: on a rising piece a kernel's state is
        max(state at the piece's start, up-ramp(u)), on a falling piece min(state, down-ramp(u))."""
        down_at, up_at, ramp, weight = self._kernels()

        def up_ramp(x: np.ndarray) -> np.ndarray:
            return np.clip((x[:, None] - (up_at - ramp)) / ramp, 0.0, 1.0)

        def down_ramp(x: np.ndarray) -> np.ndarray:
            return np.clip((x[:, None] - down_at) / ramp, 0.0, 1.0)

        state = down_ramp(np.array([0.0]))[0]
        out = np.empty(u.size)
        out[0] = state @ weight
        step = np.diff(u)
        direction = np.sign(np.where(np.abs(step) > 1e-12, step, 0.0))
        # pieces of constant direction: [bounds[k], bounds[k + 1]) in `step` indices
        bounds = np.r_[0, np.flatnonzero(np.diff(direction)) + 1, step.size]
        for i, j in zip(bounds[:-1], bounds[1:], strict=True):
            piece = u[i + 1:j + 1]
            if direction[i] == 0:
                out[i + 1:j + 1] = state @ weight
                continue
            states = np.maximum(state, up_ramp(piece)) if direction[i] > 0 else np.minimum(state, down_ramp(piece))
            out[i + 1:j + 1] = states @ weight
            state = states[-1]
        return out

    def _normalisation(self) -> tuple[float, float]:
        """Slope and offset of the mean of the rising and falling branches of the full loop (0 -> 1 -> 0), so
        the hysteretic share has unit gain on average."""
        u = np.r_[np.linspace(0.0, 1.0, 401), np.linspace(1.0, 0.0, 401)[1:]]
        p = self._run(u)
        mean = 0.5 * (p[:401] + p[400:][::-1])
        slope, offset = np.polyfit(u[:401], mean, 1)
        return float(slope), float(offset)

    def apply(self, v_plate: np.ndarray) -> np.ndarray:
        slope, offset = self._normalisation()
        p = (self._run(np.asarray(v_plate, float) / V_REF) - offset) / slope
        return (1.0 - self.share) * v_plate + self.share * V_REF * p

    def loop_width(self, amplitude_V: float) -> float:
        """Largest gap between the falling and the rising branch of a 0 -> amplitude -> 0 cycle, as a fraction
        of the response's span (the figure quoted for PZT: ~2 % small signal, 10-15 % at full drive)."""
        n = 401
        v = np.r_[np.linspace(0.0, amplitude_V, n), np.linspace(amplitude_V, 0.0, n)[1:],
                  np.linspace(0.0, amplitude_V, n)[1:], np.linspace(amplitude_V, 0.0, n)[1:]]
        e = self.apply(v)[2 * n - 2:]           # second cycle: past the first-rise transient
        rise, fall = e[:n], e[n - 1:][::-1]
        span = float(e.max() - e.min())
        return float(np.max(fall - rise) / span) if span > 0 else 0.0


# ------------------------------------------------------------------------------------------------------ creep
@dataclass(frozen=True)
class KohlrauschCreep:
    """Each increment of a plate's response relaxes further by `amplitude` x (1 - exp(-(t / tau)^beta))."""

    amplitude: float
    beta: float
    tau_s: float

    def step_response(self, t_s: np.ndarray) -> np.ndarray:
        t = np.clip(np.asarray(t_s, float), 0.0, None)
        return 1.0 + self.amplitude * (1.0 - np.exp(-((t / self.tau_s) ** self.beta)))

    def per_decade(self) -> float:
        """Mean growth per decade of time between 0.1 s and 10 s after a step, relative to the response at 0.1
        s (the "1-2 % per decade" figure)."""
        lo, hi = self.step_response(np.array([0.1, 10.0]))
        return float((hi - lo) / lo / 2.0)

    def apply(self, t_s: np.ndarray, e: np.ndarray) -> np.ndarray:
        """Superposition of the increments on the uniform grid t_s (one FFT convolution)."""
        from scipy.signal import fftconvolve

        dt = float(t_s[1] - t_s[0])
        increments = np.r_[e[0], np.diff(e)]
        kernel = self.step_response(np.arange(e.size) * dt) - 1.0
        return e + fftconvolve(increments, kernel)[:e.size]


# ------------------------------------------------------------------------------------------- field-dependent
# d31
@dataclass(frozen=True)
class RayleighAmplitudeD31:
    """Rayleigh-type rise: d31 = d31_0 (1 + alpha E_amp / 2 V/um), E_amp the largest field the plate has seen
    since its bias came on (a property of the cycling amplitude, not of the instantaneous field)."""

    alpha: float

    def gain(self, v_plate: np.ndarray, thickness_m: float) -> np.ndarray:
        amplitude_V_per_um = np.maximum.accumulate(np.abs(v_plate)) / (thickness_m * 1e6)
        return 1.0 + self.alpha * amplitude_V_per_um / FIELD_REF_V_PER_UM

    def gain_at(self, field_V_per_um: float) -> float:
        return 1.0 + self.alpha * field_V_per_um / FIELD_REF_V_PER_UM


@dataclass(frozen=True)
class CubicFieldD31:
    """d31 = d31_0 (1 + b (E / E_ref)^3) in the instantaneous field, b of either sign (a rise, or a droop
    toward saturation near the top of the field range)."""

    b: float
    field_ref_V_per_um: float

    def gain(self, v_plate: np.ndarray, thickness_m: float) -> np.ndarray:
        e = v_plate / (thickness_m * 1e6) / self.field_ref_V_per_um
        return 1.0 + self.b * np.abs(e) ** 3

    def gain_at(self, field_V_per_um: float) -> float:
        return 1.0 + self.b * (field_V_per_um / self.field_ref_V_per_um) ** 3


# ----------------------------------------------------------------------------------------------------- decoys
@dataclass(frozen=True)
class ReverseFieldDepolarisation:
    """Between runs the lab parks the drive at V_bias / 2 (the actuator straight) and switches the bias off
    first: the top plate then sees -V_bias / 2, a reverse field. Each such event removes the fraction
    max_loss / (1 + exp(-(E_rev - coercive) / spread)) of that plate's remaining polarisation."""

    max_loss: float
    coercive_V_per_um: float
    spread_V_per_um: float

    def loss(self, reverse_field_V_per_um: float) -> float:
        x = (reverse_field_V_per_um - self.coercive_V_per_um) / self.spread_V_per_um
        return float(self.max_loss / (1.0 + np.exp(-x)))


@dataclass(frozen=True)
class SelfHeatingModulus:
    """The PZT modulus falls by `per_K` per kelvin as the actuator warms while driven: the temperature rise
    approaches heat_K x (V_bias / 250 V)^2 x (ramp duty) with time constant tau_s (losses grow with the field
    squared and with how often it moves)."""

    per_K: float
    heat_K: float
    tau_s: float

    def modulus_scale(self, t_s: np.ndarray, driven: np.ndarray, bias_V: float, duty: float) -> np.ndarray:
        dt = float(t_s[1] - t_s[0])
        target = self.heat_K * (bias_V / V_REF) ** 2 * duty
        # first-order heating while driven, cooling otherwise, on the uniform grid
        from scipy.signal import lfilter

        a = np.exp(-dt / self.tau_s)
        temperature = lfilter([1.0 - a], [1.0, -a], np.where(driven, target, 0.0))
        return 1.0 - self.per_K * temperature
