"""Facts about the instruments as their vendors publish them (command sets, state codes, error letters and
texts),
kept as data that the drivers (`drivers/`) and the emulators (`sim_devices/`) both read, so a fact is written
down
once. Nothing here talks to a device. Where a fact comes from a secondary source it says so (UNVERIFIED)."""
