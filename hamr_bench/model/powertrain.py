"""The lift powertrain: actuator + serial compliance + slider-crank + flexures + leg, solved quasi-statically.

Single degree of freedom, the crank angle theta. Potential energy (paper eqs. 1-4 integrated):

    U(theta) = 1/2 A k_act (delta_tra(theta) - u)^2 + 1/2 sum_i kappa_i Phi_i(theta)^2
               + 1/2 k_sw eps^2 (theta - theta_fab)^2

with u = F_piezo / k_act the actuator's free tip deflection for the drive (bias-drive-ground), A = 1/(1 + k_act/k_ser),
delta_tra the transmission input (positive toward the hip, the direction V_drive = V_bias pushes), and the last term
only for the 2-DOF design (swing chain coupled by eps). Eliminating the internal actuator deflection
delta_act = (k_act u + k_ser delta_tra)/(k_act + k_ser) gives the series spring A k_act.

Foot height h(theta) is positive up. A support holding the foot at h feels the downward force

    F = U'(theta) / h'(theta)
      = [A k_act (u - delta_tra) - sum_i kappa_i Phi_i dPhi_i/d delta_tra] / R_tra          (paper eq. 4)

(the paper prints "+" on the flexure terms; with Phi measured from the straight flexure the virtual work of a
restoring spring is "-"; tests check a stiffer flexure resists motion). Heights are reported from the undriven
neutral theta_n (U'(theta_n) = 0 at u = 0), which for a biased design is already rotated away from theta_fab.

Holding the foot fixes theta, so foot_force_N is closed form. Free and loaded equilibria are solved vectorised: G(theta)
on a coarse grid across the linkage's range, the stable crossing (G from - to +) nearest the neutral, then bisection.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike

from hamr_bench.errors import ModelError
from hamr_bench.model import actuator as act
from hamr_bench.model import transmission as tr
from hamr_bench.model.actuator import ActuatorParams, actuator_preset
from hamr_bench.model.contact import PRESSING, friction_reading_ratio
from hamr_bench.model.designs import DesignParams, design_preset
from hamr_bench.model.effects import Effect, active, apply_voltage_series
from hamr_bench.model.flexures import FlexureStrip, SerialChain

DEFAULT_VOLTAGE_LIMIT_V = 250.0
_GRID_POINTS = 97
_ILLINOIS_STEPS = 40


_CACHE_SIZE = 4096
_NEUTRAL_CACHE: dict[tuple, float] = {}  # the undriven equilibrium of a powertrain, by what it depends on


@lru_cache(maxsize=_CACHE_SIZE)
def _serial_chain(k_eff_N_per_m: float, strip: FlexureStrip) -> SerialChain:
    """The buckling chain for this stiffness and strip (read-only; a fit builds many powertrains that share it)."""
    return SerialChain(k_eff_N_per_m, strip)


@lru_cache(maxsize=_CACHE_SIZE)
def _crank_grid(lo: float, hi: float) -> np.ndarray:
    """The solver's bracketing grid over an operating range (read-only, shared by powertrains with that range)."""
    grid = np.linspace(lo, hi, _GRID_POINTS)
    grid.flags.writeable = False
    return grid


@lru_cache(maxsize=_CACHE_SIZE)
def _closing_range(g: tr.SliderCrankGeometry, coupler_m: float) -> tuple[float, float] | None:
    """The crank range around theta_fab where the linkage with this coupler closes on one monotone branch (between
    the two toggle points); None where it does not close at theta_fab. It depends on the geometry alone."""
    th = np.linspace(g.theta_fab_rad - 1.4, g.theta_fab_rad + 1.4, 2801)
    s = g.crank_m * np.sin(th) - g.offset_m
    ok = np.abs(s) < 0.995 * coupler_m
    dd = tr.ddelta_tra_dtheta(g, coupler_m, np.where(ok, th, g.theta_fab_rad))
    ok &= dd > 0
    i0 = int(np.argmin(np.abs(th - g.theta_fab_rad)))
    if not ok[i0]:
        return None
    # the contiguous run of `ok` around i0
    bad = np.flatnonzero(~ok)
    lo = int(bad[bad < i0].max()) + 1 if np.any(bad < i0) else 0
    hi = int(bad[bad > i0].min()) - 1 if np.any(bad > i0) else th.size - 1
    return float(th[lo]), float(th[hi])


