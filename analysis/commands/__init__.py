"""Command modules of the analysis (import, fit, report, replay, compare, gap, selfcheck): the top layer, above
`analysis` and `hamr_bench`, found by the command line through the entry-point group `hamr_bench.commands`
(docs/architecture.md). Every command module is imported to build the parser, so a handler imports the analysis
stack it drives (numpy, scipy, matplotlib: 0.2 to 1.5 s) when it runs, not when the module is imported."""
