"""The numerical operators the candidate families are built from: the play operator and the generalised
Prandtl-Ishlinskii (PI) deviation curves (hysteresis), the power-law creep kernel and its superposition, the
polynomial d31(E) gain, the power-law series spring solved against the actuator, the penalised-spline baseline.

Pure functions of arrays; no knowledge of recordings or runs (`engine.py` applies them)."""

from __future__ import annotations

import math

import numpy as np
from scipy.interpolate import BSpline
from scipy.signal import fftconvolve

# ------------------------------------------------------------------ hysteresis: play and PI
PI_THRESHOLDS = 16   # play radii r_i = (i - 1/2) / N of the full drive, i = 1..N (covers the whole swing)


def play(x: np.ndarray, half_width: float, y0: float | None = None) -> np.ndarray:
    """Play (backlash) operator: the output follows the input only when pushed beyond +-half_width.

    Vectorised over monotone runs of the input: on a rising run the output is max(y_start, x - w), on a falling
    run min(y_start, x + w); only the runs are looped over."""
    x = np.asarray(x, dtype=float)
    out = np.empty_like(x)
    if x.size == 0:
        return out
    w = abs(half_width)
    y = float(x[0] if y0 is None else y0)
    d = np.sign(np.diff(x))
    nz = np.flatnonzero(d)
    starts = [0]
    if nz.size:
        dn = d[nz]
        starts += list(nz[1:][dn[1:] != dn[:-1]])
    starts.append(x.size - 1)
    out[0] = y = min(max(y, x[0] - w), x[0] + w)
    for a, b in zip(starts[:-1], starts[1:], strict=True):
        seg = x[a + 1:b + 1]
        if seg.size == 0:
            continue
        ys = np.maximum(y, seg - w) if seg[-1] >= x[a] else np.minimum(y, seg + w)
        out[a + 1:b + 1] = ys
        y = float(ys[-1])
    return out


def pi_radii() -> np.ndarray:
    return (np.arange(PI_THRESHOLDS) + 0.5) / PI_THRESHOLDS


def pi_deviations(u: np.ndarray) -> np.ndarray:
    """D_i(t) = u - play_{r_i}(u) for every radius (shape (N, len(u))), each play relaxed at u[0]. Each lies in
    [-r_i, r_i]: positive while u rises (the output lags), negative while it falls, and every D_i changes
    continuously through a reversal, so a weighted sum closes its loops at the reversal points."""
    return np.array([u - play(u, r, y0=float(u[0])) for r in pi_radii()])


def pi_weights(gap_over_span: float, density_exponent: float) -> np.ndarray:
    """Weights alpha_i of the PI hysteresis y = (u - sum alpha_i D_i) / G, G = 1 - sum alpha_i r_i (the full-drive
    gain, so a full-drive cycle keeps its nominal span). Threshold density ~ r^gamma: the loop of a swing +-A has
    half-width sum alpha_i min(r_i, A - r_i)+, growing as A^(gamma + 2) (gamma = 0: a Rayleigh-like loop whose
    share of the span grows ~ A). Scaled so that at full drive (A = 1) the loop's full width at mid-swing over the
    output's span is `gap_over_span`: lambda A1 / (1 - lambda B1) = s."""
    r = pi_radii()
    dens = r ** density_exponent
    a1 = float(np.sum(dens * np.minimum(r, 1.0 - r)))
    b1 = float(np.sum(dens * r))
    return gap_over_span / (a1 + gap_over_span * b1) * dens


def pi_full_drive_gain(weights: np.ndarray) -> float:
    """Peak-to-peak output over input of a full-drive cycle (u = +-1): 1 - sum alpha_i r_i. The family divides
    by it, so its loop is a memory effect at full drive and not also a gain change there (the specimens' gains
    hold the level)."""
    return 1.0 - float(np.sum(weights * pi_radii()))


def pi_slope_after_reversal(gap_over_span: float, density_exponent: float) -> float:
    """dy/du right after a reversal (every play stuck), before the full-drive normalisation: 1 - sum alpha_i."""
    return 1.0 - float(np.sum(pi_weights(gap_over_span, density_exponent)))


