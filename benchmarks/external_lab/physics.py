"""The bimorph written from the published equations: a layer-stack beam section (neutral axis, bending
rigidity, each plate's piezoelectric moment) and a finite-element tapered cantilever with a rigid tip
extension, clamped rigidly or held by a compliant clamp (an elastic foundation under the clamped length).

Beam theory, not the project's closed form: the section is summed layer by layer about the modulus-weighted
neutral axis, so plates of different thickness or modulus are allowed (the bias-drive-ground zero then moves
off V_bias / 2), and the cantilever is solved by Hermite beam elements, so a depoled edge band or a compliant
clamp enter as what they are. For two equal plates and a rigid clamp it reduces to the laminate closed form of
the physics notes (D, F_b, delta, G_F, G_D); tests/benchmarks/test_external_lab.py checks that limit against
an independent quadrature and against the project's model.

Sign convention (the bias-drive-ground wiring of the paper's Fig. 6): the bottom plate sees V_drive and pushes
the tip toward the force sensor (+), the top plate sees V_bias - V_drive and pulls it back (-). SI units
throughout.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

# Table I, "effective" column (Ozcan, Baisch, Wood, ICRA 2014): the values the paper's model reproduces the
# data with. A per-layer cured carbon-fibre thickness; the CF modulus is the physics notes' assumption.
TABLE_I_EFFECTIVE = {
    "cf_layer_m": 30e-6,
    "pzt_thickness_m": 155e-6,
    "length_m": 9.6e-3,
    "width_nom_m": 3.4e-3,
    "length_ratio": 0.0063,
    "width_ratio": 1.5,
    "d31_m_per_V": 0.36e-9,
    "pzt_modulus_Pa": 34e9,
}
CF_MODULUS_PA = 340e9
# Elements along the active length: Hermite cubics converge as h^4, so 40 are exact to ~1e-8 here.
ACTIVE_ELEMENTS = 40
CLAMP_ELEMENTS = 24
_GAUSS_X, _GAUSS_W = np.polynomial.legendre.leggauss(4)
_GAUSS_X = 0.5 * (_GAUSS_X + 1.0)
_GAUSS_W = 0.5 * _GAUSS_W


@dataclass(frozen=True)
class Build:
    """One actuator as built. The plates are separate (bottom sees V_drive, top sees V_bias - V_drive)."""

    layers: int
    cf_thickness_m: float
    pzt_bottom_m: float
    pzt_top_m: float
    modulus_bottom_Pa: float
    modulus_top_Pa: float
    d31_bottom_m_per_V: float
    d31_top_m_per_V: float
    length_m: float
    width_nom_m: float
    width_ratio: float
    length_ratio: float
    cf_modulus_Pa: float = CF_MODULUS_PA
    # Laser-cut heat-affected band along each cut edge: depoled (no piezo moment), its PZT softened by a
    # factor.
    edge_band_m: float = 0.0
    edge_band_modulus_factor: float = 1.0
    # Grounding: an electroded length inside the clamp, held by an elastic foundation (N/m per m of length);
    # 0 length = a rigid clamp at the root.
    clamp_length_m: float = 0.0
    clamp_foundation_N_per_m2: float = math.inf


def nominal_build(layers: int) -> Build:
    """Table I effective values, two equal plates, rigid clamp."""
    t = TABLE_I_EFFECTIVE
    return Build(layers=layers, cf_thickness_m=layers * t["cf_layer_m"], pzt_bottom_m=t["pzt_thickness_m"],
                 pzt_top_m=t["pzt_thickness_m"], modulus_bottom_Pa=t["pzt_modulus_Pa"],
                 modulus_top_Pa=t["pzt_modulus_Pa"], d31_bottom_m_per_V=t["d31_m_per_V"],
                 d31_top_m_per_V=t["d31_m_per_V"], length_m=t["length_m"], width_nom_m=t["width_nom_m"],
                 width_ratio=t["width_ratio"], length_ratio=t["length_ratio"])


@dataclass(frozen=True)
class Section:
    """Per unit width: bending rigidity about the neutral axis (N m) and each plate's moment per volt
    (N/V)."""

    rigidity_N_m: float
    moment_bottom_N_per_V: float
    moment_top_N_per_V: float


def section(b: Build, pzt_modulus_scale: float = 1.0, depoled: bool = False) -> Section:
    """Sum over the three layers (bottom PZT, CF, top PZT) about the modulus-weighted centroid. A plate's
    in-plane piezo force per width is d31 E V (field V/t times area t), acting at its mid-plane: its moment
    about the neutral axis is that force times the lever."""
    eb, et = b.modulus_bottom_Pa * pzt_modulus_scale, b.modulus_top_Pa * pzt_modulus_scale
    t = np.array([b.pzt_bottom_m, b.cf_thickness_m, b.pzt_top_m])
    e = np.array([eb, b.cf_modulus_Pa, et])
    top = np.cumsum(t)
    mid = top - t / 2.0
    z_n = float(np.sum(e * t * mid) / np.sum(e * t))
    rigidity = float(np.sum(e * (t**3 / 12.0 + t * (mid - z_n) ** 2)))
    if depoled:
        return Section(rigidity, 0.0, 0.0)
    return Section(rigidity, b.d31_bottom_m_per_V * eb * abs(mid[0] - z_n),
                   b.d31_top_m_per_V * et * abs(mid[2] - z_n))


@dataclass(frozen=True)
class Coefficients:
    """Tip (end of the rigid extension) response: free deflection per volt on each plate (m/V, both positive:
    the bottom plate pushes +, the top plate pulls -) and the compliance to a tip force (m/N)."""

    free_bottom_m_per_V: float
    free_top_m_per_V: float
    compliance_m_per_N: float

    @property
    def stiffness_N_per_m(self) -> float:
        return 1.0 / self.compliance_m_per_N

    def free_deflection_m(self, v_bottom: np.ndarray, v_top: np.ndarray) -> np.ndarray:
        return self.free_bottom_m_per_V * v_bottom - self.free_top_m_per_V * v_top


def _width(b: Build, x: np.ndarray) -> np.ndarray:
    """Linear taper from w_r w_nom at the root to (2 - w_r) w_nom at the tip; the clamped part keeps the root
    width."""
    w_base = b.width_ratio * b.width_nom_m
    w_tip = (2.0 - b.width_ratio) * b.width_nom_m
    return np.where(x < 0.0, w_base, w_base + (w_tip - w_base) * np.clip(x, 0.0, None) / b.length_m)


def _hermite(xi: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shape functions and their second x-derivatives at local coordinates xi (1-D) for elements of lengths h
    (elements, 1): arrays (elements, points, 4), the four element DOFs being deflection and rotation at each
    end."""
    xi, h = np.broadcast_arrays(xi[None, :], h)
    n = np.stack([1 - 3 * xi**2 + 2 * xi**3, h * (xi - 2 * xi**2 + xi**3), 3 * xi**2 - 2 * xi**3,
                  h * (-(xi**2) + xi**3)], axis=-1)
    d2 = np.stack([-6 + 12 * xi, h * (-4 + 6 * xi), 6 - 12 * xi, h * (-2 + 6 * xi)], axis=-1)
    d2 /= h[..., None] ** 2
    return n, d2


