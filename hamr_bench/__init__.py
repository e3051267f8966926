"""hamr-bench: bench instrumentation, simulation and analysis for the powertrain of miniature legged robots.

This package holds what every part shares: the physics model (`model`), device interfaces and the clock, rig
configuration, protocols and their runner, recording, and the command line. `drivers`, `sim_devices` and `analysis`
depend on it; it imports none of them at import time.
"""

__version__ = "0.1.0"
