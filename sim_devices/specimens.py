"""Specimen-to-specimen scatter: the parameters one built actuator and transmission really have, drawn from a seed
within fabrication tolerances around the presets (Table I effective values, Table III fits).

Each drawn parameter is the preset x (1 + sigma z) (or + sigma z for the bias), z a standard normal truncated at
+-2.5: a tolerance quoted as +-T is taken as 2 sigma (T = 2 sigma). The sources of each tolerance are in
docs/model.md ("The simulated bench"). A bench without a specimen seed uses the presets exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

TRUNCATE_SIGMA = 2.5


@dataclass(frozen=True)
class Tolerance:
    """One parameter's scatter: relative (fraction of the preset) or absolute (in the parameter's unit)."""

    sigma: float
    relative: bool = True


# ActuatorParams field -> tolerance (1 sigma)
ACTUATOR_TOLERANCES: dict[str, Tolerance] = {
    "pzt_thickness_m": Tolerance(0.05),       # plates +-10 %: the paper measured "often thicker" than 127 um
    "cf_thickness_m": Tolerance(0.05),        # cured prepreg +-10 %
    "length_m": Tolerance(0.01),              # laser cut and clamp line +-2 %
    "width_nom_m": Tolerance(0.015),          # laser kerf +-3 % of the mean width
    "d31_m_per_V": Tolerance(0.05),           # soft PZT spec tolerance +-10 %
    "pzt_modulus_Pa": Tolerance(0.025),       # +-5 %
}
# DesignParams field -> tolerance (1 sigma); kappa is a tuple, each joint drawn on its own
DESIGN_TOLERANCES: dict[str, Tolerance] = {
    "k_ser_N_per_m": Tolerance(0.10),         # assembly / off-axis compliance +-20 %
    "kappa_N_m_per_rad": Tolerance(0.15),     # Kapton thickness +-10 % (kappa ~ t^3) and flexure length: +-30 %
    "bias_m": Tolerance(10e-6, relative=False),   # assembly +-20 um
}


def _normal(rng: np.random.Generator, size: int | None = None) -> np.ndarray | float:
    z = rng.standard_normal(size)
    return np.clip(z, -TRUNCATE_SIGMA, TRUNCATE_SIGMA)


def draw_specimen(seed: int, actuator: dict[str, float], design: dict[str, object]) -> dict[str, dict[str, object]]:
    """Overrides {"actuator": {...}, "design": {...}} for one specimen (the fields of the two parameter records,
    as `BenchSettings.model_overrides` takes them), drawn around the given preset values."""
    rng = np.random.default_rng([int(seed), 0x5EC1])
    out_a: dict[str, object] = {}
    for name, tol in ACTUATOR_TOLERANCES.items():
        out_a[name] = float(actuator[name]) * (1.0 + tol.sigma * float(_normal(rng)))
    out_d: dict[str, object] = {}
    for name, tol in DESIGN_TOLERANCES.items():
        value = design[name]
        if isinstance(value, (tuple, list)):
            z = _normal(rng, len(value))
            out_d[name] = [float(v) * (1.0 + tol.sigma * float(zi))
                           for v, zi in zip(value, np.atleast_1d(z), strict=True)]
        elif tol.relative:
            out_d[name] = float(value) * (1.0 + tol.sigma * float(_normal(rng)))  # type: ignore[arg-type]
        else:
            out_d[name] = float(value) + tol.sigma * float(_normal(rng))  # type: ignore[arg-type]
    return {"actuator": out_a, "design": out_d}
