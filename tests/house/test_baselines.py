"""The baseline comparison itself: a new finding fails, a fixed one fails until pruned, line numbers and the
numbers of a complexity message do not matter, every entry needs a reason."""

from __future__ import annotations

from collections import Counter

from tests.house import baselines as b


def make(tmp_path, entries):
    tool = b.Tool("ruff", tmp_path / "baseline.toml")
    b.write_baseline(tool.baseline, "a header\nof two lines", entries)
    return tool


def test_new_fixed_and_unexplained_findings_are_reported(tmp_path):
    kept = b.Entry("a.py", "B905", "zip() without strict", 2, "numeric pairs of equal length by construction")
    gone = b.Entry("b.py", "C901", "`f` is too complex", 1, "phase 2")
    silent = b.Entry("c.py", "E501", "Line too long", 1, "")
    tool = make(tmp_path, [kept, gone, silent])
    found = Counter({kept.key: 3, silent.key: 1, ("d.py", "F401", "unused"): 1})
    comparison = b.compare(tool, found)
    assert comparison.new == [(kept.key, 1), (("d.py", "F401", "unused"), 1)]
    assert comparison.fixed == [(gone.key, 1)]
    assert comparison.unexplained == [silent.key]
    report = comparison.report(tool)
    assert "prune" in report and "d.py: F401 unused" in report and "a.py: B905 zip() without strict (x1)" not in report


def test_the_baseline_round_trips_and_keeps_its_header(tmp_path):
    entry = b.Entry("a.py", "misc", 'Name "x" already defined on line N with "quotes" and ü', 1, "why: \\ and \"")
    tool = make(tmp_path, [entry])
    assert b.read_baseline(tool.baseline) == [entry]
    assert b.header_of(tool.baseline) == "a header\nof two lines"


def test_line_numbers_and_measured_sizes_are_not_part_of_the_key():
    assert b._normalise("`load_run` is too complex (22 > 10)") == b._normalise("`load_run` is too complex (23 > 10)")
    assert b._normalise('Name "x" already defined on line 12') == 'Name "x" already defined on line N'
