"""The backend registry (found by name, one clear line when missing), the one configuration loader (types, checks,
unknown and missing keys, one-line errors naming the place), one default per setting, and the command line's
refusal to lose a command silently (commands and backends found by name through entry points)."""

from __future__ import annotations

import argparse
import dataclasses
import importlib.metadata
import inspect
import subprocess
import sys
from pathlib import Path

import pytest

from hamr_bench import backends, cli, entry_points
from hamr_bench.config import Place, load_table, setting
from hamr_bench.errors import ConfigError
from hamr_bench.rig import load_rig, sim_rig_path
from hamr_bench.rig_file import Nano17Table, read_rig_file

REPO = Path(__file__).resolve().parents[2]


def test_declared_backends_resolve_to_their_factories():
    from drivers.rig_builder import build_devices
    from sim_devices import traffic_replay
    from sim_devices.rig_sim import make_bench

    assert backends.device_factory() is build_devices
    assert backends.bench_factory() is make_bench
    assert backends.traffic_server() is traffic_replay


def test_a_backend_nobody_declared_is_one_line(monkeypatch):
    with pytest.raises(ConfigError) as info:
        backends.load_backend("no-such-backend")
    message = str(info.value)
    assert "'no-such-backend' is not installed" in message and "\n" not in message
    assert backends.DRIVERS in message  # lists what is declared


def test_a_backend_whose_module_fails_to_import_is_one_line(monkeypatch):
    monkeypatch.setattr(backends, "declared_backends", lambda: {"broken": "no_such_package.module:make"})
    with pytest.raises(ConfigError, match=r"backend 'broken' cannot be loaded: No module named 'no_such_package'"):
        backends.load_backend("broken")


def test_a_registered_backend_replaces_the_declared_one(monkeypatch):
    built = []

    def fake_bench(rig_file, options):
        built.append((rig_file.name, options.seed))
        raise ConfigError("fake bench: stop here")

    monkeypatch.setitem(backends._registered, backends.SIMULATED_BENCH, fake_bench)
    with pytest.raises(ConfigError, match="fake bench: stop here"):
        load_rig(sim_rig_path(), seed=11)
    assert built == [("Simulated HAMR-V powertrain bench", 11)]


def test_the_source_trees_own_declarations_are_the_pyprojects():
    import tomllib

    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"]["hamr_bench.backends"]
    assert backends.declared_backends().items() >= declared.items()


@dataclasses.dataclass(frozen=True)
class Table:
    count: int = setting(lo=1, hi=5)
    rate_Hz: float = setting(10.0, positive=True)
    mode: str = setting("a", choices=("a", "b"))
    pair_m: tuple[float, float] | None = None
    weights: dict[str, float] = dataclasses.field(default_factory=dict)
    flag: bool = False


@pytest.mark.parametrize("values, expected", [
    ({"count": 2, "rate_Hz": 0}, "f.toml: [t] rate_Hz: expected a positive number, got 0"),
    ({"count": 9}, "f.toml: [t] count: expected at most 5, got 9"),
    ({"count": 2.0}, "f.toml: [t] count: expected an integer, got 2.0"),
    ({"count": 2, "mode": "c"}, "f.toml: [t] mode: expected one of a, b, got 'c'"),
    ({"count": 2, "pair_m": [2, 1]}, "f.toml: [t] pair_m: expected [low, high] with low < high, got [2, 1]"),
    ({"count": 2, "weights": {"x": "y"}}, "f.toml: [t] weights.x: expected a finite number, got 'y'"),
    ({"count": 2, "flag": "yes"}, "f.toml: [t] flag: expected true or false, got 'yes'"),
    ({"count": 2, "rate": 1.0}, "f.toml: [t] rate: unknown key (known: count, rate_Hz, mode, pair_m, weights, flag)"),
    ({}, "f.toml: [t] count is missing"),
])
def test_the_loader_names_the_file_the_table_and_the_key_in_one_line(values, expected):
    with pytest.raises(ConfigError) as info:
        load_table(Table, values, Place("f.toml", "t"))
    assert str(info.value) == expected


def test_the_loader_fills_defaults_and_converts():
    t = load_table(Table, {"count": 3, "rate_Hz": 5, "pair_m": [0, 1e-3], "weights": {"a": 1}}, Place("f", "t"))
    assert t == Table(count=3, rate_Hz=5.0, pair_m=(0.0, 1e-3), weights={"a": 1.0})
    assert isinstance(t.rate_Hz, float)


