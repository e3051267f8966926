"""Performance benchmarks; run with `python -m benchmarks [--quick] --json`. Never part of the test suite."""
