"""Bad rig and protocol files get one line naming the file, the table or parameter, and what was expected."""

from pathlib import Path

import pytest

from hamr_bench.cli import main
from hamr_bench.errors import ConfigError
from hamr_bench.protocols import get_protocol
from hamr_bench.protocols.params import load_params
from hamr_bench.rig import load_rig, sim_rig_path

SIM = sim_rig_path().read_text()


def rig_with(tmp_path: Path, old: str, new: str) -> Path:
    assert old in SIM
    path = tmp_path / "rig.toml"
    text = SIM.replace(old, new).replace('"../sim_devices/', f'"{sim_rig_path().parent}/../sim_devices/')
    path.write_text(text)
    return path


@pytest.mark.parametrize("old, new, expected", [
    ("address = 1", "address = 40", "[stage] address: expected at most 31, got 40"),
    ("address = 1", "adress = 1", "[stage] adress: unknown key"),
    ("max_voltage_V = 250.0", 'max_voltage_V = "high"', "[rig] max_voltage_V: expected a finite number"),
    ("max_voltage_V = 250.0", "max_voltage_V = 400.0", "[rig] max_voltage_V: expected at most 350"),
    ('command_set = "di1000"', 'command_set = "dx9"', "[force_sensor] command_set: expected one of di1000, iload"),
    ("[camera]", "[kamera]", "unknown table [kamera]"),
    ("effects = {}", "effects = { hysterisis = 0.1 }", "[sim] effects: unknown effect 'hysterisis'"),
    ("gain_V_per_V = 35.0 ", "gain_V_per_V = -35.0 ", "[amplifier] gain_V_per_V: expected a positive number"),
])
def test_bad_rig_file_names_the_place(tmp_path, old, new, expected):
    path = rig_with(tmp_path, old, new)
    with pytest.raises(ConfigError) as info:
        rig = load_rig(path)
        rig.close()
    message = str(info.value)
    assert expected in message and "\n" not in message
    assert str(path) in message


def test_not_toml_and_missing_file(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("[rig\nkind = 'sim'")
    with pytest.raises(ConfigError, match="bad.toml: not valid TOML"):
        load_rig(bad)
    with pytest.raises(ConfigError, match="nope.toml: file not found"):
        load_rig(tmp_path / "nope.toml")


def test_bad_protocol_parameters_name_the_parameter(tmp_path):
    params = get_protocol("blocked-force").Params()
    with pytest.raises(ConfigError, match=r"--set: unknown parameter 'voltage_V' \(known: voltages_V"):
        load_params(params, None, ["voltage_V=100"])
    with pytest.raises(ConfigError, match="--set drive: cycles: expected an integer, got 'two'"):
        load_params(params, None, ["drive.cycles=two"])
    file = tmp_path / "p.toml"
    file.write_text("repetitions = 0\n")
    with pytest.raises(ConfigError, match="repetitions: expected at least 1"):
        load_params(params, file, [])


def test_cli_refuses_to_overwrite_and_says_so_in_one_line(tmp_path, capsys):
    out = tmp_path / "run.mcap"
    out.write_bytes(b"precious")
    code = main(["run", "static", "--sim", "--quiet", "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "--force" in err
    assert out.read_bytes() == b"precious"


def test_non_positive_baudrate_names_the_place(tmp_path):
    """Found by the mutated-rig property test: baudrate = 0 used to end in a ZeroDivisionError traceback."""
    with pytest.raises(ConfigError, match=r"\[force_sensor\] baudrate: expected at least 1, got 0"):
        load_rig(rig_with(tmp_path, "baudrate = 9600", "baudrate = 0"))


def test_a_loadstar_tare_of_no_readings_names_the_place(tmp_path):
    with pytest.raises(ConfigError, match=r"\[force_sensor\] tare_readings: expected at least 1, got 0"):
        load_rig(rig_with(tmp_path, "baudrate = 9600", "baudrate = 9600\ntare_readings = 0"))
