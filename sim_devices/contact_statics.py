"""Quasi-static forces and positions of the bench's two fixtures: the targets the bench's dynamics settle toward.

Coordinates: x is the plant's position along the sensor axis, positive toward the sensor (the actuator tip's
deflection, or the foot's downward travel from the undriven neutral the bench started with); x_s is where the
sensor surface sits in the same coordinate. Contact when x > x_s; the sensor (transducer in series with its mount,
stiffness k_s) then reads k_s (x - x_s).

- Actuator tip: a linear spring k_act driven to u (the free deflection), with the optional nonlinear clamp
  (effect `base_compliance`) in series: F = k_act (u - d(F) - x), d the clamp's give under the tip force F.
- Leg: the powertrain model's force on a support holding the foot at height h, P(u, h), tabulated once per bench
  on a grid of (u, h) from `Powertrain.foot_force_N` (the model's free actuator deflection is linear in the net
  drive when no plate effect is active, so a drive with V_bias = 0 and V_drive = u / (2 delta per volt) reaches any
  u; the bench's own Powertrain has no plate effects and a voltage limit far above any drive). Sensor spring,
  clamp and friction are solved around it exactly (fixed point / Newton to 1e-12 of the force).
- Foot friction (effect `foot_friction`, coefficient mu): the foot slides along the sensor when the stage moves
  it along its arc; friction T opposes the slip and enters the crank's balance U' = N h' + T x', so the vertical
  reading is N = N0 - T tan(alpha) (alpha the leg's angle below horizontal, x' / h' = tan(alpha)). Sliding:
  N = N0 / (1 - mu tan(alpha) sign(dh)); at rest T stays as the last slip left it, within |T| <= mu N.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from hamr_bench.model import actuator as act
from hamr_bench.model import transmission as tr
from hamr_bench.model.powertrain import Powertrain

_NEWTON_STEPS = 60
_TOL_N = 1e-13


# ------------------------------------------------------------------ the nonlinear clamp (base compliance)
CLAMP_SHAPE = {"form": 0.0, "hardening": 2.0, "pull_ratio": 1.0}


@dataclass(frozen=True)
class Clamp:
    """The actuator's clamp as a spring in series at the tip: give d(F) under the tip force F (> 0 pushing toward
    the sensor). Form 'hardening' (Duffing: F = k0 d + k3 d^3) or 'bilinear' (k_push for F > 0, k_pull below);
    `pull_ratio` = pull stiffness / push stiffness. Sized so the bare actuator's 250 V blocked force drops by the
    fraction `loss` (the effect's strength); `hardening` = the clamp's tangent stiffness at that load / at 0."""

    loss: float
    k_act_N_per_m: float
    free_deflection_250_m: float
    form: str = "hardening"
    hardening: float = 2.0
    pull_ratio: float = 1.0

    def __post_init__(self) -> None:
        if not 0 < self.loss < 0.9:
            raise ValueError(f"base_compliance strength (blocked-force loss) must be in (0, 0.9), got {self.loss!r}")
        if self.form not in ("hardening", "bilinear") or not 1.0 <= self.hardening <= 10.0 or \
                not 0.1 <= self.pull_ratio <= 10.0:
            raise ValueError("base_compliance shape: form hardening|bilinear, hardening in [1, 10], "
                             "pull_ratio in [0.1, 10]")
        f_load = (1.0 - self.loss) * self.k_act_N_per_m * self.free_deflection_250_m   # the reduced blocked force
        d_load = self.loss * self.free_deflection_250_m                                # the clamp's give there
        if self.form == "bilinear":
            k0 = f_load / d_load
            k3 = 0.0
        else:
            k0 = f_load / (d_load * (1.0 + (self.hardening - 1.0) / 3.0))
            k3 = (self.hardening - 1.0) * k0 / (3.0 * d_load ** 2)
        object.__setattr__(self, "k0", k0)
        object.__setattr__(self, "k3", k3)

    def give_m(self, force_N: np.ndarray) -> np.ndarray:
        f = np.asarray(force_N, dtype=float)
        k0 = np.asarray(np.where(f >= 0, self.k0, self.k0 * self.pull_ratio), dtype=np.float64)  # type: ignore[attr-defined]
        k3 = np.asarray(np.where(f >= 0, self.k3, self.k3 * self.pull_ratio), dtype=np.float64)  # type: ignore[attr-defined]
        if self.k3 == 0.0:  # type: ignore[attr-defined]
            return f / k0
        # the real root of k3 d^3 + k0 d - f = 0 (Cardano; one real root since k0, k3 > 0)
        p = k0 / k3
        q = -f / k3
        disc = np.sqrt(q * q / 4.0 + p ** 3 / 27.0)
        return np.cbrt(-q / 2.0 + disc) + np.cbrt(-q / 2.0 - disc)

    def compliance_m_per_N(self, force_N: np.ndarray) -> np.ndarray:
        """d'(F) = 1 / (k0 + 3 k3 d^2)."""
        f = np.asarray(force_N, dtype=float)
        d = self.give_m(f)
        k0 = np.asarray(np.where(f >= 0, self.k0, self.k0 * self.pull_ratio), dtype=np.float64)  # type: ignore[attr-defined]
        k3 = np.asarray(np.where(f >= 0, self.k3, self.k3 * self.pull_ratio), dtype=np.float64)  # type: ignore[attr-defined]
        return 1.0 / (k0 + 3.0 * k3 * d * d)


def make_clamp(loss: float, actuator: act.ActuatorParams, shape: dict[str, float]) -> Clamp:
    extra = sorted(set(shape) - set(CLAMP_SHAPE))
    if extra:
        raise ValueError(f"base_compliance shape: unknown parameter {extra[0]!r} (known: {', '.join(CLAMP_SHAPE)})")
    s = {**CLAMP_SHAPE, **shape}
    return Clamp(loss, act.stiffness_N_per_m(actuator), float(act.free_displacement_m(actuator, 250.0)),
                 "bilinear" if s["form"] >= 0.5 else "hardening", s["hardening"], s["pull_ratio"])


# ------------------------------------------------------------------ the bare actuator
@dataclass(frozen=True)
class ActuatorStatics:
    k_act_N_per_m: float
    k_sensor_N_per_m: float
    clamp: Clamp | None = None

    def free_position_m(self, u_m: np.ndarray) -> np.ndarray:
        return np.asarray(u_m, dtype=float)

    def contact_force_N(self, u_m: np.ndarray, surface_m: np.ndarray) -> np.ndarray:
        """F with the tip held against the sensor: F = k_act (u - d(F) - x), x = surface + F / k_s (may be < 0:
        the tip would pull away)."""
        u = np.asarray(u_m, dtype=float)
        s = np.asarray(surface_m, dtype=float)
        k, ks = self.k_act_N_per_m, self.k_sensor_N_per_m
        series = k * ks / (k + ks)
        rigid = series * (u - s)
        if self.clamp is None:
            return rigid
        # phi(F) = F (1 + k / ks) + k d(F) - k (u - s), increasing in F: Newton from the linear clamp's answer
        c = self.clamp
        f = k * (u - s) / (1.0 + k / ks + k / c.k0)  # type: ignore[attr-defined]
        for _ in range(_NEWTON_STEPS):
            phi = f * (1.0 + k / ks) + k * c.give_m(f) - k * (u - s)
            step = phi / ((1.0 + k / ks) + k * c.compliance_m_per_N(f))
            f = f - step
            if np.all(np.abs(step) <= _TOL_N):
                break
        return f


# ------------------------------------------------------------------ the leg
class LegTables:
    """One powertrain's tables in the bench's absolute height frame (heights from the neutral of `reference`, the
    powertrain the bench started with): free foot height vs u, support force vs (u, h), transmission input vs h,
    tan(alpha) vs h. Built once; read by interpolation (errors checked in tests against the model itself)."""

    U_POINTS = 17
    H_POINTS = 3601
    FREE_POINTS = 2001

    def __init__(self, p: Powertrain, reference: Powertrain, u_max_m: float,
                 h_range_m: tuple[float, float] = (-3e-3, 6e-3)) -> None:
        self.p = p
        g = p.geometry
        self.shift_m = float(tr.foot_height_fab_m(g, p.theta_neutral_rad)
                             - tr.foot_height_fab_m(reference.geometry, reference.theta_neutral_rad))
        self.per_volt = act.displacement_per_volt(p.actuator)
        self.k_eff = p.k_eff_N_per_m
        self.u_max = u_max_m
        self.u_grid = np.linspace(-u_max_m, u_max_m, self.U_POINTS)
        self.h_grid = np.linspace(h_range_m[0], h_range_m[1], self.H_POINTS)
        self.h_step = self.h_grid[1] - self.h_grid[0]
        rel = self.h_grid - self.shift_m          # heights in this powertrain's own frame
        h_neutral_fab = float(tr.foot_height_fab_m(g, p.theta_neutral_rad))
        with np.errstate(invalid="ignore"):
            inside = np.abs(np.sin(g.leg_angle0_rad) - (rel + h_neutral_fab) / g.leg_length_m) < 1.0
            rel_in = np.where(inside, rel, 0.0)
            uu, hh = np.meshgrid(self.u_grid, rel_in, indexing="ij")
            force = p.foot_force_N(0.0, self.drive_for(uu), hh)
            self.force = np.where(inside[None, :], force, np.nan)   # nan beyond the linkage's reach
            theta = np.where(inside, p.theta_at_height(rel_in), np.nan)
            self.delta = tr.delta_tra_m(g, p.coupler_m, theta)
            self.tan_alpha = np.tan(g.leg_angle0_rad + theta - g.theta_fab_rad)
        u_free = np.linspace(-u_max_m, u_max_m, self.FREE_POINTS)
        self.u_free = u_free
        self.h_free = p.free_foot_height_at_deflection_m(u_free) + self.shift_m

    def drive_for(self, u_m: np.ndarray) -> np.ndarray:
        """V_drive (with V_bias = 0) that makes the model's free deflection u."""
        return np.asarray(u_m, dtype=float) / (2.0 * self.per_volt)

    def _h_index(self, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        f = (np.asarray(h, dtype=float) - self.h_grid[0]) / self.h_step
        i = np.clip(f.astype(int), 0, self.H_POINTS - 2)
        return i, f - i

    def force_N(self, u_m: np.ndarray, h_m: np.ndarray) -> np.ndarray:
        """P(u, h) (nan outside the tables or the linkage's reach)."""
        u = np.asarray(u_m, dtype=float)
        fu = (u + self.u_max) / (self.u_grid[1] - self.u_grid[0])
        iu = np.clip(fu.astype(int), 0, self.U_POINTS - 2)
        tu = fu - iu
        ih, th = self._h_index(h_m)
        t = self.force
        out = ((1 - tu) * ((1 - th) * t[iu, ih] + th * t[iu, ih + 1])
               + tu * ((1 - th) * t[iu + 1, ih] + th * t[iu + 1, ih + 1]))
        outside = (np.asarray(h_m) < self.h_grid[0]) | (np.asarray(h_m) > self.h_grid[-1])
        return np.where(outside, np.nan, out)

    def along_h(self, table: np.ndarray, h_m: np.ndarray) -> np.ndarray:
        ih, th = self._h_index(h_m)
        return (1 - th) * table[ih] + th * table[ih + 1]

    def free_height_m(self, u_m: np.ndarray) -> np.ndarray:
        return np.interp(u_m, self.u_free, self.h_free)


class LegStatics:
    """The leg's quasi-static solutions over a set of tables (one per bias value when the bias relaxes; weights
    interpolate linearly between neighbouring biases)."""

    def __init__(self, tables: list[LegTables], k_sensor_N_per_m: float, clamp: Clamp | None) -> None:
        self.tables = tables
        self.k_s = k_sensor_N_per_m
        self.clamp = clamp

    def _blend(self, fn, weights: np.ndarray | None, *args) -> np.ndarray:
        if weights is None or len(self.tables) == 1:
            return fn(self.tables[0], *args)
        out = 0.0
        for j, t in enumerate(self.tables):
            w = weights[j]
            if np.any(w != 0):
                out = out + w * fn(t, *args)
        return np.asarray(out)

    def _u_eff_contact(self, u: np.ndarray, h: np.ndarray, weights) -> np.ndarray:
        """u minus the clamp's give under the chain force k_eff (u_eff - delta(h)) at a held foot (Newton)."""
        if self.clamp is None:
            return u
        c = self.clamp
        k = self._blend(lambda t: np.full(np.shape(u), t.k_eff), weights)
        delta = self._blend(lambda t, hh: t.along_h(t.delta, hh), weights, h)
        ue = u.copy()
        for _ in range(_NEWTON_STEPS):
            f = k * (ue - delta)
            g = ue - u + c.give_m(f)
            step = g / (1.0 + k * c.compliance_m_per_N(f))
            ue = ue - step
            if np.all(np.abs(step[np.isfinite(step)]) <= 1e-16):
                break
        return ue

    def free_position_m(self, u_m: np.ndarray, weights=None) -> np.ndarray:
        """x (downward) of the free foot."""
        u = np.asarray(u_m, dtype=float)
        if self.clamp is not None:
            ue = u.copy()
            for _ in range(8):   # the free chain carries only the flexures' reaction: a few fixed-point steps
                h = self._blend(lambda t, uu: t.free_height_m(uu), weights, ue)
                k = self._blend(lambda t: np.full(np.shape(u), t.k_eff), weights)
                delta = self._blend(lambda t, hh: t.along_h(t.delta, hh), weights, h)
                ue = u - self.clamp.give_m(k * (ue - np.nan_to_num(delta)))
            u = ue
        return -self._blend(lambda t, uu: t.free_height_m(uu), weights, u)

    def frictionless_force_N(self, u_m: np.ndarray, surface_m: np.ndarray, weights=None) -> np.ndarray:
        """N0 with the foot held by the sensor spring at x = surface + N0 / k_s (fixed point: the leg is orders of
        magnitude softer than the sensor, so it converges in a few steps; nan -> no contact possible)."""
        u = np.asarray(u_m, dtype=float)
        h_surface = -np.asarray(surface_m, dtype=float)
        n = np.zeros_like(u)
        for _ in range(40):
            h = h_surface - n / self.k_s
            ue = self._u_eff_contact(u, h, weights)
            new = self._blend(lambda t, a, b: t.force_N(a, b), weights, ue, h)
            new = np.nan_to_num(new, nan=0.0)
            done = np.all(np.abs(new - n) <= _TOL_N)
            n = new
            if done:
                break
        return n

    def tan_alpha(self, surface_m: np.ndarray, weights=None) -> np.ndarray:
        h = -np.asarray(surface_m, dtype=float)
        return np.nan_to_num(self._blend(lambda t, hh: t.along_h(t.tan_alpha, hh), weights, h))

    def corrected_force_N(self, u_m: np.ndarray, surface_m: np.ndarray, factor: np.ndarray, offset_N: np.ndarray,
                          n_first_N: np.ndarray, weights=None) -> np.ndarray:
        """N = factor P - offset, P taken where the friction-modified force holds the sensor spring (one pass
        from the frictionless solution n_first_N: the spring moves the foot by (N - N0) / k_s, which changes P
        by a fraction k_leg / k_s of that, ~1e-4, so one pass leaves ~1e-8 of the force)."""
        n = factor * n_first_N - offset_N
        h = -np.asarray(surface_m, dtype=float) - n / self.k_s
        u = self._u_eff_contact(np.asarray(u_m, dtype=float), h, weights)
        p = np.nan_to_num(self._blend(lambda t, a, b: t.force_N(a, b), weights, u, h))
        return factor * p - offset_N


# ------------------------------------------------------------------ foot friction
@dataclass
class FrictionState:
    tangential_N: float = 0.0


MIN_WEDGE = 0.2   # 1 - mu tan(alpha) floor: beyond it the foot would wedge (the stage would stall instead)


class FootFriction:
    """Friction at the foot, sample by sample in time order (vectorised over runs where the stage holds still)."""

    def __init__(self, mu: float) -> None:
        if not 0 <= mu <= 1.5:
            raise ValueError(f"foot_friction coefficient must be in [0, 1.5], got {mu!r}")
        self.mu = mu
        self.state = FrictionState()

    def snapshot(self) -> FrictionState:
        return FrictionState(self.state.tangential_N)

    def restore(self, s: FrictionState) -> None:
        self.state = FrictionState(s.tangential_N)

    def apply(self, n0: np.ndarray, tan_alpha: np.ndarray, surface_step: np.ndarray) -> tuple[np.ndarray,
                                                                                             np.ndarray]:
        """Per sample: (factor, offset) with N = factor N0 - offset, from N0 (frictionless, > 0 in contact),
        tan(alpha) and the surface's height change since the previous sample (> 0: the stage pushes the foot up).
        The tangential force T (on the foot, along +x) follows: sliding T = -mu N sign(dx); holding T kept but
        |T| <= mu N; out of contact 0."""
        n0 = np.asarray(n0, dtype=float)
        r = np.asarray(tan_alpha, dtype=float)
        dh = np.asarray(surface_step, dtype=float)
        mu = self.mu
        factor = np.ones_like(n0)
        tangential = np.zeros_like(n0)
        contact = n0 > 0
        sliding = contact & (dh != 0)
        sgn = np.sign(dh)
        # sliding: N (1 - mu |r| sgn(dh)) = N0, T = -mu N sign(r dh)
        denom = np.maximum(1.0 - mu * np.abs(r) * sgn, MIN_WEDGE)
        factor = np.where(sliding, 1.0 / denom, 1.0)
        tangential = np.where(sliding, -mu * n0 * factor * np.sign(r * dh), 0.0)
        # holding (in or out of contact, the stage still): T carries over, shrunk to the cone; 0 out of contact
        holding = ~sliding
        t_prev = self.state.tangential_N
        if np.any(holding):
            runs = _runs(holding)
            for a, b in runs:
                t0 = t_prev if a == 0 else tangential[a - 1]
                sign = math.copysign(1.0, t0) if t0 != 0 else 0.0
                if sign == 0.0:
                    tangential[a:b] = 0.0
                    continue
                # the largest |T| the cone allows with this sign: mu N0 / (1 + sign mu r) (0 out of contact)
                bound = np.where(contact[a:b], mu * n0[a:b] / np.maximum(1.0 + sign * mu * r[a:b], MIN_WEDGE), 0.0)
                magnitude = np.minimum(abs(t0), np.minimum.accumulate(np.maximum(bound, 0.0)))
                tangential[a:b] = sign * magnitude
        offset = np.where(holding, tangential * r, 0.0)
        if n0.size:
            self.state.tangential_N = float(tangential[-1])
        return factor, offset


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of each run of True in `mask`."""
    m = np.concatenate([[False], mask, [False]]).astype(int)
    edges = np.flatnonzero(np.diff(m))
    return list(zip(edges[0::2], edges[1::2], strict=True))
