"""The realistic-bench effects: how the simulated bench departs from the nominal model, switched on by name and
strength (rig file `[sim] effects` or `--effects`). Strength 0 (or absent) gives back the nominal bench exactly.

These are the GENERATOR forms. The gap diagnosis (`analysis`) fits its own candidate forms of the same physical
effects, deliberately different (e.g. Bouc-Wen hysteresis here, a play operator there), so that finding an effect
is not circular. Each effect lands in one of four places:

- drive memory (`hysteresis`, `creep`): operators on the net drive signal s = 2 V_drive - V_bias, integrated on a
  fixed time grid by `DriveMemory`;
- model hooks (`field_dependent_d31`, `base_compliance`, `width_loss`, `bias_error`): `hamr_bench.model` effects
  built here with generator-specific forms;
- contact (`sensor_compliance`): the force sensor's own spring, solved in the bench's contact;
- device emulators (`stage_backlash`, `sensor_drift`): parameters of the SMC100 and Loadstar emulators.

Realistic strengths (physics notes section 4) are in `REALISTIC`; `describe()` documents units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hamr_bench.errors import ConfigError
from hamr_bench.model import Effect
from hamr_bench.model import actuator as act

# name -> (unit of strength, what it means, a realistic strength)
EFFECTS: dict[str, tuple[str, str, float]] = {
    "hysteresis": ("fraction", "Bouc-Wen loop on the drive; strength = loop half-width / full drive", 0.12),
    "creep": ("per decade", "drift while a drive level is held (Prony series); strength = growth per decade", 0.02),
    "field_dependent_d31": ("fraction", "d31 rises with field (tanh law); strength = gain at 2 V/um", 0.25),
    "base_compliance": ("fraction", "imperfect actuator grounding; strength = blocked-force loss at the tip", 0.2),
    "width_loss": ("fraction", "laser-cut edge loss; strength = fraction of the nominal width lost", 0.15),
    "bias_error": ("m", "the transmission's actual bias minus its designed bias", 30e-6),
    # realistic: a sensor 10x stiffer than the 2-layer actuator (~2000 N/m), ~9 % force loss (physics notes s. 4)
    "sensor_compliance": ("m/N", "force-sensor spring compliance; strength = 1 / k_sensor", 1.0 / 20000.0),
    # lead-screw stage with a stepper: a few um to tens of um on reversal; 10 um is the middle of that span
    "stage_backlash": ("m", "dead band of the stage on reversal", 10e-6),
    "sensor_drift": ("N/sqrt(s)", "force-sensor baseline random walk", 2e-5),
    # decoys for the gap diagnosis's self-check: physical effects OUTSIDE its candidate library
    "amplifier_gain_error": ("fraction", "HV amplifier gain below nominal: every plate sees (1 - s) x V", 0.08),
    "flexure_softening": ("fraction", "warm Kapton: every flexure stiffness kappa_i scaled by (1 - s)", 0.3),
}
REALISTIC: dict[str, float] = {name: spec[2] for name, spec in EFFECTS.items()}


def check_effects(effects: dict[str, float], where: str = "effects") -> dict[str, float]:
    for name, strength in effects.items():
        if name not in EFFECTS:
            raise ConfigError(f"{where}: unknown effect {name!r} (known: {', '.join(EFFECTS)})")
        if not math.isfinite(strength):
            raise ConfigError(f"{where}: strength of {name} must be finite, got {strength!r}")
        if name not in ("bias_error",) and strength < 0:
            raise ConfigError(f"{where}: strength of {name} must be >= 0, got {strength!r}")
    return {k: float(v) for k, v in effects.items() if v != 0}


# ------------------------------------------------------------------ model-hook effects (generator forms)
@dataclass(frozen=True)
class TanhFieldD31(Effect):
    """d31 rising with field as a saturating law: g(V) = V (1 + s tanh^2(E / E_ref)) per plate, E_ref = 1.4 V/um,
    normalised so the gain at 2 V/um is s."""

    name: str = "field_dependent_d31"

    def plate_voltage(self, v_plate_V, actuator):
        v = np.asarray(v_plate_V, dtype=float)
        field = np.abs(v) / actuator.pzt_thickness_m / 1.4e6
        return v * (1.0 + self.strength * np.tanh(field) ** 2 / math.tanh(2.0 / 1.4) ** 2)


@dataclass(frozen=True)
class RotationalBaseCompliance(Effect):
    """A rotational spring at the clamp: the tip gains the clamp rotation x length, so blocked force drops by the
    fraction `strength` while the free displacement is kept (a series spring k_act (1 - s) / s)."""

    name: str = "base_compliance"

    def serial_stiffness(self, k_ser_N_per_m, actuator):
        s = min(self.strength, 0.95)
        k_base = act.stiffness_N_per_m(actuator) * (1.0 - s) / s
        return 1.0 / (1.0 / k_ser_N_per_m + 1.0 / k_base)


@dataclass(frozen=True)
class WidthLoss(Effect):
    """Laser-cut edge loss: the effective width is (1 - strength) of the nominal."""

    name: str = "width_loss"

    def actuator_params(self, params):
        return act.with_changes(params, width_nom_m=params.width_nom_m * (1.0 - min(self.strength, 0.9)))


@dataclass(frozen=True)
class BiasError(Effect):
    """The transmission's actual bias differs from its designed value by `strength` metres."""

    name: str = "bias_error"

    def design_params(self, design):
        import dataclasses

        return dataclasses.replace(design, bias_m=design.bias_m + self.strength)