def test_text_values_are_accepted_only_where_asked():
    base = Table(count=1)
    t = load_table(Table, {"count": "4", "flag": "true", "rate_Hz": "2.5"}, Place("--set"), base=base, from_text=True)
    assert (t.count, t.flag, t.rate_Hz) == (4, True, 2.5)
    with pytest.raises(ConfigError, match=r"--set: count: expected an integer, got '4'"):
        load_table(Table, {"count": "4"}, Place("--set"), base=base)


def test_one_default_per_setting_the_nano17_rate():
    # The driver's default and the rig file's were 5000 and 1000 Hz; now the driver takes the rig file's.
    from drivers.ati_nano17 import AtiNano17

    driver_default = inspect.signature(AtiNano17).parameters["sample_rate_Hz"].default
    assert driver_default == Nano17Table.sample_rate_Hz == 5000.0


def test_every_table_of_the_shipped_rig_files_is_checked_before_anything_is_built():
    for path in sorted((REPO / "rigs").glob("*.toml")):
        rig_file = read_rig_file(path)
        assert rig_file.rig.kind in ("real", "sim") and rig_file.stage.backend == "smc100"


def test_a_bad_key_in_a_table_the_run_does_not_use_is_still_an_error(tmp_path):
    # [actuator_force_sensor] is used by the actuator protocol only; a mistake in it is still found by any run.
    text = sim_rig_path().read_text().replace('axis = "Fz"', 'axis = "Fw"')
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=r"\[actuator_force_sensor\] axis: expected one of Fx, Fy, Fz, got 'Fw'"):
        load_rig(path)


def test_a_command_module_that_fails_to_import_is_one_line_and_a_failure(monkeypatch, capsys):
    declared = {**cli.declared_commands(), "nothing": "hamr_bench.commands.no_such_command:register"}
    monkeypatch.setattr(cli, "declared_commands", lambda: declared)
    code = cli.main(["--help"])
    err = capsys.readouterr().err.strip()
    assert code == cli.EXIT_ERROR and len(err.splitlines()) == 1
    assert "command 'nothing' (hamr_bench.commands.no_such_command:register) cannot be loaded: ModuleNotFoundError" \
        in err


def test_the_command_line_lists_the_declared_commands_in_declaration_order(capsys):
    import tomllib

    declared = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["entry-points"][cli.COMMAND_GROUP]
    assert list(cli.declared_commands())[:len(declared)] == list(declared)
    parser = cli.build_parser()
    (subparsers,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    listed = [choice.dest for choice in subparsers._choices_actions]
    # each module registers one command; its name is the entry point's (`import` lives in import_cmd.py)
    assert listed[:len(declared)] == list(declared)


def test_the_source_trees_declarations_replace_a_stale_installed_copy(monkeypatch):
    # An editable install records the entry points of the day it was installed; a checkout that has since moved a
    # module must not see the old name (it would fail to import), while other distributions' plug-ins stay.
    class Dist:
        def __init__(self, name):
            self.name = name

    def fake_installed(group):
        stale = importlib.metadata.EntryPoint("fit", "hamr_bench.commands.fit:register", group)
        plugin = importlib.metadata.EntryPoint("lab-extra", "lab_plugin.cmd:register", group)
        return [stale._for(Dist("hamr_bench")), plugin._for(Dist("lab-plugin"))]

    monkeypatch.setattr(importlib.metadata, "entry_points", lambda group: fake_installed(group))
    monkeypatch.setattr(entry_points, "_source_tree", lambda group: {"fit": "analysis.commands.fit:register"})
    assert entry_points.declared(cli.COMMAND_GROUP) == {"fit": "analysis.commands.fit:register",
                                                         "lab-extra": "lab_plugin.cmd:register"}
    monkeypatch.setattr(entry_points, "_source_tree", lambda group: None)  # an installed wheel: metadata only
    assert entry_points.declared(cli.COMMAND_GROUP) == {"fit": "hamr_bench.commands.fit:register",
                                                         "lab-extra": "lab_plugin.cmd:register"}


def test_importing_the_selfcheck_loads_no_simulated_device():
    code = ("import sys, analysis.gap.selfcheck; "
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('sim_devices', 'drivers')))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_the_demo_finds_every_command_it_runs_wherever_its_module_lives():
    # the demo skips a step whose command is missing; a command module that moved packages must not look missing
    from hamr_bench.commands import demo

    assert all(demo._available(c) for c in ("paper", "fit", "report", "replay", "compare", "gap"))
    assert not demo._available("no-such-command")
