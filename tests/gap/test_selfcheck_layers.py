"""A self-check trial over several layer counts (`selfcheck --layers`): the same hidden case, more specimens, one
CSV per test x layer count x V_bias through the importer."""

from __future__ import annotations

from analysis.gap.selfcheck import draw_trial, trial_recordings


def test_other_layer_counts_add_specimens_and_leave_the_rest_of_the_draw_as_it_was():
    for seed in (205600001, 205600002, 205600040):
        one, three = draw_trial(seed), draw_trial(seed, layer_counts=(1, 2, 3))
        assert three.effects == one.effects and three.kind == one.kind
        assert three.specimens[:len(one.specimens)] == one.specimens
        assert three.layer_counts == (1, 2, 3) and one.layer_counts == (2,)
        assert sorted(s.layers for s in three.specimens) == [1] * 3 + [2] * 3 + [3] * 3
        assert len({s.label for s in three.specimens}) == 9
        assert len({s.seed for s in three.specimens}) == 9


def test_each_layer_count_is_written_and_imported_as_its_own_files(tmp_path):
    from analysis.gap.features import load_gap_data

    sc = draw_trial(205600001, specimens=1, layer_counts=(1, 3))
    paths = trial_recordings(sc, 205600001, tmp_path)
    assert len(paths) == 2 * 2 * 3      # blocked and free x two layer counts x three voltages
    runs = load_gap_data(paths).runs
    assert sorted({r.layers for r in runs}) == [1, 3]
    for r in runs:      # each file's layer count, as the importer was told it, is the one its name says
        assert f"-{r.layers}x-" in r.path
