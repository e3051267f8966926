"""The bench's PZT hysteresis: a Preisach operator with a continuous, non-separable density over the relays'
(up-switch alpha, down-switch beta) thresholds, evaluated through its Everett function, plus a reversible part.

Why this form (docs/model.md, "The simulated bench"): a Preisach operator is rate-independent, its loops close at
the reversal points (wiping-out), and its loop width grows with amplitude (a cycle of amplitude A switches only the
relays of width below A), as a real PZT's does (~2 % of span at small signal to 10-15 % at large). The reversible
part (1 - eta) x gives the finite slope right after a reversal that the Preisach part alone lacks. The density is
deliberately not uniform (a uniform density would be Rayleigh's law exactly), not a function of alpha - beta alone
(that would be a superposition of play operators, the diagnosis's family) and not a product f(alpha) g(beta):

    mu(alpha, beta) = exp(-r / (r0 (1 + kappa (2 c - 1)))),   r = (alpha - beta) / 2,  c = (alpha + beta) / 2

on the unipolar input range [0, 1] (a plate's voltage over the full scale). r0 sets how wide the switching-field
distribution is (how fast the loop grows with amplitude), kappa tilts it between low and high bias fields.

The Everett function E(a, b) = measure of the triangle {b <= beta <= alpha <= a} is tabulated once (trapezoidal
rule on a 257 x 257 grid) and read bilinearly; the operator's output is the measure of the relays that are up,
summed from the memory's alternating extrema (the staircase), normalised so 0 = all down and 1 = all up.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

_TABLE_POINTS = 257


@dataclass(frozen=True)
class PreisachDensity:
    """The relay-threshold density's shape (see the module docstring)."""

    r0: float = 0.15
    kappa: float = 0.0

    def __post_init__(self) -> None:
        if not (0.01 <= self.r0 <= 2.0):
            raise ValueError(f"Preisach density r0 must be in [0.01, 2], got {self.r0!r}")
        if not (-0.9 <= self.kappa <= 0.9):
            raise ValueError(f"Preisach density kappa must be in [-0.9, 0.9], got {self.kappa!r}")

    def __call__(self, alpha: np.ndarray, beta: np.ndarray) -> np.ndarray:
        a = np.asarray(alpha, dtype=float)
        b = np.asarray(beta, dtype=float)
        r = 0.5 * (a - b)
        c = 0.5 * (a + b)
        return np.where(a >= b, np.exp(-r / (self.r0 * (1.0 + self.kappa * (2.0 * c - 1.0)))), 0.0)