# ------------------------------------------------------------------ creep: power law (log law at n -> 0)
CREEP_TAU0_S = 1e-3                # regularises the kernel at the step itself
CREEP_SPAN_DECADES = (-2.0, 2.0)   # the strength is the mean growth per decade over 10 ms - 100 s


def creep_kernel(tau_s: np.ndarray, exponent: float) -> np.ndarray:
    """phi_n(tau) = ((tau + tau0)^n - 1) / (n ln 10) / m_n (tau in s), log10(tau + tau0) at n = 0: zero at 1 s,
    growing by 1 per decade on average over 10 ms - 100 s (m_n: the mean of the slope (tau)^n per decade there).
    A step grows as 1 + g phi_n(t - t_step): low early, on nominal at 1 s, still creeping after (Nutting's power
    law; the log law is its n -> 0 limit)."""
    t = np.asarray(tau_s, float) + CREEP_TAU0_S
    if exponent < 1e-6:
        return np.log10(t)
    a, b = CREEP_SPAN_DECADES
    mean_slope = (10.0 ** (exponent * b) - 10.0 ** (exponent * a)) / (exponent * math.log(10.0) * (b - a))
    return (t ** exponent - 1.0) / (exponent * math.log(10.0)) / mean_slope


def creep_response(y: np.ndarray, dt_s: float, exponent: float) -> np.ndarray:
    """sum_k dy_k phi_n(t - t_k) on a uniform grid (the creep part per unit strength), one FFT convolution."""
    dy = np.r_[0.0, np.diff(y)]
    if dy.size < 2:
        return np.zeros_like(y)
    kernel = creep_kernel(np.arange(dy.size) * dt_s, exponent)
    return fftconvolve(dy, kernel)[:dy.size]


# ------------------------------------------------------------------ field-dependent d31
D31_FIELD_SCALE_V_PER_UM = 2.0   # the polynomial's variable is E / 2 V/um
D31_ANCHOR_V_PER_UM = 1.0        # the nominal d31 is taken to hold here (an effective value over the range)
D31_REF_VOLTS = (100.0, 250.0)   # the strength is the gain at 250 V over the gain at 100 V (nominal plate)


def d31_gain(field_V_per_um: np.ndarray, slope: float, curvature: float) -> np.ndarray:
    """G(E) = 1 + a [(1 - q) x + q x^2], x = E / 2 V/um: a polynomial in field of either sign (a < 0: d31 falls
    with field), q the quadratic share. Floored at 0.05 (a d31 cannot change sign)."""
    x = np.abs(field_V_per_um) / D31_FIELD_SCALE_V_PER_UM
    return np.maximum(1.0 + slope * ((1.0 - curvature) * x + curvature * x * x), 0.05)


def d31_slope(strength: float, curvature: float, pzt_thickness_m: float) -> float:
    """The polynomial's coefficient a for which G(250 V / t_p) / G(100 V / t_p) - 1 = strength (t_p the nominal
    plate): the ratio is a Moebius function of a, inverted in closed form."""
    x1, x2 = (v / pzt_thickness_m * 1e-6 / D31_FIELD_SCALE_V_PER_UM for v in D31_REF_VOLTS)
    p1 = (1.0 - curvature) * x1 + curvature * x1 * x1
    p2 = (1.0 - curvature) * x2 + curvature * x2 * x2
    den = p2 - (1.0 + strength) * p1
    return strength / den if abs(den) > 1e-12 else 0.0


def plate_map(v_V: np.ndarray, pzt_thickness_m: float, strength: float, curvature: float,
              ref_thickness_m: float | None = None) -> np.ndarray:
    """Effective plate voltage v G(E) / G(E_anchor): the strain a plate makes with the field-dependent d31, in
    volts of the nominal d31. The strength refers to the nominal plate `ref_thickness_m` (default: this one)."""
    a = d31_slope(strength, curvature, ref_thickness_m or pzt_thickness_m)
    e = np.abs(v_V) / pzt_thickness_m * 1e-6
    anchor = float(d31_gain(np.array([D31_ANCHOR_V_PER_UM]), a, curvature)[0])
    return v_V * d31_gain(e, a, curvature) / anchor


