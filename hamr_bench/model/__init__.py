"""The powertrain physics model (seed paper: Ozcan, Baisch & Wood, ICRA 2014): bimorph actuator, slider-crank lift
transmission with flexures, serial compliance and the quasi-static power balance, plus the effects mechanism.
See docs/model.md for equations, sign conventions and sources."""

from hamr_bench.model.actuator import ActuatorParams, actuator_preset
from hamr_bench.model.designs import (DEFAULT_KAPPA_UNITS, GEOMETRIES, GEOMETRY, KAPPA_READINGS, DesignParams,
                                      design_preset)
from hamr_bench.model.effects import BaseCompliance, Effect, FieldDependentD31, PlayHysteresis
from hamr_bench.model.powertrain import DEFAULT_VOLTAGE_LIMIT_V, Powertrain, powertrain
from hamr_bench.model.transmission import SliderCrankGeometry

__all__ = [
    "ActuatorParams", "actuator_preset", "DesignParams", "design_preset", "GEOMETRY", "GEOMETRIES",
    "KAPPA_READINGS", "DEFAULT_KAPPA_UNITS",
    "Effect", "BaseCompliance", "FieldDependentD31", "PlayHysteresis", "Powertrain", "powertrain",
    "DEFAULT_VOLTAGE_LIMIT_V", "SliderCrankGeometry",
]
