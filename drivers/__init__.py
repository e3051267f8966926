"""Real device drivers: the code that talks to a lab's stage, force sensors, amplifiers and cameras. The same code
runs against the emulators in `sim_devices`, which sit below it at the wire (serial) or vendor-API (DAQ, camera)
level. Depends on `hamr_bench` only."""
