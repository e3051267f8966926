"""The three readings of Table III's kappa units compared on physics and robustness (issue 17 item 1).

Per reading (designs.KAPPA_READINGS) and its searched geometry (designs.GEOMETRIES): the worst fitted-claim margin,
the worst after a 1 % change of any one geometric parameter (each up and down), a Monte-Carlo of joint +-1 %
changes, and every Table III kappa against the pseudo-rigid-body band of a Kapton strip of that design's
thickness (flexures.prb_band_N_m_per_rad). `python3 -m hamr_bench paper --readings` prints the markdown tables that
docs/model.md carries.
"""

from __future__ import annotations

from dataclasses import dataclass
from collections.abc import Callable

from hamr_bench.model.designs import _TABLE, DEFAULT_KAPPA_UNITS, GEOMETRIES, KAPPA_READINGS
from hamr_bench.model.flexures import prb_band_N_m_per_rad
from hamr_bench.model.robustness import (JointMonteCarlo, OneAtATime, joint_monte_carlo, one_at_a_time,
                                         worst_margin)

TABLE_III_BOUND = 1e-6        # the printed "< 1e-6" entries: an upper bound in the column's unit


@dataclass(frozen=True)
class KappaRow:
    design: int
    joint: int
    printed: float                 # Table III number (0 for "< 1e-6")
    kappa_N_m_per_rad: float       # under the reading (the bound for "< 1e-6")
    bound: bool                    # True: an upper bound
    prb_lo: float
    prb_hi: float

    @property
    def ratio(self) -> tuple[float, float]:
        """kappa over the PRB band: (kappa / highest PRB, kappa / lowest PRB)."""
        return self.kappa_N_m_per_rad / self.prb_hi, self.kappa_N_m_per_rad / self.prb_lo


def kappa_rows(kappa_units: str) -> list[KappaRow]:
    rows = []
    for design in (1, 2, 3, 4):
        t = _TABLE[design]
        lo, hi = prb_band_N_m_per_rad(t["kapton_thickness_m"])
        for j, (value, factor) in enumerate(zip(t["kappa"], KAPPA_READINGS[kappa_units], strict=True), start=1):
            bound = value == 0.0
            rows.append(KappaRow(design, j, value, (TABLE_III_BOUND if bound else value) * factor, bound, lo, hi))
    return rows


def prb_ratio_span(rows: list[KappaRow]) -> tuple[float, float]:
    """Smallest and largest kappa/PRB ratio over the entries Table III gives a value for."""
    vals = [r.ratio for r in rows if not r.bound]
    return min(v[0] for v in vals), max(v[1] for v in vals)


@dataclass(frozen=True)
class ReadingReport:
    kappa_units: str
    worst: float
    worst_claim: str
    oat: OneAtATime
    joint: JointMonteCarlo
    rows: list[KappaRow]

    @property
    def prb_span(self) -> tuple[float, float]:
        return prb_ratio_span(self.rows)


_CACHE: dict[tuple[int, int], dict[str, ReadingReport]] = {}


def compare_readings(joint_samples: int = 100, seed: int = 0,
                     progress: Callable[[str], None] | None = None) -> dict[str, ReadingReport]:
    """Every reading's report (memoised per process: the model is pure and the draws are seeded)."""
    if (joint_samples, seed) not in _CACHE:
        _CACHE[joint_samples, seed] = _compare(joint_samples, seed, progress)
    return _CACHE[joint_samples, seed]


def _compare(joint_samples: int, seed: int, progress: Callable[[str], None] | None) -> dict[str, ReadingReport]:
    out = {}
    for ku in KAPPA_READINGS:
        if progress:
            progress(f"kappa reading {ku}")
        g = GEOMETRIES[ku]
        worst, claim = worst_margin(g, ku)
        out[ku] = ReadingReport(ku, worst, claim, one_at_a_time(g, ku), joint_monte_carlo(g, ku, joint_samples,
                                                                                           seed=seed),
                                kappa_rows(ku))
    return out


def _x(v: float) -> str:
    return f"{v:.2g}x" if v < 10 else f"{v:.0f}x"


def readings_markdown(reports: dict[str, ReadingReport]) -> str:
    """The comparison as two markdown tables (robustness, then every kappa against its PRB band)."""
    lines = ["| reading | kappa_1, kappa_2, kappa_3 x | worst fitted margin | worst after any 1 % change | "
             "joint +-1 % (n, 5th pct, holding) | fitted kappa / PRB | geometry r, l, e, theta_fab, L, alpha_0 |",
             "|---|---|---|---|---|---|---|"]
    for ku, r in reports.items():
        g = GEOMETRIES[ku]
        lo, hi = r.prb_span
        default = " (default)" if ku == DEFAULT_KAPPA_UNITS else ""
        lines.append(
            f"| {ku}{default} | {', '.join(f'{f:g}' for f in KAPPA_READINGS[ku])} | {r.worst:+.3f} ({r.worst_claim}) "
            f"| {r.oat.worst:+.3f} ({r.oat.where}) | {r.joint.samples}, {r.joint.p05:+.3f}, "
            f"{100 * r.joint.fraction_holding:.0f} % | {_x(lo)}-{_x(hi)} | "
            f"{1e3 * g.crank_m:.3f}, {1e3 * g.coupler_m:.3f}, {1e3 * g.offset_m:.3f} mm, {g.theta_fab_rad:.3f} rad, "
            f"{1e3 * g.leg_length_m:.2f} mm, {g.leg_angle0_rad:.3f} rad |")
    lines += ["", "| design | joint | Table III | PRB band (N m/rad) | "
              + " | ".join(f"{ku}: N m/rad (x PRB)" for ku in reports) + " |",
              "|---|---|---|---|" + "---|" * len(reports)]
    per = {ku: r.rows for ku, r in reports.items()}
    first = next(iter(per.values()))
    for i, row in enumerate(first):
        printed = "< 1e-6" if row.bound else f"{row.printed:.3g}"
        cells = []
        for rows in per.values():
            cell = rows[i]
            a, b = cell.ratio
            cells.append(f"< {cell.kappa_N_m_per_rad:.2g} (< {_x(b)})" if cell.bound
                         else f"{cell.kappa_N_m_per_rad:.2g} ({_x(a)}-{_x(b)})")
        lines.append(f"| {row.design} | {row.joint} | {printed} | {row.prb_lo:.2g}-{row.prb_hi:.2g} | "
                     + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"