# ------------------------------------------------------------------ series spring (power law, push / pull)
SPRING_REF_FORCE_N = 0.05   # the sensor spring's strength is its secant compliance at this force


def compliance_for_loss(loss: float, k_N_per_m: float, f0_N: float, exponent: float) -> float:
    """The compliance C of a spring x = C F_ref (F/F_ref)^beta that takes the fraction `loss` off a blocked force
    f0 of an actuator of stiffness k: F = (1 - loss) f0 and F + k x(F) = f0."""
    loss = min(max(loss, 0.0), 0.95)
    f = (1.0 - loss) * f0_N
    return loss * f0_N / (k_N_per_m * SPRING_REF_FORCE_N * (f / SPRING_REF_FORCE_N) ** exponent)


def spring_deflection(force_N: np.ndarray, compliance: float, exponent: float, pull_ratio: float) -> np.ndarray:
    """x(F) = C F_ref (F / F_ref)^beta pushing, -rho C F_ref (|F| / F_ref)^beta pulling: beta < 1 stiffens with
    load, rho != 1 differs between push and pull."""
    f = np.asarray(force_N, float)
    mag = compliance * SPRING_REF_FORCE_N * (np.abs(f) / SPRING_REF_FORCE_N) ** exponent
    return np.where(f >= 0, mag, -pull_ratio * mag)


def spring_solve_many(f0_N: np.ndarray, k_N_per_m: float, springs: list[tuple[float, float, float]],
                      points: int = 600) -> np.ndarray:
    """F with F + k sum_j x_j(F) = F0: the actuator's force F0 = F_piezo + k x_push on a support that gives way by
    the series springs' deflections x_j (each (C, beta, rho), `spring_deflection`). The left side is monotone in
    F, so its inverse is tabulated on a fine grid of F (geometric from 1 uN to beyond the largest |F0|, each
    side) and interpolated; linear springs have the closed form."""
    f0 = np.asarray(f0_N, float)
    if not springs:
        return f0.copy()
    if all(beta == 1.0 for _, beta, _ in springs):
        push = 1.0 + k_N_per_m * sum(c for c, _, _ in springs)
        pull = 1.0 + k_N_per_m * sum(c * rho for c, _, rho in springs)
        return np.where(f0 >= 0, f0 / push, f0 / pull)
    top = max(float(np.max(np.abs(f0))) if f0.size else 0.0, 1e-5)
    f = np.r_[0.0, np.geomspace(1e-6, top, points)]
    out = np.empty_like(f0)
    for sign, side in ((1.0, f0 >= 0), (-1.0, f0 < 0)):
        if not side.any():
            continue
        left = f + k_N_per_m * sum(sign * spring_deflection(sign * f, c, beta, rho) for c, beta, rho in springs)
        out[side] = sign * np.interp(np.abs(f0[side]), left, f)
    return out


# ------------------------------------------------------------------ baseline (sensor drift)
def spline_basis(t: np.ndarray, t0: float, t1: float, knot_s: float) -> np.ndarray:
    """Cubic B-spline basis over [t0, t1] with interior knots about every `knot_s` (columns sum to 1)."""
    span = max(t1 - t0, 1e-6)
    n_int = max(0, int(math.floor(span / knot_s)))
    inner = np.linspace(t0, t1, n_int + 2)
    knots = np.r_[[t0] * 3, inner, [t1] * 3]
    x = np.clip(np.asarray(t, float), t0, t1)
    return BSpline.design_matrix(x, knots, 3).toarray()


def warm_up(t_since_start_s: np.ndarray, tau_s: float) -> np.ndarray:
    """t / (t + tau): a saturating warm-up (the bench's is exponential; this one is algebraic)."""
    t = np.maximum(np.asarray(t_since_start_s, float), 0.0)
    return t / (t + tau_s)