def solve_cantilever(b: Build, pzt_modulus_scale: float = 1.0) -> Coefficients:
    """Static Euler-Bernoulli solution by Hermite elements: stiffness from the local rigidity x width (the
    edge bands at their own rigidity), piezo loads from the distributed plate moments, a Winkler foundation
    under the clamped length when the clamp is compliant, the rigid extension l_r l carrying the tip load."""
    full = section(b, pzt_modulus_scale)
    band = section(replace(b, modulus_bottom_Pa=b.modulus_bottom_Pa * b.edge_band_modulus_factor,
                           modulus_top_Pa=b.modulus_top_Pa * b.edge_band_modulus_factor),
                   pzt_modulus_scale, depoled=True)
    compliant_clamp = b.clamp_length_m > 0 and math.isfinite(b.clamp_foundation_N_per_m2)
    x_active = np.linspace(0.0, b.length_m, ACTIVE_ELEMENTS + 1)
    nodes = (np.r_[np.linspace(-b.clamp_length_m, 0.0, CLAMP_ELEMENTS + 1)[:-1], x_active] if compliant_clamp
             else x_active)
    n_dof = 2 * nodes.size
    h = np.diff(nodes)[:, None]                                   # (elements, 1)
    xg = nodes[:-1, None] + h * _GAUSS_X[None, :]                 # (elements, gauss)
    wg = h * _GAUSS_W[None, :]
    n, d2 = _hermite(_GAUSS_X, h)                     # (elements, gauss, 4)
    w = _width(b, xg)
    bands = 2.0 * b.edge_band_m
    rigidity = full.rigidity_N_m * (w - bands) + band.rigidity_N_m * bands
    ke = np.einsum("egi,eg,egj->eij", d2, rigidity * wg, d2)
    if compliant_clamp:
        in_clamp = (nodes[1:] <= 0.0)[:, None] * np.ones_like(wg)
        ke += np.einsum("egi,eg,egj->eij", n, b.clamp_foundation_N_per_m2 * wg * in_clamp, n)
    active_w = (w - bands) * wg
    fe = np.stack([np.einsum("egi,eg->ei", d2, full.moment_bottom_N_per_V * active_w),
                   np.einsum("egi,eg->ei", d2, full.moment_top_N_per_V * active_w)], axis=2)
    dof = 2 * np.arange(nodes.size - 1)[:, None] + np.arange(4)[None, :]   # (elements, 4)
    k = np.zeros((n_dof, n_dof))
    np.add.at(k, (dof[:, :, None], dof[:, None, :]), ke)
    loads = np.zeros((n_dof, 3))   # bottom plate 1 V, top plate 1 V, tip force 1 N
    np.add.at(loads, (dof[:, :, None], np.arange(2)[None, None, :]), fe)
    l_ext = b.length_ratio * b.length_m
    loads[-2, 2] = 1.0
    loads[-1, 2] = l_ext
    # a rigid clamp holds the root node (no deflection, no rotation); a compliant one holds nothing
    free = np.arange(n_dof) if compliant_clamp else np.arange(2, n_dof)
    u = np.zeros((n_dof, 3))
    u[free] = _solve_banded_spd(k[np.ix_(free, free)], loads[free])
    tip = u[-2] + l_ext * u[-1]
    return Coefficients(float(tip[0]), float(tip[1]), float(tip[2]))


