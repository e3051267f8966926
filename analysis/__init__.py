"""Offline analysis of recordings: dataset, fits, replay, comparison and the sim-to-real gap diagnosis. Reads only
recordings and imported tables; never imports `drivers`."""
