"""`mypy` on the packages (pyproject.toml [tool.mypy]) finds no error beyond its baseline, and nothing in the
baseline that is fixed (tests/house/baselines.py says how both are kept)."""

from __future__ import annotations

import pytest

from tests.house import baselines


@pytest.mark.parametrize("package", ["mypy", "types-pyserial", "types-tqdm"])
def test_type_checker_and_stubs_are_the_pinned_versions(package):
    installed, pinned = baselines.installed_version(package), baselines.pinned_version(package)
    if installed != pinned:
        pytest.fail(f"{package} {installed} is installed, the baseline is {package} {pinned}'s: "
                    "pip install -e '.[test]'")


def test_type_errors_are_the_baselines():
    comparison = baselines.compare(baselines.MYPY)
    assert comparison.clean, comparison.report(baselines.MYPY)