def _solve_banded_spd(k: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve the symmetric positive definite beam system in banded storage (two-node elements with two DOFs
    per node couple DOFs at most 3 apart): a dense solve is slower and, under a threaded BLAS on a busy
    machine, far slower."""
    from scipy.linalg import solveh_banded

    u = 3
    ab = np.zeros((u + 1, k.shape[0]))
    for d in range(u + 1):
        ab[u - d, d:] = np.diagonal(k, d)
    return solveh_banded(ab, rhs)


def clamp_for_lengthening(b: Build, lengthening: float, clamp_length_m: float) -> Build:
    """The foundation stiffness under a clamped length that raises the free deflection by the fraction
    `lengthening` (a few % in the paper: "imperfect mechanical grounding ... effectively increasing tip
    displacement"), found by bisection in log stiffness. The free deflection falls monotonically as the
    foundation stiffens."""
    rigid = solve_cantilever(replace(b, clamp_length_m=0.0, clamp_foundation_N_per_m2=math.inf))
    target = rigid.free_bottom_m_per_V * (1.0 + lengthening)
    lo, hi = 1e6, 1e16   # N/m per m: soft (curls far into the clamp) to effectively rigid
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        trial = solve_cantilever(replace(b, clamp_length_m=clamp_length_m, clamp_foundation_N_per_m2=mid))
        if trial.free_bottom_m_per_V > target:
            lo = mid
        else:
            hi = mid
        if hi / lo < 1.0 + 1e-5:
            break
    return replace(b, clamp_length_m=clamp_length_m, clamp_foundation_N_per_m2=math.sqrt(lo * hi))
