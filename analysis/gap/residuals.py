"""Where the gap lies: the nominal model's residual mapped by protocol, condition, sweep direction and phase within
a cycle, against the noise floor measured from repetitions (the cycle-to-cycle pure error), with a lack-of-fit F
test per region and the regions whose gap exceeds noise ranked by size."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from analysis.gap.problem import Problem
from analysis.gap.results import LackOfFit, Region

ALPHA = 0.01


def condition_label(problem: Problem, i: int) -> str:
    r = problem.rows[i]
    run = problem.data.runs[r.run]
    who = f"design {run.design}" if run.fixture == "leg" else f"{run.layers}-layer actuator"
    parts = [who]
    if r.mode:
        parts.append(r.mode)
    if r.protocol != "static":
        parts.append(f"{r.voltage_V:.0f} V")
    if r.protocol in ("sag-sweep", "static") or r.sag_m:
        parts.append(f"sag {r.sag_m * 1e3:.2f} mm")
    if r.protocol in ("blocked-force", "static"):
        parts.append(r.direction)
    return ", ".join(parts)


def lack_of_fit_p(z: np.ndarray, pure_dof: int, n_params: int = 0) -> float:
    n = z.size - n_params
    if n <= 0:
        return 1.0
    f = float(np.sum(z ** 2)) / n
    return float(stats.f.sf(f, n, max(pure_dof, 1)))


def regions(problem: Problem, z: np.ndarray, by_phase: bool = False) -> list[Region]:
    """One region per (protocol, condition[, phase]); sorted: significant first, then by gap over noise."""
    keys: dict[tuple, list[int]] = {}
    for i, r in enumerate(problem.rows):
        key = (r.protocol, condition_label(problem, i), r.quantity) + ((r.phase,) if by_phase else ())
        keys.setdefault(key, []).append(i)
    out = []
    for key, members in keys.items():
        idx = np.array(members)
        resid = z[idx] * problem.sigma[idx]
        out.append(Region(protocol=key[0], condition=key[1] + (f", {key[3]}" if by_phase else ""), quantity=key[2],
                          rows=idx, rms_gap=float(np.sqrt(np.mean(resid ** 2))),
                          noise_floor=float(np.sqrt(np.mean(problem.sigma[idx] ** 2))),
                          p_value=lack_of_fit_p(z[idx], problem.pure_dof),
                          z_rms=float(np.sqrt(np.mean(z[idx] ** 2)))))
    out.sort(key=lambda g: (g.p_value >= ALPHA, -g.z_rms))
    return out


def phase_map(problem: Problem, z: np.ndarray) -> dict[str, dict[str, float]]:
    """RMS z by protocol x phase x direction (the residual map's compact form)."""
    out: dict[str, dict[str, float]] = {}
    for i, r in enumerate(problem.rows):
        out.setdefault(r.protocol, {}).setdefault(f"{r.phase}/{r.direction}", []).append(z[i])  # type: ignore
    return {p: {k: float(np.sqrt(np.mean(np.square(v)))) for k, v in d.items()} for p, d in out.items()}


def global_test(problem: Problem, z: np.ndarray, n_params: int) -> LackOfFit:
    return LackOfFit(chi2=float(np.sum(z ** 2)), n_rows=int(z.size), n_params=int(n_params),
                     pure_error_dof=int(problem.pure_dof), p_value=lack_of_fit_p(z, problem.pure_dof, n_params),
                     z_rms=float(math.sqrt(np.mean(z ** 2))))