@dataclass(frozen=True)
class AmplifierGainError(Effect):
    """Decoy: both HV channels deliver (1 - strength) of the commanded voltage (per-plate voltage scaled)."""

    name: str = "amplifier_gain_error"

    def plate_voltage(self, v_plate_V, actuator):
        return np.asarray(v_plate_V, dtype=float) * (1.0 - min(self.strength, 0.9))


@dataclass(frozen=True)
class FlexureSoftening(Effect):
    """Decoy: every flexure joint softer by the fraction `strength` (Kapton modulus falls with temperature)."""

    name: str = "flexure_softening"

    def design_params(self, design):
        import dataclasses

        k = tuple(float(x) * (1.0 - min(self.strength, 0.9)) for x in design.kappa_N_m_per_rad)
        return dataclasses.replace(design, kappa_N_m_per_rad=k)


def model_effects(effects: dict[str, float]) -> list[Effect]:
    makers = {"field_dependent_d31": TanhFieldD31, "base_compliance": RotationalBaseCompliance,
              "width_loss": WidthLoss, "bias_error": BiasError,
              "amplifier_gain_error": AmplifierGainError, "flexure_softening": FlexureSoftening}
    return [makers[name](strength=s) for name, s in effects.items() if name in makers and s != 0]


# ------------------------------------------------------------------ drive memory (hysteresis, creep)
class DriveMemory:
    """Effective (V_bias, V_drive) as a function of time, from the commanded amplifier outputs through the memory
    effects. Integrated on a fixed grid (`dt_s`) as far as the latest time asked; earlier times interpolate the
    stored history, so emulators may ask in any order within `keep_s`."""

    CREEP_TAUS_S = (0.03, 0.3, 3.0, 30.0)

    def __init__(self, voltages_at, hysteresis: float, creep: float, full_scale_V: float = 250.0,
                 dt_s: float = 5e-4, keep_s: float = 30.0) -> None:
        self._voltages_at = voltages_at  # times array -> (v_bias array, v_drive array)
        self.hysteresis = float(hysteresis)
        self.creep = float(creep)
        self.full_scale_V = full_scale_V
        self.dt_s = dt_s
        self.keep = int(keep_s / dt_s)
        self._t0 = None
        self._times = np.empty(0)
        self._vb = np.empty(0)
        self._vd = np.empty(0)
        # Bouc-Wen state h (in units of full scale) and creep lag states (volts)
        self._h = 0.0
        self._s_prev = None
        self._lags = np.zeros(len(self.CREEP_TAUS_S))

    @property
    def active(self) -> bool:
        return self.hysteresis > 0 or self.creep > 0

    def many(self, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        if np.size(times_s) == 0:  # an empty query (a DAQ validating its channels): nothing to look up
            empty = np.empty(np.shape(times_s))
            return empty, empty.copy()
        if not self.active:
            return self._voltages_at(times_s)
        self._extend_to(float(np.max(times_s)))
        return np.interp(times_s, self._times, self._vb), np.interp(times_s, self._times, self._vd)

    def _extend_to(self, time_s: float) -> None:
        if self._t0 is None:
            self._t0 = time_s
            self._times = np.array([time_s])
            vb, vd = self._voltages_at(self._times)
            self._s_prev = float(2 * vd[0] - vb[0])
            self._lags[:] = self._s_prev
            self._vb, self._vd = vb.astype(float), vd.astype(float)
            return
        last = self._times[-1]
        if time_s <= last:
            return
        n = int(math.ceil((time_s - last) / self.dt_s))
        times = last + self.dt_s * np.arange(1, n + 1)
        vb, vd = self._voltages_at(times)
        s = 2 * np.asarray(vd, float) - np.asarray(vb, float)
        s_eff = self._integrate(s)
        vd_eff = (s_eff + vb) / 2.0
        self._times = np.concatenate([self._times, times])[-self.keep:]
        self._vb = np.concatenate([self._vb, vb])[-self.keep:]
        self._vd = np.concatenate([self._vd, vd_eff])[-self.keep:]

    def _integrate(self, s: np.ndarray) -> np.ndarray:
        """Bouc-Wen hysteresis, then Prony-series creep, sample by sample on the grid.

        Hysteresis: x = s / full scale; h obeys dh = dx - beta |dx| h - gamma dx |h| with beta = gamma = 1 / (2 w),
        so h saturates at +w on rising input and -w on falling input; the effective drive is x - h (it lags the
        command by up to w = strength on each side).
        Creep: each lag state follows the effective drive with its time constant (one per decade); the output is
        y - g sum_k (y - lag_k), so after a step the response starts low by g per decade and creeps up to the
        static value by g per decade of time."""
        out = np.empty_like(s)
        fs = self.full_scale_V
        w = self.hysteresis
        k = 1.0 / (2.0 * w) if w > 0 else 0.0
        h, prev = self._h, self._s_prev
        alphas = self.dt_s / (np.asarray(self.CREEP_TAUS_S) + self.dt_s)
        lags = self._lags
        g = self.creep
        for i, si in enumerate(s):
            y = si
            if w > 0:
                dx = (si - prev) / fs
                h += dx - k * abs(dx) * h - k * dx * abs(h)
                y = si - h * fs
            if g > 0:
                lags += alphas * (y - lags)
                y = y - g * float(np.sum(y - lags))
            out[i] = y
            prev = si
        self._h, self._s_prev = h, prev
        return out
