"""The seed paper's claims, each evaluated by the model for one choice of the unpublished quantities.

`evaluate(Unpublished())` gives every claim's signed margin (> 0 holds; the size says how far it is from flipping)
and the model's figures as text. reproduction.py evaluates it over the Monte-Carlo bands and builds the table.
Nothing here is stored output: every number comes from the model when it runs.

Each claim has a kind:
- fitted: the unpublished geometry was chosen to satisfy it (geometry_search.py); "reproduced" says a geometry
  exists, not that the model predicted it;
- structural: follows from the model's structure or from an input, whatever the fit (more carbon fibre -> more
  force and less stroke for any positive parameters; magnitudes of Table I's own fitted values; the assumed swing
  coupling);
- independent: nothing was fitted to it; a prediction.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from collections.abc import Callable

import numpy as np

from hamr_bench.model.actuator import actuator_preset
from hamr_bench.model.designs import DEFAULT_KAPPA_UNITS, design_preset
from hamr_bench.model.powertrain import Powertrain
from hamr_bench.model.transmission import SliderCrankGeometry, foot_height_fab_m
from hamr_bench.model.unpublished import Unpublished

WEIGHT_N = 10.6e-3                 # HAMR-V weight (paper)
WALK_FORCE_N = WEIGHT_N / 2        # half the weight while walking
STAND_FORCE_N = WEIGHT_N / 4       # a quarter while standing
SAGS_M = np.array([0.0, 1e-3, 2e-3, 3e-3])
ZERO_SAG_VOLTAGES_V = np.array([100.0, 150.0, 200.0, 250.0])
STATIC_TOLERANCE = 0.30            # "about 0.5 mm / 2 mm": within 30 %
DESIGNED_BIAS_M = 200e-6
V_MAX = 250.0

FITTED, STRUCTURAL, INDEPENDENT, CHECK = "fitted", "structural", "independent", "check"


@dataclass(frozen=True)
class Spec:
    id: str
    claim: str
    paper: str
    kind: str


SPECS: dict[str, Spec] = {s.id: s for s in (
    Spec("actuator_energy_density", "2-layer actuator has the highest energy density (250 V, effective params)",
         "2x highest", INDEPENDENT),
    Spec("actuator_force_3x", "3-layer actuator has the largest blocked force", "3x largest", STRUCTURAL),
    Spec("actuator_displacement_1x", "1-layer actuator has the largest free displacement", "1x largest", STRUCTURAL),
    Spec("actuator_magnitudes", "blocked force in the 100s of mN, free displacement sub-mm (250 V)",
         "100s of mN, sub-mm", STRUCTURAL),
    Spec("bias_equals_actuator_stroke", "the 200 um bias matches the actuator's deflection at 250 V (2-layer, "
         "peak-to-peak free deflection; within 30 %)", "200 um", INDEPENDENT),
    Spec("zero_sag_biased", "designs 3, 4, 5 reach 5.3 mN at zero sag at 200 and 250 V", ">= 5.3 mN", FITTED),
    Spec("zero_sag_unbiased", "designs 1, 2 stay below 5.3 mN at zero sag from 100 to 200 V", "< 5.3 mN", FITTED),
    Spec("sag_reaches", "at 250 V every design reaches 5.3 mN at some sag of 1, 2 or 3 mm", ">= 5.3 mN", FITTED),
    Spec("sag_rises_d4", "design 4: force rises with sag (0-3 mm, 250 V)", "rising", FITTED),
    Spec("sag_falls_d3", "design 3: force falls with sag (0-3 mm, 250 V)", "falling", INDEPENDENT),
    Spec("free_displacement_order", "free displacement at 250 V is highest for design 1, lowest for design 4",
         "d1 max, d4 min", FITTED),
    Spec("static_sag_d4", "design 4 sags about 0.5 mm under a quarter weight (2.65 mN), actuator off, within 30 %",
         "0.5 mm", FITTED),
    Spec("static_sag_d1", "design 1 sags about 2 mm under a quarter weight (2.65 mN), actuator off, within 30 %",
         "2 mm", FITTED),
    Spec("swing_negligible", "adding the swing DOF (design 5) changes the lift force by under 5 %", "< 5 %",
         STRUCTURAL),
    Spec("bias_matches_stroke", "a 200 um bias drops the foot's neutral to the baseline's lowest position at 250 V "
         "(design intent; within 30 %)", "drop = baseline stroke (peak-to-peak)", INDEPENDENT),
)}
FITTED_CLAIMS = frozenset(i for i, s in SPECS.items() if s.kind == FITTED)


@dataclass(frozen=True)
class Outcome:
    margin: float
    model: str


Reading = Callable[[Powertrain, np.ndarray, np.ndarray], np.ndarray]


# --- the transmission figures and margins the geometry search maximises --------------------------------------
def powertrains(geometry: SliderCrankGeometry | None = None, kappa_units: str = DEFAULT_KAPPA_UNITS,
                **design_changes) -> dict[int, Powertrain]:
    """Designs 1..5 on the 2-layer effective actuator under a kappa reading (its geometry unless given)."""
    a = actuator_preset(2, "effective")
    return {d: Powertrain(a, design_preset(d, kappa_units, geometry, **design_changes)) for d in range(1, 6)}


def _blocked(p: Powertrain, v: np.ndarray, s: np.ndarray) -> np.ndarray:
    return p.blocked_force_N(v, s)


def transmission_figures(pts: dict[int, Powertrain], reading: Reading = _blocked) -> dict:
    """The raw model figures behind the transmission claims; `reading` turns a powertrain, voltages and sags into
    what the sensor reads (frictionless blocked force unless given)."""
    out = {}
    for d, p in pts.items():
        out[d] = dict(
            zero_sag_N=reading(p, ZERO_SAG_VOLTAGES_V, np.zeros(1)),
            sag_sweep_N=reading(p, np.array(V_MAX), SAGS_M),
            free_250_m=float(p.free_displacement_m(V_MAX)),
            static_sag_m=float(p.static_displacement_m(STAND_FORCE_N)),
        )
    return out


def transmission_margins(fig: dict) -> dict[str, float]:
    """Signed relative margins of the fitted transmission claims (nan counts as failing, -1)."""
    m = {}
    m["zero_sag_biased"] = min(fig[d]["zero_sag_N"][2] for d in (3, 4, 5)) / WALK_FORCE_N - 1
    m["zero_sag_unbiased"] = 1 - max(fig[d]["zero_sag_N"][:3].max() for d in (1, 2)) / WALK_FORCE_N
    m["sag_reaches"] = min(_nanmax(fig[d]["sag_sweep_N"][1:]) for d in range(1, 6)) / WALK_FORCE_N - 1
    s4 = fig[4]["sag_sweep_N"]
    m["sag_rises_d4"] = float(np.min(np.diff(s4)) / s4[0])
    free = {d: fig[d]["free_250_m"] for d in range(1, 5)}
    m["free_order_max_d1"] = (free[1] - max(free[2], free[3], free[4])) / free[1]
    m["free_order_min_d4"] = (min(free[1], free[2], free[3]) - free[4]) / free[4]
    m["static_d4"] = STATIC_TOLERANCE - abs(fig[4]["static_sag_m"] / 0.5e-3 - 1)
    m["static_d1"] = STATIC_TOLERANCE - abs(fig[1]["static_sag_m"] / 2.0e-3 - 1)
    return {k: (float(v) if np.isfinite(v) else -1.0) for k, v in m.items()}


def _nanmax(x) -> float:
    x = np.asarray(x, dtype=float)
    return float(np.max(x[np.isfinite(x)])) if np.any(np.isfinite(x)) else float("nan")


def _mN(x) -> str:
    return ", ".join(f"{1e3 * v:.2f}" for v in np.atleast_1d(x)) + " mN"


def _finite(m: float) -> float:
    return float(m) if np.isfinite(m) else -1.0


# --- evaluation ------------------------------------------------------------------------------------------------
def evaluate(u: Unpublished) -> dict[str, Outcome]:
    """Every claim's margin and model figures for one choice of the unpublished quantities."""
    out = actuator_outcomes(u)
    if u.unbuildable:
        out.update({i: Outcome(-1.0, f"linkage cannot be assembled: {u.unbuildable}") for i, s in SPECS.items()
                    if i not in out})
        return out
    out.update(transmission_outcomes(u))
    return out


