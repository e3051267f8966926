"""Sim-to-real gap diagnosis (issue 7): where the measured data leave the nominal model (residuals), which
unmodelled effect explains it (library, screening, attribution), how much it closes on held-out conditions, and
a blind self-check on the simulated bench (selfcheck). Entry point: `attribution.diagnose`."""
