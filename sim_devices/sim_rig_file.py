"""Rig files for the simulated bench written from code: the shipped `rigs/sim.toml` with chosen `[sim]` keys set
(effects, their shapes, a specimen's parameters), so a run made from them goes through the same rig loader as any
run (`hamr-bench run --rig FILE`). Used by the trial scenarios and the tests."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

SIM_RIG = Path(__file__).resolve().parents[1] / "rigs" / "sim.toml"


def toml_value(value: Any) -> str:
    """A TOML inline value for numbers, booleans, strings, lists and (nested) tables."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if not math.isfinite(value):
            raise ValueError(f"a rig file value must be finite, got {value!r}")
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{_key(k)} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise ValueError(f"cannot write {value!r} into a rig file")


def _key(name: str) -> str:
    return name if name.replace("_", "").isalnum() else toml_value(str(name))


def sim_rig_text(sim: dict[str, Any]) -> str:
    """`rigs/sim.toml` with the given `[sim]` keys replaced or added (the [sim] table is the file's last)."""
    lines = [_absolute_paths(ln) for ln in SIM_RIG.read_text(encoding="utf-8").splitlines()]
    start = lines.index("[sim]")
    body = lines[start + 1:]
    kept = [ln for ln in body if ln.split("=", 1)[0].strip() not in sim]
    added = [f"{_key(k)} = {toml_value(v)}" for k, v in sim.items()]
    return "\n".join(lines[:start + 1] + kept + added) + "\n"


def _absolute_paths(line: str) -> str:
    """Paths in the shipped file are relative to it; the written file may live anywhere."""
    key, eq, rest = line.partition("=")
    if eq and key.strip() == "calibration_file":
        value = rest.split("#", 1)[0].strip().strip('"')
        return f"{key.rstrip()} = {toml_value(str((SIM_RIG.parent / value).resolve()))}"
    return line


def write_sim_rig(path: Path, sim: dict[str, Any]) -> Path:
    path = Path(path)
    path.write_text(sim_rig_text(sim), encoding="utf-8")
    return path