def actuator_outcomes(u: Unpublished) -> dict[str, Outcome]:
    acts = {n: u.actuator(n) for n in (1, 2, 3)}
    ed = {n: float(a.energy_density_J_per_kg(V_MAX)) for n, a in acts.items()}
    fb = {n: float(a.blocked_force_N(V_MAX)) for n, a in acts.items()}
    dx = {n: float(a.free_displacement_m(V_MAX)) for n, a in acts.items()}
    en = {n: float(a.energy_J(V_MAX)) for n, a in acts.items()}
    out = {
        "actuator_energy_density": Outcome(
            (ed[2] - max(ed[1], ed[3])) / ed[2],
            "J/kg: " + ", ".join(f"{n}x {ed[n]:.4f}" for n in (1, 2, 3)) + "; energy F_b delta: "
            + ", ".join(f"{n}x {1e6 * en[n]:.2f} uJ" for n in (1, 2, 3))),
        "actuator_force_3x": Outcome((fb[3] - max(fb[1], fb[2])) / fb[3],
                                     "F_b: " + ", ".join(f"{n}x {1e3 * fb[n]:.1f} mN" for n in (1, 2, 3))),
        "actuator_displacement_1x": Outcome((dx[1] - max(dx[2], dx[3])) / dx[1],
                                            "delta: " + ", ".join(f"{n}x {1e6 * dx[n]:.1f} um" for n in (1, 2, 3))),
    }
    lo = min(min(fb.values()) / 0.1 - 1, 1 - max(fb.values()) / 1.0)
    out["actuator_magnitudes"] = Outcome(
        min(lo, 1 - max(dx.values()) / 1e-3),
        f"F_b {1e3 * min(fb.values()):.0f}-{1e3 * max(fb.values()):.0f} mN, delta "
        f"{1e6 * min(dx.values()):.0f}-{1e6 * max(dx.values()):.0f} um")
    p2p = 2 * dx[2]
    out["bias_equals_actuator_stroke"] = Outcome(
        STATIC_TOLERANCE - abs(DESIGNED_BIAS_M / p2p - 1),
        f"2-layer peak-to-peak free deflection {1e6 * p2p:.0f} um (one-sided {1e6 * dx[2]:.0f} um) vs bias "
        f"{1e6 * DESIGNED_BIAS_M:.0f} um")
    return out


