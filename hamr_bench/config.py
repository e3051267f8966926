"""Reading TOML configuration (rig and protocol files) with errors that name the file, the key and what was
expected. Owns only the checked accessors; what the keys mean belongs to `rig` and `protocols`."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path
from typing import Any

from hamr_bench.errors import ConfigError


def load_toml(path: Path) -> dict[str, Any]:
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a UTF-8 text file") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None


class Section:
    """A table of a TOML file with typed getters whose errors name `file: [table] key`."""

    def __init__(self, source: str, table: str, data: dict[str, Any]) -> None:
        self.source = source
        self.table = table
        self.data = data
        self._used: set[str] = set()

    def where(self, key: str) -> str:
        return f"{self.source}: [{self.table}] {key}"

    def has(self, key: str) -> bool:
        return key in self.data

    def _get(self, key: str, default: Any) -> Any:
        self._used.add(key)
        if key not in self.data:
            if default is _REQUIRED:
                raise ConfigError(f"{self.where(key)} is missing")
            return default
        return self.data[key]

    def str(self, key: str, default: Any = None, choices: tuple[str, ...] | None = None) -> str:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, str):
            raise ConfigError(f"{self.where(key)}: expected a string, got {value!r}")
        if choices and value not in choices:
            raise ConfigError(f"{self.where(key)}: expected one of {', '.join(choices)}, got {value!r}")
        return value

    def int(self, key: str, default: Any = None, lo: int | None = None, hi: int | None = None) -> int:
        value = self._get(key, _REQUIRED if default is None else default)
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{self.where(key)}: expected an integer, got {value!r}")
        _check_range(self.where(key), value, lo, hi)
        return value

    def float(
        self, key: str, default: Any = None, lo: float | None = None, hi: float | None = None, positive: bool = False
    ) -> float:
        value = self._get(key, _REQUIRED if default is None else default)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ConfigError(f"{self.where(key)}: expected a finite number, got {value!r}")
        if positive and value <= 0:
            raise ConfigError(f"{self.where(key)}: expected a positive number, got {value!r}")
        _check_range(self.where(key), value, lo, hi)
        return float(value)

    def bool(self, key: str, default: Any = None) -> bool:
        value = self._get(key, _REQUIRED if default is None else default)
        if not isinstance(value, bool):
            raise ConfigError(f"{self.where(key)}: expected true or false, got {value!r}")
        return value

    def float_pair(self, key: str, default: Any = None) -> tuple[float, float]:
        value = self._get(key, _REQUIRED if default is None else default)
        if (
            not isinstance(value, (list, tuple))
            or len(value) != 2
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value)
            or not value[0] < value[1]
        ):
            raise ConfigError(f"{self.where(key)}: expected [low, high] with low < high, got {value!r}")
        return float(value[0]), float(value[1])

    def table_of_floats(self, key: str) -> dict[str, float]:
        value = self._get(key, {})
        if not isinstance(value, dict):
            raise ConfigError(f"{self.where(key)}: expected a table of name = number")
        out = {}
        for name, strength in value.items():
            if isinstance(strength, bool) or not isinstance(strength, (int, float)) or not math.isfinite(strength):
                raise ConfigError(f"{self.where(key)}.{name}: expected a finite number, got {strength!r}")
            out[name] = float(strength)
        return out

    def mark_used(self, *keys: str) -> None:
        """Keys that are valid here even when this run does not read them (e.g. a port the simulator replaces)."""
        self._used.update(keys)

    def check_no_unknown_keys(self) -> None:
        unknown = sorted(set(self.data) - self._used)
        if unknown:
            raise ConfigError(f"{self.where(unknown[0])}: unknown key (known: {', '.join(sorted(self._used))})")


class _Required:
    pass


_REQUIRED = _Required()


def _check_range(where: str, value: float, lo: float | None, hi: float | None) -> None:
    if lo is not None and value < lo:
        raise ConfigError(f"{where}: expected at least {lo}, got {value!r}")
    if hi is not None and value > hi:
        raise ConfigError(f"{where}: expected at most {hi}, got {value!r}")


def section(doc: dict[str, Any], source: str, table: str, required: bool = True) -> Section | None:
    if table not in doc:
        if required:
            raise ConfigError(f"{source}: [{table}] table is missing")
        return None
    data = doc[table]
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: {table} must be a table ([{table}])")
    return Section(source, table, data)


def parse_effects(text: str, source: str = "--effects") -> dict[str, float]:
    """Parse 'name=strength,name=strength' (the command-line form of rig `effects`)."""
    effects: dict[str, float] = {}
    for item in filter(None, (part.strip() for part in text.split(","))):
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise ConfigError(f"{source}: expected NAME=STRENGTH, got {item!r}")
        try:
            strength = float(value)
        except ValueError:
            raise ConfigError(f"{source}: strength of {name.strip()!r} must be a number, got {value!r}") from None
        if not math.isfinite(strength):
            raise ConfigError(f"{source}: strength of {name.strip()!r} must be finite, got {value!r}")
        effects[name.strip()] = strength
    return effects
