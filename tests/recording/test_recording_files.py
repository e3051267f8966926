"""The recordings a command was given (hamr_bench.recording.files): directories searched one level, and the one
line a user sees where that finds none."""

from __future__ import annotations

import pytest

from hamr_bench.cli import main
from hamr_bench.errors import ConfigError
from hamr_bench.recording.files import recording_files


def test_files_as_named_and_each_directorys_recordings_sorted(tmp_path):
    (tmp_path / "b.mcap").write_bytes(b"")
    (tmp_path / "a.mcap").write_bytes(b"")
    (tmp_path / "notes.txt").write_text("")
    other = tmp_path / "z.mcap"
    assert recording_files([tmp_path, other]) == [tmp_path / "a.mcap", tmp_path / "b.mcap", other]


def test_recordings_one_level_down_are_named_not_read(tmp_path):
    for sub in ("imported", "runs"):
        (tmp_path / sub).mkdir()
        (tmp_path / sub / "x.mcap").write_bytes(b"")
    with pytest.raises(ConfigError) as err:
        recording_files([tmp_path])
    assert f"{tmp_path / 'imported'}, {tmp_path / 'runs'}" in str(err.value)


def test_gap_on_a_folder_of_folders_is_one_line(tmp_path, capsys):
    (tmp_path / "imported").mkdir()
    (tmp_path / "imported" / "x.mcap").write_bytes(b"")
    assert main(["gap", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "imported" in err[0] and "Traceback" not in err[0]


def test_nothing_anywhere(tmp_path):
    with pytest.raises(ConfigError, match="no recordings given"):
        recording_files([tmp_path])