@dataclass(frozen=True)
class ThetaTerms:
    """What G(theta) needs from the crank angle alone (flex1, flex2: the first two flexures' torques; None for a
    linkage without flexure stiffness)."""

    delta: np.ndarray
    ddelta: np.ndarray
    phi3: np.ndarray
    flex1: np.ndarray | None
    flex2: np.ndarray | None


@dataclass(frozen=True)
class HeldFoot:
    """A powertrain's linkage with the foot held at given heights (`Powertrain.hold_foot`): which heights the
    linkage reaches, the crank angles (the neutral where it does not), their G terms and dh/dtheta."""

    inside: np.ndarray
    theta_rad: np.ndarray
    terms: ThetaTerms
    dheight: np.ndarray

    def take(self, index: np.ndarray) -> HeldFoot:
        """The same linkage at heights[index]: solved once per distinct height, then spread."""
        t = self.terms
        flex = [None if a is None else a[index] for a in (t.flex1, t.flex2)]
        return HeldFoot(self.inside[index], self.theta_rad[index],
                        ThetaTerms(t.delta[index], t.ddelta[index], t.phi3[index], flex[0], flex[1]),
                        self.dheight[index])


class Powertrain:
    """One lift powertrain (actuator + design) with optional effects. All methods broadcast over numpy arrays."""

    def __init__(self, actuator: ActuatorParams, design: DesignParams, effects: Sequence[Effect] = (),
                 voltage_limit_V: float = DEFAULT_VOLTAGE_LIMIT_V) -> None:
        self.effects = tuple(effects)
        self.voltage_limit_V = float(voltage_limit_V)
        for e in active(self.effects, "actuator_params"):
            actuator = e.actuator_params(actuator)
        for e in active(self.effects, "design_params"):
            design = e.design_params(design)
        self.actuator = actuator
        self.design = design
        self.geometry = design.geometry
        self.coupler_m = design.coupler_m
        self._plate_effects = active(self.effects, "plate_voltage")
        self._force_effects = active(self.effects, "foot_force")

        self.k_act_N_per_m = act.stiffness_N_per_m(actuator)
        k_ser = design.k_ser_N_per_m
        for e in active(self.effects, "serial_stiffness"):
            k_ser = e.serial_stiffness(k_ser, actuator)
        self.k_ser_N_per_m = float(k_ser)
        self.A = 1.0 / (1.0 + self.k_act_N_per_m / self.k_ser_N_per_m)
        self.k_eff_N_per_m = self.A * self.k_act_N_per_m
        self.kappa = np.asarray(design.kappa_N_m_per_rad, dtype=float)
        # The coupler's Kapton strips buckle past their Euler load: the serial chain softens (flexures.py).
        strip = design.flexure_strip if design.coupler_buckling else None
        self.serial_chain = _serial_chain(self.k_eff_N_per_m, strip) if strip is not None else None

        g = self.geometry
        # Swing chain rotational stiffness at its own crank (undriven, unbiased copy of this transmission).
        if design.swing:
            dd = float(tr.ddelta_tra_dtheta(g, g.coupler_m, g.theta_fab_rad))
            dphi = tr.joint_dangles_dtheta(g, g.coupler_m, g.theta_fab_rad)
            self.k_swing_N_m_per_rad = self.k_eff_N_per_m * dd**2 + float(np.sum(self.kappa * dphi**2))
            self.k_swing_coupled = self.k_swing_N_m_per_rad * design.swing_coupling**2
        else:
            self.k_swing_N_m_per_rad = 0.0
            self.k_swing_coupled = 0.0

        self._x_ref = tr.reference_slider_x_m(g)
        self._psi_fab = float(tr.coupler_angle_rad(g, self.coupler_m, g.theta_fab_rad))
        self._has_flex = bool(np.any(self.kappa != 0) or self.k_swing_coupled != 0)
        self._theta_lo, self._theta_hi = self._operating_range()
        self._grid = _crank_grid(self._theta_lo, self._theta_hi)
        # Fits build many powertrains that differ only in what the undriven equilibrium does not see (the
        # actuator's d31, a drive effect), so it is kept by everything it depends on.
        neutral_key = (g, self.coupler_m, self.k_eff_N_per_m, strip, tuple(self.kappa.tolist()), self.k_swing_coupled)
        th_n = _NEUTRAL_CACHE.get(neutral_key)
        if th_n is None:
            th_n = self._solve(np.zeros(1), np.zeros(1), g.theta_fab_rad)[0]
            if len(_NEUTRAL_CACHE) >= _CACHE_SIZE:
                _NEUTRAL_CACHE.clear()
            _NEUTRAL_CACHE[neutral_key] = th_n
        if not np.isfinite(th_n):
            raise ModelError(f"design {design.design}: no stable undriven equilibrium with this geometry and bias "
                             f"(bias_m={design.bias_m:.4g})")
        self.theta_neutral_rad = float(th_n)
        self._h_neutral_fab = float(tr.foot_height_fab_m(g, th_n))

    # --- pipeline stages -----------------------------------------------------------------------------------
    def _voltage_map(self, v: np.ndarray) -> np.ndarray:
        for e in self._plate_effects:
            v = e.plate_voltage(v, self.actuator)
        return v

    def plate_voltage_map(self, v_plate_V: ArrayLike) -> np.ndarray:
        """Public form of the per-plate voltage map after field effects (identity when none is active)."""
        return self._voltage_map(np.asarray(v_plate_V, dtype=float))

    def free_foot_height_at_deflection_m(self, u_m: ArrayLike) -> np.ndarray:
        """Free foot height (from neutral, positive up) for a given free actuator deflection u (drive-agnostic)."""
        u = np.asarray(u_m, dtype=float)
        return self.foot_height_m(self._solve(u, np.zeros_like(u), self.theta_neutral_rad, stops=True))

    def check_voltage(self, voltage_V: ArrayLike, name: str = "voltage_V") -> np.ndarray:
        v = np.asarray(voltage_V, dtype=float)
        # One reduction on the usual (valid) path: the simulated bench asks this per sensor read and camera frame.
        # The peak is NaN if any value is, and NaN <= limit is False.
        if v.size and not float(np.abs(v).max()) <= self.voltage_limit_V:
            if not np.all(np.isfinite(v)):
                raise ModelError(f"{name} must be finite")
            raise ModelError(f"{name}={float(np.max(np.abs(v))):.6g} V exceeds the configured limit "
                             f"{self.voltage_limit_V:g} V")
        return v

    def free_actuator_deflection_m(self, v_bias_V: ArrayLike, v_drive_V: ArrayLike) -> np.ndarray:
        """u: the bare actuator's free tip deflection for this drive (after field effects)."""
        vb = self.check_voltage(v_bias_V, "v_bias_V")
        vd = self.check_voltage(v_drive_V, "v_drive_V")
        if self._plate_effects:
            return act.free_tip_deflection_m(self.actuator, vb, vd, self._voltage_map)
        return act.free_tip_deflection_m(self.actuator, vb, vd)

    def apply_voltage_series(self, time_s: ArrayLike, v_bias_V: ArrayLike, v_drive_V: ArrayLike):
        """Memory effects (hook `voltage_series`) on a time series; feed the result to the quasi-static methods."""
        return apply_voltage_series(self.effects, time_s, v_bias_V, v_drive_V)

    def _out(self, force_N: np.ndarray) -> np.ndarray:
        for e in self._force_effects:
            force_N = e.foot_force(force_N)
        return force_N

    # --- energy and its derivative -------------------------------------------------------------------------
    def energy_J(self, theta_rad: ArrayLike, u_m: ArrayLike) -> np.ndarray:
        """Stored energy U(theta) for actuator free deflection u (J)."""
        g, c = self.geometry, self.coupler_m
        th = np.asarray(theta_rad, dtype=float)
        d = tr.delta_tra_m(g, c, th)
        phi = tr.joint_angles_rad(g, c, th)
        flex = 0.5 * np.tensordot(self.kappa, phi**2, axes=1)
        sw = 0.5 * self.k_swing_coupled * (th - g.theta_fab_rad) ** 2
        return self.chain_energy_J(np.asarray(u_m) - d) + flex + sw

    def chain_force_N(self, gap_m: ArrayLike) -> np.ndarray:
        """Force through the actuator-serial-coupler chain for an overlap gap = u - delta_tra (> 0: compression)."""
        if self.serial_chain is None:
            return self.k_eff_N_per_m * np.asarray(gap_m, dtype=float)
        return self.serial_chain.force_N(gap_m)

    def chain_energy_J(self, gap_m: ArrayLike) -> np.ndarray:
        if self.serial_chain is None:
            return 0.5 * self.k_eff_N_per_m * np.asarray(gap_m, dtype=float) ** 2
        return self.serial_chain.energy_J(gap_m)

    def coupler_force_N(self, v_bias_V: ArrayLike, v_drive_V: ArrayLike, foot_height_m: ArrayLike) -> np.ndarray:
        """Compression carried by the input link (along the transmission input) with the foot held at a height."""
        u = self.free_actuator_deflection_m(v_bias_V, v_drive_V)
        th = self.theta_at_height(foot_height_m)
        return self.chain_force_N(u - tr.delta_tra_m(self.geometry, self.coupler_m, th))

    def _flex_torque(self, th: np.ndarray) -> np.ndarray:
        g, c = self.geometry, self.coupler_m
        phi = tr.joint_angles_rad(g, c, th)
        dphi = tr.joint_dangles_dtheta(g, c, th)
        return np.tensordot(self.kappa, phi * dphi, axes=1) + self.k_swing_coupled * (th - g.theta_fab_rad)

    def denergy_dtheta(self, theta_rad: ArrayLike, u_m: ArrayLike) -> np.ndarray:
        """U'(theta) (N m / rad)."""
        g, c = self.geometry, self.coupler_m
        th = np.asarray(theta_rad, dtype=float)
        d = tr.delta_tra_m(g, c, th)
        dd = tr.ddelta_tra_dtheta(g, c, th)
        return -self.chain_force_N(np.asarray(u_m) - d) * dd + self._flex_torque(th)

    # --- solver ------------------------------------------------------------------------------------------------
    def _operating_range(self) -> tuple[float, float]:
        """Contiguous crank range around theta_fab where the (biased) linkage closes, on one monotone branch."""
        g, c = self.geometry, self.coupler_m
        span = _closing_range(g, c)
        if span is None:
            raise ModelError(f"design {self.design.design}: transmission geometry cannot close or is at a toggle "
                             f"at theta_fab (coupler_m={c:.6g}, crank_m={g.crank_m:.6g}, offset_m={g.offset_m:.6g})")
        return span

    def _theta_terms(self, th: np.ndarray) -> ThetaTerms:
        """The factors of G that depend on the crank angle alone: the transmission input, its derivative and the
        flexures' torques (same equations as transmission.py, constants cached; one pass of the trigonometry)."""
        g = self.geometry
        r, e, l = g.crank_m, g.offset_m, self.coupler_m
        sn, cs = np.sin(th), np.cos(th)
        s = r * sn - e
        q = np.sqrt(l * l - s * s)
        delta = self._x_ref - r * cs - q
        ddelta = r * sn + s * r * cs / q
        phi3 = th - g.theta_fab_rad
        if not self._has_flex:
            return ThetaTerms(delta, ddelta, phi3, None, None)
        dpsi = -r * cs / q
        phi1 = -np.arcsin(s / l) - self._psi_fab
        k1, k2, _ = self.kappa
        return ThetaTerms(delta, ddelta, phi3, k1 * phi1 * dpsi, k2 * (phi3 - phi1) * (1.0 - dpsi))

    def _G_of(self, terms: ThetaTerms, u: np.ndarray, load: np.ndarray | float) -> np.ndarray:
        """U'(theta) - load h'(theta) from the angle's terms and the drive's free deflection u."""
        g = self.geometry
        delta, ddelta, phi3 = terms.delta, terms.ddelta, terms.phi3
        chain = self.k_eff_N_per_m * (u - delta) if self.serial_chain is None else self.serial_chain.force_N(u - delta)
        if isinstance(load, float) and load == 0.0:
            out = -(chain * ddelta)
        else:
            out = load * g.leg_length_m * np.cos(g.leg_angle0_rad + phi3) - chain * ddelta
        if terms.flex1 is not None:
            out = out + terms.flex1 + terms.flex2 + (self.kappa[2] + self.k_swing_coupled) * phi3
        return out

    def _G(self, th: np.ndarray, u: np.ndarray, load: np.ndarray | float) -> np.ndarray:
        """U'(theta) - load h'(theta), one fused pass."""
        return self._G_of(self._theta_terms(th), u, load)

    def _solve(self, u_m: np.ndarray, load_N: np.ndarray, theta_start: float, stops: bool = False) -> np.ndarray:
        """Stable root of U'(theta) - load h'(theta) nearest theta_start, vectorised; nan where none exists.

        With `stops`, an input pushed beyond the branch's end rests at the end (the linkage's dead point).
        """
        u, load = np.broadcast_arrays(np.asarray(u_m, float), np.asarray(load_N, float))
        shape = u.shape
        u = u.reshape(-1, 1)
        load = load.reshape(-1, 1)
        grid = self._grid
        Gg = self._G(grid[None, :], u, load)                       # (N, M)
        stable = (Gg[:, :-1] < 0) & (Gg[:, 1:] >= 0)
        mid = 0.5 * (grid[:-1] + grid[1:])
        dist = np.where(stable, np.abs(mid - theta_start)[None, :], np.inf)
        j = np.argmin(dist, axis=1)
        rows = np.arange(dist.shape[0])
        found = np.isfinite(dist[rows, j])
        lo = grid[j].copy()
        hi = grid[j + 1].copy()
        glo = Gg[rows, j]
        ghi = Gg[rows, j + 1]
        u1 = u[:, 0]
        l1 = load[:, 0]
        # Illinois (modified regula falsi) inside the bracket: superlinear, never leaves it.
        side = np.zeros(lo.shape, dtype=int)
        m = m_prev = lo
        for _ in range(_ILLINOIS_STEPS):
            denom = np.where(found, ghi - glo, 1.0)
            m = np.where(found, (lo * ghi - hi * glo) / denom, lo)
            m = np.clip(m, np.minimum(lo, hi), np.maximum(lo, hi))
            gm = self._G(m, u1, l1)
            neg = gm < 0
            # keep the sign-change bracket; halve the stale end's value when the same side moves twice
            glo_new = np.where(neg, gm, np.where(side == 1, 0.5 * glo, glo))
            ghi_new = np.where(neg, np.where(side == -1, 0.5 * ghi, ghi), gm)
            lo = np.where(neg, m, lo)
            hi = np.where(neg, hi, m)
            glo, ghi = glo_new, ghi_new
            side = np.where(neg, -1, 1)
            if _ > 2 and np.all(np.abs(m - m_prev) <= 1e-14):
                break
            m_prev = m
        out = np.where(found, m, np.nan)
        if stops:
            # Driven past the end of the branch: the slider-crank reaches its dead point (input at maximum travel)
            # and locks there. Only when no interior equilibrium exists and the push is toward that end.
            at_hi = ~found & (Gg[:, -1] < 0) & (Gg[:, 0] < 0)
            at_lo = ~found & (Gg[:, 0] > 0) & (Gg[:, -1] > 0)
            out = np.where(at_hi, grid[-1], np.where(at_lo, grid[0], out))
        return out.reshape(shape)

    # --- public quasi-static primitives ------------------------------------------------------------------------
    def foot_height_m(self, theta_rad: ArrayLike) -> np.ndarray:
        """Foot height from the undriven neutral (positive up) at crank angle theta."""
        return tr.foot_height_fab_m(self.geometry, theta_rad) - self._h_neutral_fab

    def theta_at_height(self, foot_height_m: ArrayLike) -> np.ndarray:
        return tr.theta_from_foot_height(self.geometry, np.asarray(foot_height_m, float) + self._h_neutral_fab)

    def foot_force_N(self, v_bias_V: ArrayLike, v_drive_V: ArrayLike, foot_height_m: ArrayLike,
                     friction_mu: ArrayLike = 0.0, foot_sliding: ArrayLike = PRESSING) -> np.ndarray:
        """Downward force on a rigid support holding the foot at foot_height_m (from neutral, positive up).

        Negative means the leg would pull away. nan where that height is outside the linkage's range.
        With friction_mu > 0 it is the vertical reading of a flat support with Coulomb friction, the foot sliding
        `foot_sliding` (contact.py: +1 pressing down, -1 pushed up by the support); frictionless by default.
        """
        u = self.free_actuator_deflection_m(v_bias_V, v_drive_V)
        return self.force_on_held_foot(self.hold_foot(foot_height_m), u, friction_mu, foot_sliding)

    @property
    def held_foot_key(self) -> tuple:
        """Everything a `HeldFoot` of this powertrain depends on: powertrains with equal keys share them (a fit
        that changes only the drive evaluates the linkage at the same heights again)."""
        return (self.geometry, self.coupler_m, tuple(self.kappa.tolist()), self._has_flex, self._h_neutral_fab,
                self.theta_neutral_rad)

    def hold_foot(self, foot_height_m: ArrayLike) -> HeldFoot:
        """The linkage with its foot held at these heights: every factor of the support force but the drive."""
        th = self.theta_at_height(foot_height_m)
        inside = (th >= self._theta_lo) & (th <= self._theta_hi)
        th_safe = np.where(inside, th, self.theta_neutral_rad)
        return HeldFoot(inside, th_safe, self._theta_terms(th_safe), tr.dfoot_height_dtheta(self.geometry, th_safe))

    def force_on_held_foot(self, held: HeldFoot, u_m: ArrayLike, friction_mu: ArrayLike = 0.0,
                           foot_sliding: ArrayLike = PRESSING) -> np.ndarray:
        """`foot_force_N` for a free actuator deflection u at heights already held (`hold_foot`)."""
        f = self._G_of(held.terms, np.asarray(u_m, float), 0.0) / held.dheight
        if np.any(np.asarray(friction_mu) != 0):
            f = f * friction_reading_ratio(self.leg_angle_rad(held.theta_rad), friction_mu, foot_sliding)
        return self._out(np.where(held.inside, f, np.nan))

    def blocked_force_N(self, voltage_V: ArrayLike, sag_m: ArrayLike = 0.0, friction_mu: ArrayLike = 0.0,
                        foot_sliding: ArrayLike = PRESSING) -> np.ndarray:
        """Paper test: V_bias = V_drive = voltage, sensor raised by sag_m above the foot's undriven neutral."""
        return self.foot_force_N(voltage_V, voltage_V, sag_m, friction_mu, foot_sliding)

    def leg_angle_rad(self, theta_rad: ArrayLike) -> np.ndarray:
        """Angle of the hip-to-foot line below horizontal at crank angle theta (contact.py's beta)."""
        g = self.geometry
        return g.leg_angle0_rad + np.asarray(theta_rad, dtype=float) - g.theta_fab_rad

    def free_foot_height_m(self, v_bias_V: ArrayLike, v_drive_V: ArrayLike) -> np.ndarray:
        """Foot height (from neutral, positive up) with nothing touching the foot."""
        u = self.free_actuator_deflection_m(v_bias_V, v_drive_V)
        th = self._solve(u, np.zeros_like(u), self.theta_neutral_rad, stops=True)
        return self.foot_height_m(th)

    def free_displacement_m(self, voltage_V: ArrayLike) -> np.ndarray:
        """Leg stroke, ONE-SIDED: downward travel of the free foot from neutral at V_drive = V_bias = voltage."""
        return -self.free_foot_height_m(voltage_V, voltage_V)

    def static_displacement_m(self, force_N: ArrayLike) -> np.ndarray:
        """Actuator undriven: how far the foot is pushed up (the sag, >= 0 for a downward load) by force_N."""
        f = np.asarray(force_N, dtype=float)
        th = self._solve(np.zeros_like(f), f, self.theta_neutral_rad)
        return self.foot_height_m(th)

    # --- diagnostics -----------------------------------------------------------------------------------------------
    def transmission_ratio(self, foot_height_m: ArrayLike = 0.0) -> np.ndarray:
        return tr.transmission_ratio(self.geometry, self.coupler_m, self.theta_at_height(foot_height_m))

    def leg_stiffness_N_per_m(self, foot_height_m: ArrayLike = 0.0, step_m: float = 1e-6) -> np.ndarray:
        """dF/dh of the undriven leg (N/m): how fast the support force grows as the foot is pushed up (sag)."""
        h = np.asarray(foot_height_m, float)
        return (self.foot_force_N(0.0, 0.0, h + step_m) - self.foot_force_N(0.0, 0.0, h - step_m)) / (2 * step_m)


def powertrain(design: int, layers: int = 2, params: str = "effective", effects: Sequence[Effect] = (),
               voltage_limit_V: float = DEFAULT_VOLTAGE_LIMIT_V, **design_kwargs) -> Powertrain:
    """Factory: the paper's powertrain for `design` (1..5) with the `layers`-layer actuator."""
    return Powertrain(actuator_preset(layers, params), design_preset(design, **design_kwargs), effects,
                      voltage_limit_V)
