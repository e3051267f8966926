"""The simulated bench: one object owning the physics (the powertrain model) and the virtual clock, with emulators
for each device as its ports, plus realistic-bench effects and fault injection. Depends on `hamr_bench` only."""
