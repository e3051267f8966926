"""The force sensor's baseline drift (effect `sensor_drift`), on the bench's time grid: an exponential thermal
warm-up plus an Ornstein-Uhlenbeck wander,

    drift(t) = A (1 - exp(-t / tau_w)) + w(t),    dw = -w / tau_r dt + sigma dW

sigma (N/sqrt(s)) is the strength; tau_r (reversion time) long against a run makes w a random walk of that rate,
which is what the diagnosis's wander rate estimates. w is solved exactly on the grid (w[k+1] = a w[k] +
sigma sqrt(tau_r (1 - a^2) / 2) n[k], a = exp(-h / tau_r)). The normal draws n[k] come in chunks seeded by the
bench seed and the chunk's index, so a grid point's value does not depend on how the bench's queries were split
into blocks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sim_devices.linear_dynamics import first_order_recursion

_CHUNK = 4096
DRIFT_SHAPE = {"warmup_N": 2e-4, "warmup_tau_s": 120.0, "reversion_s": 3000.0}


@dataclass(frozen=True)
class DriftModel:
    rate_N_per_sqrt_s: float
    warmup_N: float = 2e-4
    warmup_tau_s: float = 120.0
    reversion_s: float = 3000.0

    def __post_init__(self) -> None:
        if not (self.rate_N_per_sqrt_s >= 0 and self.warmup_tau_s > 0 and self.reversion_s > 0):
            raise ValueError("sensor_drift: rate >= 0, warmup_tau_s > 0 and reversion_s > 0 needed")


class DriftProcess:
    """drift(t) at grid index k (t = t0 + k h); stateful in k, each index's noise fixed by (seed, k)."""

    def __init__(self, model: DriftModel, h_s: float, seed: int) -> None:
        self.model = model
        self.h = h_s
        self.seed = int(seed)
        self.a = math.exp(-h_s / model.reversion_s)
        self.noise_scale = model.rate_N_per_sqrt_s * math.sqrt(model.reversion_s * (1.0 - self.a ** 2) / 2.0)
        self.wander = 0.0     # w at the last index computed
        self.index = -1       # the grid index of `wander` (none yet)

    def snapshot(self) -> tuple[float, int]:
        return self.wander, self.index

    def restore(self, state: tuple[float, int]) -> None:
        self.wander, self.index = state

    def _normals(self, first: int, count: int) -> np.ndarray:
        out = np.empty(count)
        k = first
        while k < first + count:
            chunk = k // _CHUNK
            draws = np.random.default_rng([self.seed, 0xD81F7, chunk]).standard_normal(_CHUNK)
            lo = k - chunk * _CHUNK
            n = min(_CHUNK - lo, first + count - k)
            out[k - first:k - first + n] = draws[lo:lo + n]
            k += n
        return out

    def run(self, first_index: int, count: int, elapsed_s: np.ndarray) -> np.ndarray:
        """Drift at grid indices first_index .. first_index + count - 1 (continuing from index first_index - 1);
        `elapsed_s` their times since the bench started (for the warm-up)."""
        if first_index != self.index + 1:
            raise ValueError(f"drift: grid index {first_index} does not follow {self.index}")
        w = first_order_recursion(self.a, self.noise_scale * self._normals(first_index, count), self.wander)
        if count:
            self.wander = float(w[-1])
            self.index = first_index + count - 1
        m = self.model
        return m.warmup_N * -np.expm1(-np.asarray(elapsed_s) / m.warmup_tau_s) + w
