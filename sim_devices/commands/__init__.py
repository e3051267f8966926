"""Command modules that serve the simulated devices (the top layer: they sit above `sim_devices` and `hamr_bench`
and are found by the command line through the entry-point group `hamr_bench.commands`, docs/architecture.md)."""
