"""The command line's shared behaviour: help, version, and one-line errors."""

import subprocess
import sys

from hamr_bench.cli import main


def test_help_lists_commands(capsys):
    assert main([]) == 2
    assert "COMMAND" in capsys.readouterr().out


def test_version_runs_as_module():
    out = subprocess.run([sys.executable, "-m", "hamr_bench", "--version"], capture_output=True, text=True)
    assert out.returncode == 0
    assert out.stdout.startswith("hamr-bench ")
