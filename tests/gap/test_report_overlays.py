"""The report's overlay panels (which rows share a panel) and its specimen table's labels."""

from types import SimpleNamespace

from analysis.gap.report import _overlay_panels, specimen_label


def _run(index, protocol="actuator", fixture="actuator", specimen="A", session="s1"):
    return SimpleNamespace(index=index, protocol=protocol, fixture=fixture, layers=2, specimen=specimen,
                           session=session)


def _row(run, mode, phase="high_late"):
    return SimpleNamespace(run=run, mode=mode, phase=phase)


def test_an_imported_specimens_files_share_a_panel_and_a_leg_run_keeps_its_own():
    # an imported trace holds one bias voltage per file: alone, each run's panel would be one point
    runs = [_run(0), _run(1), _run(2, specimen="B"), _run(3, protocol="sag-sweep", fixture="leg"),
            _run(4, protocol="sag-sweep", fixture="leg")]
    rows = [_row(0, "blocked"), _row(0, "blocked", "rise"), _row(1, "blocked"), _row(0, "free"), _row(2, "blocked"),
            _row(3, ""), _row(4, ""), _row(4, "", "hold")]
    problem = SimpleNamespace(rows=rows, data=SimpleNamespace(runs=runs))
    assert _overlay_panels(problem) == {(0, "blocked"): [0, 2], (0, "free"): [3], (2, "blocked"): [4],
                                        (3, ""): [5], (4, ""): [6, 7]}


def test_the_specimen_table_names_a_specimen_by_its_layers_and_label():
    assert specimen_label("layers=1|specimen=") == "1 layer"          # a native recording names no specimen
    assert specimen_label("layers=2|specimen=B") == "2 layers, specimen B"
    # a key the report does not know, or a label holding '|': kept whole, the '|' escaped for the Markdown table
    assert specimen_label("layers=3|specimen=a|b") == "layers=3\\|specimen=a\\|b"
