"""An independent "other lab": bare-actuator test data in the documented trace CSV format, and a scorer that
runs hamr-bench on it as a user would (import every CSV, then `gap`), so the gap diagnosis is measured on data
it did not write.

Independence is the point: nothing in this package imports `analysis`, `sim_devices`, `hamr_bench.model` or
`drivers` (tests/benchmarks/test_external_lab.py parses every module's imports). The bimorph physics is
written here from the published equations (a layer-stack beam section and a finite-element tapered
cantilever), and every unmodelled effect is in a form that is in neither column of the project's effect-forms
table (the bench generator's and the diagnosis's). The truth of each case goes into a manifest outside the
case directories.

Modules: `physics` (laminate section, FEM cantilever, Table I), `effects` (material-side effect forms and
decoys), `mechanics` (series springs and the contact solve), `sensors` (drift, noise, camera, sensor chains),
`drive` (drive timing and the amplifier), `cases` (drawing a case), `simulate` (one specimen block's time
series), `generate` (cases to CSV files and the manifest), `score` (the user path and the figures).
"""