def transmission_outcomes(u: Unpublished) -> dict[str, Outcome]:
    pts = u.powertrains
    fig = transmission_figures(pts, u.reading_N)
    mg = transmission_margins(fig)
    out = {
        "zero_sag_biased": Outcome(mg["zero_sag_biased"], "; ".join(
            f"d{d} {_mN(fig[d]['zero_sag_N'][2:])}" for d in (3, 4, 5))),
        "zero_sag_unbiased": Outcome(mg["zero_sag_unbiased"], "; ".join(
            f"d{d} {_mN(fig[d]['zero_sag_N'][:3])}" for d in (1, 2))),
        "sag_reaches": Outcome(mg["sag_reaches"], "; ".join(
            f"d{d} max {_mN(_nanmax(fig[d]['sag_sweep_N'][1:]))}" for d in range(1, 6))),
        "sag_rises_d4": Outcome(mg["sag_rises_d4"], f"d4 {_mN(fig[4]['sag_sweep_N'])}"),
    }
    s3 = fig[3]["sag_sweep_N"]
    m3 = float(-np.max(np.diff(s3)) / s3[0]) if np.all(np.isfinite(s3)) else -1.0
    out["sag_falls_d3"] = Outcome(m3, f"d3 {_mN(s3)}")
    free = {d: fig[d]["free_250_m"] for d in range(1, 6)}
    out["free_displacement_order"] = Outcome(
        min(mg["free_order_max_d1"], mg["free_order_min_d4"]),
        "one-sided stroke: " + ", ".join(f"d{d} {1e3 * free[d]:.3f} mm" for d in range(1, 6)))
    for d, key in ((4, "static_d4"), (1, "static_d1")):
        s = fig[d]["static_sag_m"]
        out[f"static_sag_d{d}"] = Outcome(mg[key], f"{1e3 * s:.3f} mm" if np.isfinite(s) else
                                          "no equilibrium (collapses)")
    f4 = np.concatenate([fig[4]["zero_sag_N"], fig[4]["sag_sweep_N"]])
    f5 = np.concatenate([fig[5]["zero_sag_N"], fig[5]["sag_sweep_N"]])
    dev = float(np.max(np.abs(f5 / f4 - 1)))
    out["swing_negligible"] = Outcome(_finite(1 - dev / 0.05),
                                      f"max |F5/F4 - 1| = {100 * dev:.3f} % (swing coupling "
                                      f"{pts[5].design.swing_coupling:g})")
    out["bias_matches_stroke"] = bias_drop_outcome(pts)
    return out


def bias_drop_outcome(pts: dict[int, Powertrain]) -> Outcome:
    """Design intent of the 200 um bias: the biased neutral sits at the baseline's lowest foot position. Read with
    the trapezoid drive's rest at V_drive = 0 (foot at its top), that is a drop of one peak-to-peak stroke."""
    base = pts[1]
    designed = Powertrain(base.actuator, replace(pts[4].design, bias_m=pts[4].design.bias_designed_m))
    g = base.geometry
    drop = float(foot_height_fab_m(g, base.theta_neutral_rad) - foot_height_fab_m(g, designed.theta_neutral_rad))
    p2p = float(base.free_foot_height_m(V_MAX, 0.0) - base.free_foot_height_m(V_MAX, V_MAX))
    return Outcome(_finite(STATIC_TOLERANCE - abs(drop / p2p - 1)),
                   f"drop {1e3 * drop:.3f} mm vs baseline peak-to-peak {1e3 * p2p:.3f} mm (one-sided "
                   f"{0.5e3 * p2p:.3f} mm)")
