"""The paper-reproduction table: every claim of the seed paper's text, evaluated by the model at run time.

Each claim gives the paper's statement, the model's computed figure, whether it is reproduced, its margin (a
signed relative number: > 0 holds, the size says how far a parameter could move before it flips) and, when not
reproduced, the reason. Nothing here is stored output: every number comes from the model when `table()` runs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hamr_bench.model.actuator import actuator_preset
from hamr_bench.model.designs import GEOMETRY, LITERAL_KAPPA_GEOMETRY, design_preset
from hamr_bench.model.powertrain import Powertrain
from hamr_bench.errors import ModelError
from hamr_bench.model.transmission import SliderCrankGeometry

WEIGHT_N = 10.6e-3                 # HAMR-V weight (paper)
WALK_FORCE_N = WEIGHT_N / 2        # half the weight while walking
STAND_FORCE_N = WEIGHT_N / 4       # a quarter while standing
SAGS_M = np.array([0.0, 1e-3, 2e-3, 3e-3])
ZERO_SAG_VOLTAGES_V = np.array([100.0, 150.0, 200.0, 250.0])
STATIC_TOLERANCE = 0.30            # issue 2: "within 30 %"
THIN_MARGIN = 0.05                 # below this a claim is flagged: one fabrication tolerance from flipping
# Claims the unpublished geometry was fitted to (geometry_search.py maximises their worst margin). Their
# "reproduced" says the geometry exists, not that the model predicted them; every other claim is a check.
FITTED_CLAIMS = frozenset({"zero_sag_biased", "zero_sag_unbiased", "sag_reaches", "sag_rises_d4",
                           "free_displacement_order", "static_sag_d4", "static_sag_d1"})


@dataclass(frozen=True)
class Claim:
    id: str
    claim: str
    paper: str
    model: str
    reproduced: bool
    margin: float
    reason: str = ""
    kind: str = "paper"          # "paper": a claim of the paper's text; "check": a robustness/decision check

    @property
    def fitted(self) -> bool:
        return self.id in FITTED_CLAIMS

    @property
    def note(self) -> str:
        notes = []
        if self.fitted:
            notes.append("geometry fitted to this claim")
        if self.reproduced and self.margin < THIN_MARGIN:
            notes.append(f"thin margin ({100 * self.margin:.1f} %)")
        return "; ".join(notes)

    def as_dict(self) -> dict:
        d = {"id": self.id, "claim": self.claim, "paper": self.paper, "model": self.model,
             "reproduced": bool(self.reproduced), "margin": float(round(self.margin, 4)),
             "fitted": self.fitted, "note": self.note, "kind": self.kind}
        if not self.reproduced:
            d["reason"] = self.reason
        return d


def powertrains(geometry: SliderCrankGeometry = GEOMETRY, kappa_unit: float | None = None) -> dict[int, Powertrain]:
    a = actuator_preset(2, "effective")
    kw = {} if kappa_unit is None else {"kappa_unit_N_m_per_rad": kappa_unit}
    return {d: Powertrain(a, design_preset(d, geometry=geometry, **kw)) for d in range(1, 6)}


def transmission_figures(pts: dict[int, Powertrain]) -> dict:
    """The raw model figures behind the transmission claims (used by the table and the geometry search)."""
    out = {}
    for d, p in pts.items():
        out[d] = dict(
            zero_sag_N=p.blocked_force_N(ZERO_SAG_VOLTAGES_V, 0.0),
            sag_sweep_N=p.blocked_force_N(250.0, SAGS_M),
            free_250_m=float(p.free_displacement_m(250.0)),
            static_sag_m=float(p.static_displacement_m(STAND_FORCE_N)),
        )
    return out


def transmission_margins(fig: dict) -> dict[str, float]:
    """Signed relative margins of the transmission claims (nan counts as failing)."""
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


def table() -> list[Claim]:
    claims: list[Claim] = []
    V = 250.0
    # --- actuator ---------------------------------------------------------------------------------------------
    acts = {n: actuator_preset(n, "effective") for n in (1, 2, 3)}
    ed = {n: float(a.energy_density_J_per_kg(V)) for n, a in acts.items()}
    en = {n: float(a.energy_J(V)) for n, a in acts.items()}
    fb = {n: float(a.blocked_force_N(V)) for n, a in acts.items()}
    dx = {n: float(a.free_displacement_m(V)) for n, a in acts.items()}
    m = (ed[2] - max(ed[1], ed[3])) / ed[2]
    claims.append(Claim(
        "actuator_energy_density", "2-layer actuator has the highest energy density (250 V, effective params)",
        "2x highest", "J/kg: " + ", ".join(f"{n}x {ed[n]:.4f}" for n in (1, 2, 3)), m > 0, m,
        "" if m > 0 else
        f"half-cycle energy F_b x delta does peak at 2x ({', '.join(f'{n}x {1e6 * en[n]:.2f} uJ' for n in (1, 2, 3))}), "
        "but the 1x actuator is lighter by the extra 30 um CF layer and the closed-form model gives it a higher "
        "density; the difference is within fabrication scatter"))
    m = (fb[3] - max(fb[1], fb[2])) / fb[3]
    claims.append(Claim("actuator_force_3x", "3-layer actuator has the largest blocked force", "3x largest",
                        "F_b: " + ", ".join(f"{n}x {1e3 * fb[n]:.1f} mN" for n in (1, 2, 3)), m > 0, m,
                        "3x is not the largest"))
    m = (dx[1] - max(dx[2], dx[3])) / dx[1]
    claims.append(Claim("actuator_displacement_1x", "1-layer actuator has the largest free displacement",
                        "1x largest", "delta: " + ", ".join(f"{n}x {1e6 * dx[n]:.1f} um" for n in (1, 2, 3)),
                        m > 0, m, "1x is not the largest"))
    lo = min(min(fb.values()) / 0.1 - 1, 1 - max(fb.values()) / 1.0)
    hi = 1 - max(dx.values()) / 1e-3
    m = min(lo, hi)
    claims.append(Claim("actuator_magnitudes", "blocked force in the 100s of mN, free displacement sub-mm (250 V)",
                        "100s of mN, sub-mm",
                        f"F_b {1e3 * min(fb.values()):.0f}-{1e3 * max(fb.values()):.0f} mN, delta "
                        f"{1e6 * min(dx.values()):.0f}-{1e6 * max(dx.values()):.0f} um", m > 0, m, "out of range"))

    # --- transmission -------------------------------------------------------------------------------------------
    pts = powertrains()
    fig = transmission_figures(pts)
    mg = transmission_margins(fig)
    claims.append(Claim(
        "zero_sag_biased", "designs 3, 4, 5 reach 5.3 mN at zero sag at 200 and 250 V", ">= 5.3 mN",
        "; ".join(f"d{d} {_mN(fig[d]['zero_sag_N'][2:])}" for d in (3, 4, 5)), mg["zero_sag_biased"] > 0,
        mg["zero_sag_biased"], "a biased design stays below 5.3 mN at 200 V"))
    claims.append(Claim(
        "zero_sag_unbiased", "designs 1, 2 stay below 5.3 mN at zero sag from 100 to 200 V", "< 5.3 mN",
        "; ".join(f"d{d} {_mN(fig[d]['zero_sag_N'][:3])}" for d in (1, 2)), mg["zero_sag_unbiased"] > 0,
        mg["zero_sag_unbiased"], "an unbiased design reaches 5.3 mN below 250 V"))
    claims.append(Claim(
        "sag_reaches", "at 250 V every design reaches 5.3 mN at some sag of 1, 2 or 3 mm", ">= 5.3 mN",
        "; ".join(f"d{d} max {_mN(_nanmax(fig[d]['sag_sweep_N'][1:]))}" for d in range(1, 6)),
        mg["sag_reaches"] > 0, mg["sag_reaches"], "a design never reaches 5.3 mN in the 1-3 mm sag sweep"))
    claims.append(Claim(
        "sag_rises_d4", "design 4: force rises with sag (0-3 mm, 250 V)", "rising",
        f"d4 {_mN(fig[4]['sag_sweep_N'])}", mg["sag_rises_d4"] > 0, mg["sag_rises_d4"],
        "force does not rise monotonically with sag"))
    s3 = fig[3]["sag_sweep_N"]
    m3 = float(-np.max(np.diff(s3)) / s3[0]) if np.all(np.isfinite(s3)) else -1.0
    claims.append(Claim(
        "sag_falls_d3", "design 3: force falls with sag (0-3 mm, 250 V)", "falling", f"d3 {_mN(s3)}",
        m3 > 0, m3,
        f"design 3 has no flexure stiffness, so the sign of dF/dsag at a fixed drive is set by the geometry, the "
        f"bias and the actuator stroke alone (k_ser scales F but not its slope's sign); on the geometry shared with "
        f"design 4 (whose force must rise) its 146 um bias differs by only 37 um, and it rises too "
        f"({100 * (s3[1] / s3[0] - 1):+.0f} % from 0 to 1 mm). No physically justified feature was found that makes "
        f"it fall while design 4 rises; not forced"))
    free = {d: fig[d]["free_250_m"] for d in range(1, 6)}
    ok = mg["free_order_max_d1"] > 0 and mg["free_order_min_d4"] > 0
    claims.append(Claim(
        "free_displacement_order", "free displacement at 250 V is highest for design 1, lowest for design 4",
        "d1 max, d4 min", "one-sided stroke: " + ", ".join(f"d{d} {1e3 * free[d]:.3f} mm" for d in range(1, 6)),
        ok, min(mg["free_order_max_d1"], mg["free_order_min_d4"]), "order differs"))
    for d, target, key in ((4, 0.5e-3, "static_d4"), (1, 2.0e-3, "static_d1")):
        s = fig[d]["static_sag_m"]
        claims.append(Claim(
            f"static_sag_d{d}", f"design {d} sags about {1e3 * target:g} mm under a quarter weight (2.65 mN), "
            "actuator off, within 30 %", f"{1e3 * target:g} mm",
            f"{1e3 * s:.3f} mm" if np.isfinite(s) else "no equilibrium (collapses)", mg[key] > 0, mg[key],
            "outside 30 %"))
    f4 = np.concatenate([fig[4]["zero_sag_N"], fig[4]["sag_sweep_N"]])
    f5 = np.concatenate([fig[5]["zero_sag_N"], fig[5]["sag_sweep_N"]])
    dev = float(np.max(np.abs(f5 / f4 - 1)))
    claims.append(Claim(
        "swing_negligible", "adding the swing DOF (design 5) changes the lift force by under 5 %", "< 5 %",
        f"max |F5/F4 - 1| = {100 * dev:.3f} % (swing coupling {pts[5].design.swing_coupling:g})",
        dev < 0.05, 1 - dev / 0.05, "coupling too strong"))
    # design intent of the 200 um bias: the biased neutral sits at the baseline's lowest foot position. Read with
    # the trapezoid drive's rest at V_drive = 0 (foot at its top), that is a drop of one peak-to-peak stroke.
    from dataclasses import replace as _replace
    a2 = pts[1].actuator
    d4_designed = Powertrain(a2, _replace(pts[4].design, bias_m=pts[4].design.bias_designed_m))
    g = pts[1].geometry
    from hamr_bench.model.transmission import foot_height_fab_m
    drop = float(foot_height_fab_m(g, pts[1].theta_neutral_rad) - foot_height_fab_m(g, d4_designed.theta_neutral_rad))
    p2p = float(pts[1].free_foot_height_m(V, 0.0) - pts[1].free_foot_height_m(V, V))
    m = STATIC_TOLERANCE - abs(drop / p2p - 1)
    claims.append(Claim(
        "bias_matches_stroke", "a 200 um bias drops the foot's neutral to the baseline's lowest position at 250 V "
        "(design intent; within 30 %)", "drop = baseline stroke (peak-to-peak)",
        f"drop {1e3 * drop:.3f} mm vs baseline peak-to-peak {1e3 * p2p:.3f} mm (one-sided {0.5e3 * p2p:.3f} mm)",
        m > 0, m, "the bias moves the foot by a different amount than the baseline's stroke"))
    # Robustness of the fitted transmission claims to a 1 % change of any one geometry parameter (fabrication
    # tolerance of PC-MEMS links is at least that): worst margin over the 12 perturbed geometries.
    worst, where = np.inf, ""
    base = {k: getattr(GEOMETRY, k) for k in ("crank_m", "coupler_m", "offset_m", "theta_fab_rad",
                                               "leg_length_m", "leg_angle0_rad")}
    for k, v in base.items():
        for f in (0.99, 1.01):
            kw = dict(base)
            kw[k] = v * f
            try:
                mm = transmission_margins(transmission_figures(powertrains(SliderCrankGeometry(**kw))))
            except ModelError:
                mm = {"closes": -1.0}
            key = min(mm, key=mm.get)
            if mm[key] < worst:
                worst, where = mm[key], f"{k} x{f:g} -> {key}"
    claims.append(Claim(
        "geometry_tolerance", "(robustness check, not a paper claim) the fitted transmission claims survive a 1 % "
        "change of any one geometry parameter", "-", f"worst fitted-claim margin {worst:+.3f} ({where})",
        worst > 0, worst, kind="check", reason=
        "the fitted claims are only jointly compatible in a knife-edge region of this single-DOF slider-crank "
        "model: a 1 % change of one link length flips one of them (usually the baseline's 2 mm static sag or the "
        "biased designs' 5.3 mN at 200 V)"))
    # kappa unit arbitration: the static sags under each reading, on the chosen geometry and on the best geometry
    # the search finds for the literal reading (designs.LITERAL_KAPPA_GEOMETRY).
    lit = powertrains(kappa_unit=1.0)
    s_lit = float(lit[4].static_displacement_m(STAND_FORCE_N))
    s_mm = fig[4]["static_sag_m"]
    alt = powertrains(LITERAL_KAPPA_GEOMETRY, kappa_unit=1.0)
    alt_fig = transmission_figures(alt)
    alt_margin = min(transmission_margins(alt_fig).values())
    chosen_decides = (abs(s_mm / 0.5e-3 - 1) < STATIC_TOLERANCE) and (abs(s_lit / 0.5e-3 - 1) > STATIC_TOLERANCE)
    decides = chosen_decides and alt_margin <= 0
    claims.append(Claim(
        "kappa_units", "the static sags (0.5 mm design 4, 2 mm design 1) decide Table III's kappa unit "
        "(printed N m/rad vs N mm/rad)", "N m/rad printed",
        f"chosen geometry: d4 {1e3 * s_mm:.3f} mm (N mm/rad) vs {1e3 * s_lit:.3f} mm (N m/rad); geometry refit "
        f"for N m/rad: d4 {1e3 * alt_fig[4]['static_sag_m']:.3f} mm, d1 {1e3 * alt_fig[1]['static_sag_m']:.3f} mm, "
        f"worst fitted-claim margin {alt_margin:+.3f}",
        decides, (-alt_margin if chosen_decides else -1.0), kind="check", reason=
        "on the chosen geometry only N mm/rad gives the 0.5 mm sag, but a geometry that parks joint 1 where the "
        "coupler barely rotates hides the 0.02 N m/rad kappa_1 and satisfies every fitted claim too; the static "
        "sag alone cannot decide. N mm/rad is kept on flexure physics: it puts kappa_1 at the pseudo-rigid-body "
        "value of a 25 um Kapton joint (3-5e-5 N m/rad) instead of 500x above it (docs/model.md)"))
    return claims


def summary(claims: list[Claim]) -> str:
    paper = [c for c in claims if c.kind == "paper"]
    checks = [c for c in claims if c.kind != "paper"]
    return (f"{sum(c.reproduced for c in paper)} of {len(paper)} paper claims reproduced; "
            f"{sum(c.reproduced for c in checks)} of {len(checks)} checks pass.")


def as_markdown(claims: list[Claim]) -> str:
    lines = ["# Paper reproduction", "",
             "Generated by `python3 -m hamr_bench paper --markdown` (computed by the model at run time; do not edit).",
             "Seed paper: Ozcan, Baisch & Wood, ICRA 2014. Margin: signed relative distance from the claim's "
             "threshold (> 0 holds).", "",
             f"Claims marked *fitted* were used to choose the unpublished transmission geometry "
             f"(`hamr_bench/model/geometry_search.py`); the others are checks. *thin* = margin under "
             f"{100 * THIN_MARGIN:.0f} %.", "",
             "| id | claim | paper | model | reproduced | margin | note |", "|---|---|---|---|---|---|---|"]
    esc = lambda t: str(t).replace("|", "\\|")
    for c in claims:
        rep = "yes" if c.reproduced else "**not reproduced**"
        cells = (c.id, c.claim, c.paper, c.model, rep, f"{c.margin:+.3f}", c.note)
        lines.append("| " + " | ".join(esc(x) for x in cells) + " |")
    missing = [c for c in claims if not c.reproduced]
    if missing:
        lines += ["", "## Not reproduced: reasons", ""]
        lines += [f"- **{c.id}**: {c.reason}" for c in missing]
    lines += ["", summary(claims), ""]
    return "\n".join(lines)
