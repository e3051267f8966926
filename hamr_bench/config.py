"""Reading configuration (rig files, protocol files, `--set` options) into frozen dataclasses: one loader that
checks every value against the dataclass field it fills and reports a mistake in one line naming the file, the
table or parameter, and what was expected.

A configuration table is a frozen dataclass. Its field types say what a value must be (`float`, `int`, `bool`,
`str`, `tuple[float, float]` for a [low, high] pair, `tuple[X, ...]` for a list, `dict[str, float]` for a table
of numbers, `X | None` for an optional key, a nested dataclass for a sub-table); its field defaults are THE
defaults (a field without one is a required key); `setting(...)` adds range and choice checks. `load_table`
builds an instance from a mapping; what the keys mean belongs to the modules that declare the tables (`rig_file`,
`protocols`, `sim_devices.rig_sim`).
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import tomllib
import types
import typing
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

from hamr_bench.errors import ConfigError

T = TypeVar("T")


def load_toml(path: Path) -> dict[str, Any]:
    return read_toml(path)[1]


def read_toml(path: Path) -> tuple[str, dict[str, Any]]:
    """(text, parsed document) of a TOML file; an unreadable or invalid file is one line naming it."""
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: file not found") from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read ({exc.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a UTF-8 text file") from None
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML ({exc})") from None


@dataclass(frozen=True)
class Check:
    """Checks on one value beyond its type."""

    lo: float | None = None
    hi: float | None = None
    positive: bool = False
    choices: tuple[str, ...] = ()


def setting(default: Any = dataclasses.MISSING, *, lo: float | None = None, hi: float | None = None,
            positive: bool = False, choices: tuple[str, ...] = ()) -> Any:
    """A dataclass field with checks: `lo`/`hi` bound a number, `positive` excludes zero and below, `choices`
    lists the strings allowed. Without `default` the key is required."""
    return dataclasses.field(default=default, metadata={"check": Check(lo, hi, positive, choices)})


@dataclass(frozen=True)
class Place:
    """Where values come from, for the one-line errors: a table of a TOML file (`file: [stage] address`) or a set
    of parameters (`--set drive: cycles`, `protocol.toml: repetitions`)."""

    source: str
    table: str | None = None

    def key(self, name: str) -> str:
        return f"{self.source}: [{self.table}] {name}" if self.table is not None else f"{self.source}: {name}"

    def nested(self, name: str) -> Place:
        return Place(f"{self.source} {name}")


def table_of(doc: Mapping[str, Any], source: str, table: str) -> Mapping[str, Any] | None:
    """The table `[table]` of a parsed TOML document, None when absent; a non-table value is an error."""
    if table not in doc:
        return None
    data = doc[table]
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: {table} must be a table ([{table}])")
    return data


def required_table(doc: Mapping[str, Any], source: str, table: str) -> Mapping[str, Any]:
    data = table_of(doc, source, table)
    if data is None:
        raise ConfigError(f"{source}: [{table}] table is missing")
    return data


def load_table(cls: type[T], values: Mapping[str, Any], place: Place, *, base: T | None = None,
               from_text: bool = False) -> T:
    """An instance of the dataclass `cls` from `values`, every value checked against its field. Keys absent from
    `values` keep `base`'s value (or the field default; a required field without either is an error). An unknown
    key is an error listing the known ones. `from_text` also accepts strings for numbers, booleans and lists
    (`--set voltages_V=100,150`), as a parameter file or option gives them."""
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    for name in values:
        if name not in fields:
            known = ", ".join(fields)
            if place.table is not None:
                raise ConfigError(f"{place.key(name)}: unknown key (known: {known})")
            raise ConfigError(f"{place.source}: unknown parameter {name!r} (known: {known})")
    changes: dict[str, Any] = {}
    for name, f in fields.items():
        if name in values:
            current = getattr(base, name) if base is not None else None
            changes[name] = _value(hints[name], values[name], name, place, f.metadata.get("check"), current,
                                   from_text)
        elif base is None and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
            raise ConfigError(f"{place.key(name)} is missing")
    if base is not None:
        return dataclasses.replace(base, **changes)  # type: ignore[type-var]
    return cls(**changes)


def _value(annotation: Any, value: Any, name: str, place: Place, check: Check | None, current: Any,
           from_text: bool) -> Any:
    """`value` checked against the field type `annotation` (and `check`), converted to it."""
    origin = typing.get_origin(annotation)
    args = typing.get_args(annotation)
    where = place.key(name)
    if origin in (typing.Union, types.UnionType):  # `X | None`: TOML has no null, so a value present is an X
        (inner,) = [a for a in args if a is not type(None)]
        return _value(inner, value, name, place, check, current, from_text)
    if dataclasses.is_dataclass(annotation):
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table of {name} parameters")
        return load_table(annotation, value, place.nested(name), base=current, from_text=from_text)  # type: ignore[arg-type]
    if origin is tuple and len(args) == 2 and args[1] is not Ellipsis:
        return _pair(where, value)
    if origin is tuple:
        if from_text and isinstance(value, str):
            value = [v for v in value.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)) or not value:
            raise ConfigError(f"{where}: expected a non-empty list, got {value!r}")
        return tuple(_value(args[0], v, name, place, check, None, from_text) for v in value)
    if origin is dict:
        return _table_of_tables(where, value) if typing.get_origin(args[1]) is dict else _table_of_numbers(where, value)
    if annotation in _SCALARS:
        return _SCALARS[annotation](where, value, check, from_text)
    raise ConfigError(f"{where}: cannot be set from a file")


def _bool(where: str, value: Any, check: Check | None, from_text: bool) -> bool:
    if from_text and isinstance(value, str) and value.lower() in ("true", "false"):
        return value.lower() == "true"
    if not isinstance(value, bool):
        raise ConfigError(f"{where}: expected true or false, got {value!r}")
    return value


def _int(where: str, value: Any, check: Check | None, from_text: bool) -> int:
    number: int | None = value if isinstance(value, int) and not isinstance(value, bool) else None
    if number is None and from_text and not isinstance(value, bool):
        # text "3", or 3.0 from a file, is the integer 3; "3.5" and 3.5 are not integers
        with contextlib.suppress(TypeError, ValueError, OverflowError):
            if not (isinstance(value, float) and not value.is_integer()):
                number = int(value)
    if number is None:
        raise ConfigError(f"{where}: expected an integer, got {value!r}")
    _check_number(where, number, check)
    return number


def _float(where: str, value: Any, check: Check | None, from_text: bool) -> float:
    if from_text and isinstance(value, str):
        with contextlib.suppress(ValueError):
            value = float(value)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise ConfigError(f"{where}: expected a finite number, got {value!r}")
    _check_number(where, value, check)  # the value as written, in the message
    return float(value)


def _str(where: str, value: Any, check: Check | None, from_text: bool) -> str:
    if from_text:
        value = str(value)
    if not isinstance(value, str):
        raise ConfigError(f"{where}: expected a string, got {value!r}")
    if check and check.choices and value not in check.choices:
        raise ConfigError(f"{where}: expected one of {', '.join(check.choices)}, got {value!r}")
    return value


_SCALARS: dict[type, Callable[[str, Any, Check | None, bool], Any]] = {bool: _bool, int: _int, float: _float,
                                                                       str: _str}


def _check_number(where: str, value: float, check: Check | None) -> None:
    if check is None:
        return
    if check.positive and value <= 0:
        raise ConfigError(f"{where}: expected a positive number, got {value!r}")
    if check.lo is not None and value < check.lo:
        raise ConfigError(f"{where}: expected at least {check.lo}, got {value!r}")
    if check.hi is not None and value > check.hi:
        raise ConfigError(f"{where}: expected at most {check.hi}, got {value!r}")


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _pair(where: str, value: Any) -> tuple[float, float]:
    if not (isinstance(value, (list, tuple)) and len(value) == 2 and all(_is_number(v) for v in value)
            and value[0] < value[1]):
        raise ConfigError(f"{where}: expected [low, high] with low < high, got {value!r}")
    return float(value[0]), float(value[1])


def _table_of_tables(where: str, value: Any) -> dict[str, dict[str, Any]]:
    """A table of tables (`effect_shapes = { hysteresis = { r0 = 0.4 } }`); each inner table is checked by its user."""
    if not isinstance(value, dict) or not all(isinstance(v, dict) for v in value.values()):
        raise ConfigError(f"{where}: expected a table of tables, e.g. {{ hysteresis = {{ r0 = 0.4 }} }}")
    return {str(k): dict(v) for k, v in value.items()}


def _table_of_numbers(where: str, value: Any) -> dict[str, float]:
    if not isinstance(value, dict):
        raise ConfigError(f"{where}: expected a table of name = number")
    out = {}
    for name, number in value.items():
        if not _is_number(number):
            raise ConfigError(f"{where}.{name}: expected a finite number, got {number!r}")
        out[name] = float(number)
    return out


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
