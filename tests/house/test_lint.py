"""`ruff check` (rules E, F, B, UP, SIM and C901 at complexity 10: pyproject.toml) finds nothing beyond its
baseline, and nothing in the baseline that is fixed (tests/house/baselines.py says how both are kept)."""

from __future__ import annotations

import pytest

from tests.house import baselines


def test_ruff_is_the_pinned_version():
    installed, pinned = baselines.installed_version("ruff"), baselines.pinned_version("ruff")
    if installed != pinned:
        pytest.fail(f"ruff {installed} is installed, the baseline is ruff {pinned}'s: pip install -e '.[test]'")


def test_lint_findings_are_the_baselines():
    comparison = baselines.compare(baselines.RUFF)
    assert comparison.clean, comparison.report(baselines.RUFF)
