"""Entry points by group: how `hamr_bench` finds what the packages above it provide (backends, command modules)
by name, without importing those packages itself.

A group is declared in pyproject.toml (`[project.entry-points."<group>"]`, name = "module" or "module:attribute").
Installed distributions declare theirs in their metadata; the source tree this package runs from declares its own
in its pyproject.toml, and those win over hamr-bench's installed metadata: an editable install's entry points are
fixed when it is installed, so a checkout run in place (a worktree, a branch that moved a module) would otherwise
see the stale names of whatever was installed. Other distributions' entry points (plug-ins) are kept either way.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import tomllib
from pathlib import Path

DISTRIBUTION = "hamr-bench"
_PYPROJECT = Path(__file__).resolve().parent.parent / "pyproject.toml"


def declared(group: str) -> dict[str, str]:
    """name -> "module[:attribute]" of every entry point of `group`, the source tree's first, in declaration order
    (the order the command line lists its commands in)."""
    own = _source_tree(group)
    found = dict(own) if own is not None else {}
    for ep in importlib.metadata.entry_points(group=group):
        if own is not None and _is_this_distribution(ep):
            continue  # the source tree's declarations replace the installed copy's
        found.setdefault(ep.name, ep.value)
    return found


def resolve(value: str) -> object:
    """Import the module of an entry-point value ("module" or "module:attribute") and return the object it names.
    ImportError and AttributeError propagate: callers turn them into their own one-line errors."""
    module_name, _, attr = value.partition(":")
    module = importlib.import_module(module_name.strip())
    return getattr(module, attr.strip()) if attr else module


def _source_tree(group: str) -> dict[str, str] | None:
    """The group as this checkout's pyproject.toml declares it; None when this package is not run from a
    hamr-bench checkout (an installed wheel has no pyproject.toml beside it)."""
    try:
        project = tomllib.loads(_PYPROJECT.read_text(encoding="utf-8")).get("project", {})
    except (OSError, tomllib.TOMLDecodeError):
        return None
    if project.get("name") != DISTRIBUTION:
        return None
    return dict(project.get("entry-points", {}).get(group, {}))


def _is_this_distribution(ep: importlib.metadata.EntryPoint) -> bool:
    dist = ep.dist
    return dist is not None and dist.name.replace("_", "-").lower() == DISTRIBUTION
