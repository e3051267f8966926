"""Which recordings a command was given: files as named, directories searched for *.mcap (not recursively), and
one clear line where that finds none."""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

from hamr_bench.errors import ConfigError


def recording_files(paths: Iterable[Path | str]) -> list[Path]:
    """The .mcap files named, and those directly inside each directory named, in order (each directory's sorted).
    None at all is a ConfigError; where a directory's subdirectories hold recordings, it names them, since a
    recording one level down is the usual reason (an import's or a campaign's output folder)."""
    files: list[Path] = []
    empty_dirs: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(p.glob("*.mcap"))
            files.extend(found)
            if not found:
                empty_dirs.append(p)
        else:
            files.append(p)
    if files:
        return files
    below = sorted({f.parent for d in empty_dirs for f in d.glob("*/**/*.mcap")})
    if below:
        shown = ", ".join(str(b) for b in below[:3]) + (f" and {len(below) - 3} more" if len(below) > 3 else "")
        raise ConfigError(f"no .mcap recordings directly in {', '.join(str(d) for d in empty_dirs)}; "
                          f"directories below hold some: {shown} (give those)")
    raise ConfigError("no recordings given (expected .mcap files or directories holding them)")
