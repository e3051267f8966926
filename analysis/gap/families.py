"""The candidate effects as FAMILIES: each fits its physical effect in a range of forms (shape parameters, fitted)
with ONE strength in a physical unit. The forms are deliberately not the simulated bench's (docs/gap.md lists the
pairs side by side):

| candidate | family (shape parameters) | strength |
|---|---|---|
| hysteresis | per plate, a weighted sum of plays on the unipolar range (threshold density ~ r^gamma), read |
|   | back through its first rise (tip share c mixes in the unmapped sum) | largest loop gap / span, full drive |
| creep | power-law (Nutting) superposition of every drive increment, exponent n of either sign; log law at 0; |
|   | curved (q) and skewed (r) in log time | growth per decade, 50 - 400 ms |
| field_dependent_d31 | d31 gain 1 + a E^p / (E^p + c^p), knee c, steepness p, either sign | d31(250 V)/d31(100 V) - 1 |
| base_compliance | series spring x = C F_ref (F / F_ref)^beta, pull side rho x | blocked-force loss, 2-layer, 250 V |
| sensor_compliance | the same spring in the sensor | secant compliance at 50 mN, m/N |
| width_loss | constant kerf per cut edge on the tapered plate (one way) | fraction of the mean width lost |
| pzt_thickness, pzt_modulus, cf_thickness | the parameter scaled | fractional change |
| grounding_lengthening | active length scaled, the rigid extension kept (one way) | fractional change |
| sensor_drift | per run (per specimen on one clock) a penalised cubic spline + warm-up t / (t + tau) | N/sqrt(s) |
| bias_error | coupler lengthening offset (leg) | m |
| stage_backlash | play on the stage-target sequence | m (full width) |

A strength of 0 is the nominal model exactly. Fabrication shifts (`TOLERANCE`) are effects only BEYOND the
tolerance band of their parameter: within it they belong to the specimens' scatter (`tolerances.py`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from analysis.gap.tolerances import BAND_SIGMAS, TOLERANCE
from hamr_bench.errors import ConfigError


@dataclass(frozen=True)
class Shape:
    """A shape parameter: fitted within [lo, hi], softly held near `default` (a Gaussian prior of `prior_sd`)
    so that it stays defined when the strength is small."""

    default: float
    lo: float
    hi: float
    prior_sd: float


@dataclass(frozen=True)
class Family:
    name: str
    unit: str
    bounds: tuple[float, float]
    form: str
    kind: str                      # drive | contact | params | baseline | design | stage
    shapes: dict[str, Shape] = field(default_factory=dict)
    tolerance: float = 0.0         # fabrication shifts: the parameter's 1-sigma tolerance (fraction)
    scale: float = 1.0             # typical strength (finite-difference and solver scale)
    # Shape settings the coarse strength grid tries besides the defaults: at strength 0 a shape has no gradient,
    # so a form far from the default is reached only from a start near it.
    grid_shapes: tuple[dict[str, float], ...] = ()


def _one_sided(tolerance: float, hi: float) -> tuple[float, float]:
    """Bounds of a mechanism that acts one way only: a laser kerf only takes width away, and imperfect grounding
    only moves the clamp line outward (a longer active length). The other side reaches just to the tolerance band,
    where the specimens' scatter already is, so that an opposite shift beyond tolerance (a wider plate, a shorter
    actuator) is left to the candidates that can make it, not read as this mechanism run backwards."""
    return (-BAND_SIGMAS * tolerance, hi)


FAMILIES: dict[str, Family] = {f.name: f for f in (
    Family("hysteresis", "largest rise/fall gap of the net drive / span, full drive cycle (250 V)", (0.0, 0.3),
           "plays on each plate's unipolar range (threshold density ~ r^gamma), tips on the first rise", "drive",
           {"density_exponent": Shape(0.0, -2.0, 2.0, 1.0), "tip_share": Shape(0.0, 0.0, 1.0, 0.5)},
           scale=0.05, grid_shapes=({"density_exponent": -1.0},)),
    # The exponent's bounds reach a single Kelvin-Voigt element anywhere from ~40 ms (growth front-loaded: n -> -2)
    # to far beyond the dwell (growth per decade ~ age: n -> 1); above 1 a creep would outgrow a viscous flow. The
    # skew (a cubic in log time) lets the bump carry a shoulder: a second band of time constants decades away.
    Family("creep", "growth from 50 to 400 ms after a step, per decade (fraction of the step)", (0.0, 0.12),
           "superposition of drive increments, power law in age (log law at n = 0), curved in log time by q and skewed"
           " by r", "drive",
           {"exponent": Shape(0.0, -2.0, 1.0, 0.3), "curvature": Shape(0.0, -2.0, 0.3, 0.5),
            "skew": Shape(0.0, -0.8, 0.8, 0.3)}, scale=0.01),
    Family("field_dependent_d31", "d31 at 250 V / d31 at 100 V - 1 (nominal plate)", (-0.6, 1.5),
           "d31 gain 1 + a h(E), h a knee E^p / (E^p + c^p) in field", "drive",
           {"log10_knee_V_per_um": Shape(0.5, -0.7, 1.0, 0.6), "steepness": Shape(1.5, 0.5, 8.0, 2.0)},
           scale=0.2),
    Family("base_compliance", "blocked-force loss of the 2-layer actuator at 250 V", (0.0, 0.8),
           "series spring at the actuator base, x = C F_ref (F/F_ref)^beta, pull side rho x", "contact",
           {"exponent": Shape(1.0, 0.3, 1.5, 0.4), "pull_ratio": Shape(1.0, 0.2, 5.0, 1.5)}, scale=0.1),
    Family("sensor_compliance", "m/N (secant at 50 mN)", (0.0, 2e-3),
           "series spring in the force sensor, x = C F_ref (F/F_ref)^beta, pull side rho x", "contact",
           {"exponent": Shape(1.0, 0.3, 1.5, 0.4), "pull_ratio": Shape(1.0, 0.2, 5.0, 1.5)}, scale=5e-5),
    Family("width_loss", "fraction of the nominal mean width lost", _one_sided(TOLERANCE["width"], 0.5),
           "constant kerf per cut edge on the tapered plate", "params", tolerance=TOLERANCE["width"], scale=0.1),
    Family("pzt_thickness", "fractional change of the PZT plate thickness", (-0.3, 0.6),
           "PZT plate thickness scaled", "params", tolerance=TOLERANCE["pzt_thickness"], scale=0.1),
    Family("pzt_modulus", "fractional change of the PZT modulus", (-0.6, 0.6),
           "effective PZT modulus scaled", "params", tolerance=TOLERANCE["pzt_modulus"], scale=0.1),
    Family("grounding_lengthening", "fractional change of the active length", _one_sided(TOLERANCE["length"], 0.5),
           "active length scaled, the rigid extension kept (clamp line moved)", "params",
           tolerance=TOLERANCE["length"], scale=0.05),
    Family("cf_thickness", "fractional change of the carbon-fibre layer thickness", (-0.7, 1.0),
           "carbon-fibre layer thickness scaled", "params", tolerance=TOLERANCE["cf_thickness"], scale=0.2),
    Family("sensor_drift", "N/sqrt(s) (baseline wander rate)", (0.0, math.inf),
           "force baseline per run (per specimen on a shared clock): penalised cubic spline + warm-up t/(t + tau)",
           "baseline",
           {"warmup_log10_tau_s": Shape(1.5, 0.5, 3.0, 1.0)}, scale=2e-5),
    Family("bias_error", "m", (-150e-6, 150e-6), "coupler lengthening offset", "design", scale=20e-6),
    Family("stage_backlash", "m", (0.0, 60e-6), "play on the stage-target sequence", "stage", scale=5e-6),
)}
CANDIDATES = tuple(FAMILIES)
FABRICATION = tuple(n for n, f in FAMILIES.items() if f.kind == "params")


def family(name: str) -> Family:
    return FAMILIES[name]


def check_names(names: list[str] | tuple[str, ...]) -> list[str]:
    """Candidate names as given to `--effects`, checked (one line naming the unknown one)."""
    out = []
    for n in names:
        n = n.strip()
        if not n:
            continue
        if n not in FAMILIES:
            raise ConfigError(f"--effects: unknown candidate effect {n!r} (known: {', '.join(FAMILIES)})")
        out.append(n)
    return out