class EverettTable:
    """E(a, b) for 0 <= b <= a <= 1, tabulated and read by bilinear interpolation (vectorised)."""

    def __init__(self, density: PreisachDensity, points: int = _TABLE_POINTS) -> None:
        grid = np.linspace(0.0, 1.0, points)
        self.step = grid[1] - grid[0]
        self.points = points
        alpha, beta = np.meshgrid(grid, grid, indexing="ij")
        mu = density(alpha, beta)
        # trapezoidal weights over each cell of the triangle beta <= alpha: corner values averaged per cell
        cell = 0.25 * (mu[:-1, :-1] + mu[1:, :-1] + mu[:-1, 1:] + mu[1:, 1:])
        lower = np.tril(np.ones_like(cell), k=-1)          # cells wholly below the diagonal (alpha > beta)
        diagonal = np.eye(cell.shape[0])                   # cells the diagonal halves: the triangle's half
        diag_cell = (mu[:-1, :-1] + mu[1:, :-1] + mu[1:, 1:]) / 3.0   # the lower triangle's corners
        mass = self.step ** 2 * (cell * lower + 0.5 * diag_cell * diagonal)
        # E[i, j] = sum of cells with alpha-index < i and beta-index >= j (alpha' <= a_i, beta' >= b_j)
        table = np.zeros((points, points))
        table[1:, :-1] = np.cumsum(np.cumsum(mass[:, ::-1], axis=1)[:, ::-1], axis=0)
        self.table = table
        self.total = float(table[-1, 0])

    def __call__(self, a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
        """E(a, b), 0 where a <= b."""
        a = np.clip(np.asarray(a, dtype=float), 0.0, 1.0)
        b = np.clip(np.asarray(b, dtype=float), 0.0, 1.0)
        fa = a / self.step
        fb = b / self.step
        ia = np.minimum(fa.astype(int), self.points - 2)
        ib = np.minimum(fb.astype(int), self.points - 2)
        ta = fa - ia
        tb = fb - ib
        t = self.table
        value = ((1 - ta) * ((1 - tb) * t[ia, ib] + tb * t[ia, ib + 1])
                 + ta * ((1 - tb) * t[ia + 1, ib] + tb * t[ia + 1, ib + 1]))
        return np.where(a > b, value, 0.0)


@dataclass
class PreisachState:
    """The memory: alternating extrema [m0, M1, m1, M2, ...] after wiping-out (m0 = 0, the lower end), and the
    last input. Ends with a minimum: the input last rose (or never moved); with a maximum: it last fell."""

    extrema: list[float] = field(default_factory=lambda: [0.0])
    last: float = 0.0
    direction: int = 0   # +1 rising, -1 falling, 0 not moved yet

    def copy(self) -> PreisachState:
        return PreisachState(list(self.extrema), self.last, self.direction)


class PreisachOperator:
    """Output in [0, 1] (0 = every relay down, 1 = every relay up) of an input in [0, 1] (clipped), sample by
    sample in order, vectorised over each monotone run of the input."""

    def __init__(self, everett: EverettTable, state: PreisachState | None = None) -> None:
        self.everett = everett
        self.state = state or PreisachState()

    def _prefix(self, ext: list[float]) -> np.ndarray:
        """P[k] = sum_{j=1..k} E(M_j, m_{j-1}) - E(M_j, m_j) over the complete pairs of `ext`."""
        maxima = np.array(ext[1::2])
        minima = np.array(ext[0::2])
        n_pairs = min(len(maxima), len(minima) - 1)
        if n_pairs == 0:
            return np.zeros(1)
        e = self.everett
        terms = e(maxima[:n_pairs], minima[:n_pairs]) - e(maxima[:n_pairs], minima[1:n_pairs + 1])
        return np.concatenate([[0.0], np.cumsum(terms)])

    def _rising(self, ext: list[float], x: np.ndarray) -> np.ndarray:
        """Output along a rising run that starts from the minimum ending `ext`."""
        maxima = np.array(ext[1::2])                      # M1 > M2 > ... (decreasing)
        minima = np.array(ext[0::2])                      # m0 < m1 < ... (increasing)
        prefix = self._prefix(ext)
        # survivors: maxima above x (a prefix of the decreasing list); the branch rises from the min after them
        k = np.searchsorted(-maxima, -x, side="left")     # number of maxima > x
        return prefix[k] + self.everett(x, minima[k])

    def _falling(self, ext: list[float], x: np.ndarray) -> np.ndarray:
        """Output along a falling run that starts from the maximum ending `ext`."""
        maxima = np.array(ext[1::2])
        minima = np.array(ext[0::2])
        prefix = self._prefix(ext)
        # survivors: minima m1.. below x (a prefix of the increasing list, m0 = 0 always survives)
        k = np.searchsorted(minima[1:], x, side="left")   # number of m_j (j >= 1) < x
        e = self.everett
        return prefix[k] + e(maxima[k], minima[k]) - e(maxima[k], x)

    @staticmethod
    def _wipe_and_push(ext: list[float], value: float, rising: bool) -> list[float]:
        """The memory after a run that ended at `value` (a turning point) in the given direction."""
        out = list(ext)
        if rising:
            # remove every (M_j, m_j) pair whose maximum the run reached, then push the new maximum
            while len(out) >= 3 and out[-2] <= value:
                del out[-2:]
            out.append(value)
        else:
            while len(out) >= 3 and out[-2] >= value:
                del out[-2:]
            if len(out) >= 2 and value <= 0.0:
                out = [0.0]          # down to the lower end: every relay down, the memory is wiped
            else:
                out.append(value)
        return out

    def run(self, x: np.ndarray) -> np.ndarray:
        """Outputs for the inputs `x` (continuing from the stored state); the state advances to the last input."""
        x = np.clip(np.asarray(x, dtype=float), 0.0, 1.0)
        out = np.empty_like(x)
        if x.size == 0:
            return out
        st = self.state
        ext = list(st.extrema)
        prev = st.last
        direction = st.direction
        steps = np.diff(np.concatenate([[prev], x]))
        signs = np.sign(steps).astype(int)
        # a sample that does not move keeps the direction before it
        if direction == 0 and signs.size and not np.any(signs):
            out[:] = self._value(ext, prev, direction)
            st.last = float(x[-1])
            return out
        nonzero = np.flatnonzero(signs)
        filled = np.empty_like(signs)
        filled[:] = direction
        if nonzero.size:
            filled[nonzero] = signs[nonzero]
            idx = np.maximum.accumulate(np.where(signs != 0, np.arange(signs.size), -1))
            filled = np.where(idx >= 0, signs[np.maximum(idx, 0)], direction)
        # runs of one direction
        change = np.flatnonzero(np.diff(filled)) + 1
        starts = np.concatenate([[0], change])
        stops = np.concatenate([change, [x.size]])
        for a, b in zip(starts, stops, strict=True):
            d = int(filled[a])
            if d != 0 and d != direction and direction != 0:
                ext = self._wipe_and_push(ext, prev, rising=direction > 0)
            elif d != 0 and direction == 0 and prev > 0.0:
                # first motion from a non-zero start: treat the start as reached from below
                ext = self._wipe_and_push(ext, prev, rising=True) if d < 0 else ext
            if d > 0:
                out[a:b] = self._rising(ext, x[a:b])
            elif d < 0:
                out[a:b] = self._falling(ext, x[a:b])
            else:
                out[a:b] = self._value(ext, prev, direction)
            if d != 0:
                direction = d
            prev = float(x[b - 1])
        st.extrema = ext
        st.last = prev
        st.direction = direction
        return out

    def _value(self, ext: list[float], x: float, direction: int) -> float:
        arr = np.array([x])
        if len(ext) % 2 == 1:   # ends with a minimum: on a rising branch (or at rest at the start)
            return float(self._rising(ext, arr)[0])
        return float(self._falling(ext, arr)[0])

    def output(self, x: float) -> float:
        """The normalised output at input x with the present memory (no state change)."""
        return self._value(self.state.extrema, x, self.state.direction) / self.everett.total


def normalised_run(op: PreisachOperator, x: np.ndarray) -> np.ndarray:
    """`op.run` scaled to [0, 1] by the Everett function's total."""
    return op.run(x) / op.everett.total


def loop_area_quadrature(density: PreisachDensity, n: int = 801) -> float:
    """The major loop's area (0 -> 1 -> 0) in normalised units, as a double integral independent of the Everett
    table: int int (alpha - beta) mu d alpha d beta / int int mu d alpha d beta over beta <= alpha (midpoints)."""
    g = (np.arange(n) + 0.5) / n
    a, b = np.meshgrid(g, g, indexing="ij")
    mu = density(a, b) * (a > b)
    return float(np.sum((a - b) * mu) / np.sum(mu))


def relative_loop_width(density: PreisachDensity, amplitude: float, points: int = 2001) -> float:
    """Largest up/down gap of the normalised output over a cycle 0 -> amplitude -> 0, over the amplitude (the
    Preisach part alone): how the loop grows with amplitude."""
    op = PreisachOperator(EverettTable(density))
    up = np.linspace(0.0, amplitude, points)
    rise = normalised_run(op, up)
    fall = normalised_run(op, up[::-1])[::-1]
    return float(np.max(fall - rise) / amplitude) if amplitude > 0 else 0.0


def check_finite(value: float, name: str) -> float:
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return value
