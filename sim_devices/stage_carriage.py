"""The stage's carriage as it follows the motor (effect `stage_backlash`): a lead-screw nut with play, then a
compliant drive with static and kinetic friction (stick-slip). Not a pure play operator: after the play is taken
up the carriage lags the nut by the drive's friction deflection and advances in slips.

- Nut: the motor position through a play of full width b (the effect's strength): the nut moves only once the
  motor has taken up the play in the new direction.
- Carriage: held by friction until the drive spring's deflection (nut - carriage) reaches the static threshold
  L_s = rho L_k (L_k = F_kinetic / k_drive, rho = F_static / F_kinetic >= 1); it then slips forward to the
  deflection L_k (2 - rho) (a slip with inertia overshoots the kinetic equilibrium by as much as it started
  above it), so while the nut advances the carriage moves in steps of 2 L_k (rho - 1) of nut travel; rho = 1 is
  steady sliding at lag L_k. Where the carriage stops after a move depends on where the last slip fell: a
  direction- and distance-dependent positioning error, as a real stage has.

Vectorised over each monotone run of the motor; the state (nut, carriage, direction) carries across blocks.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class CarriageState:
    motor_m: float
    nut_m: float
    carriage_m: float
    direction: int = 0

    @classmethod
    def at_rest(cls, position_m: float) -> CarriageState:
        """Motor, nut and carriage together (the play centred, the drive relaxed)."""
        return cls(position_m, position_m, position_m, 0)

    def copy(self) -> CarriageState:
        return CarriageState(self.motor_m, self.nut_m, self.carriage_m, self.direction)


@dataclass(frozen=True)
class CarriageModel:
    play_m: float
    lag_m: float = 0.5e-6
    stick_ratio: float = 1.3

    def __post_init__(self) -> None:
        if not (self.play_m >= 0 and self.lag_m >= 0 and 1.0 <= self.stick_ratio < 2.0):
            raise ValueError(f"stage carriage: play >= 0, lag >= 0 and 1 <= stick_ratio < 2 needed, got "
                             f"{self.play_m!r}, {self.lag_m!r}, {self.stick_ratio!r}")

    def run(self, motor_m: np.ndarray, state: CarriageState) -> np.ndarray:
        """Carriage positions for the motor positions (in time order); `state` advances."""
        x = np.asarray(motor_m, dtype=float)
        out = np.empty_like(x)
        if x.size == 0:
            return out
        steps = np.diff(np.concatenate([[state.motor_m], x]))
        signs = np.sign(steps).astype(int)
        idx = np.maximum.accumulate(np.where(signs != 0, np.arange(signs.size), -1))
        filled = np.where(idx >= 0, signs[np.maximum(idx, 0)], state.direction)
        change = np.flatnonzero(np.diff(filled)) + 1
        for a, b in zip(np.concatenate([[0], change]), np.concatenate([change, [x.size]]), strict=True):
            d = int(filled[a])
            if d == 0:
                out[a:b] = state.carriage_m
                continue
            out[a:b] = self._run(x[a:b], d, state)
            state.direction = d
        state.motor_m = float(x[-1])
        return out

    def _run(self, x: np.ndarray, d: int, st: CarriageState) -> np.ndarray:
        half = 0.5 * self.play_m
        if d > 0:
            nut = np.maximum(st.nut_m, np.maximum.accumulate(x - half))
        else:
            nut = np.minimum(st.nut_m, np.minimum.accumulate(x + half))
        # work in the direction of motion: e = d (nut - carriage) is the drive spring's deflection
        lk, rho = self.lag_m, self.stick_ratio
        ls = rho * lk
        settle = lk * (2.0 - rho)
        c0 = st.carriage_m
        travel = d * (nut - c0)                         # nut ahead of the carriage's rest position
        if lk == 0.0:
            carriage = np.where(travel > 0, nut, c0)
        elif rho == 1.0:
            carriage = np.where(travel > lk, nut - d * lk, c0)
        else:
            step = 2.0 * lk * (rho - 1.0)
            n_slips = np.floor((travel - ls) / step)     # slips after the first, while the nut keeps going
            carriage = np.where(travel >= ls, c0 + d * (ls - settle + n_slips * step), c0)
        st.nut_m = float(nut[-1])
        st.carriage_m = float(carriage[-1])
        return carriage


def positioning_error_bound_m(model: CarriageModel) -> float:
    """Largest distance between a resting carriage and the motor, once a move has taken up the play: half the
    play plus the static deflection of the drive."""
    return 0.5 * model.play_m + model.stick_ratio * model.lag_m
