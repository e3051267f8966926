"""Protocol parameters: every protocol's parameters are a frozen dataclass whose defaults follow the paper. This
module turns a protocol file (TOML) and `--set name=value` options into such a dataclass through the one
configuration loader (`hamr_bench.config`), with errors that name the file or option, the parameter and what was
expected, then runs the dataclasses' own `validate()` for the rules that span fields."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, TypeVar

from hamr_bench.config import Place, load_table, load_toml
from hamr_bench.errors import ConfigError

P = TypeVar("P")


@dataclasses.dataclass(frozen=True)
class DriveParams:
    """The trapezoid drive shared by every driven protocol."""

    ramp_s: float = 0.05
    dwell_high_s: float = 0.4
    dwell_low_s: float = 0.4
    cycles: int = 3
    sample_rate_Hz: float = 1000.0
    settle_s: float = 0.2
    # A second ramp rate on alternate repetitions (0: one rate): on one ramp rate a timing lag and
    # rate-independent hysteresis delay the ramps alike; a lag scales with the ramp's slope, hysteresis does not.
    slow_ramp_s: float = 0.15

    def ramp_for(self, repetition: int, period: int = 1) -> float:
        """The ramp of a repetition: `slow_ramp_s` on every other block of `period` repetitions (a protocol that
        alternates its sweep direction passes 2, so both directions see both rates)."""
        if self.slow_ramp_s > 0 and (repetition // max(period, 1)) % 2 == 1:
            return self.slow_ramp_s
        return self.ramp_s

    def validate(self) -> None:
        # The same checks the waveform generator makes, up front: a bad drive must not surface only after the
        # contact search.
        if self.slow_ramp_s < 0:
            raise ConfigError(f"drive slow_ramp_s: expected 0 (one ramp rate) or a positive time, got "
                              f"{self.slow_ramp_s!r}")
        if not self.ramp_s > 0:
            raise ConfigError(f"drive ramp_s: must be positive (a step excites the actuator resonance), "
                              f"got {self.ramp_s!r}")
        for name in ("dwell_high_s", "dwell_low_s", "settle_s"):
            if getattr(self, name) < 0:
                raise ConfigError(f"drive {name}: expected a non-negative time, got {getattr(self, name)!r}")
        if self.cycles < 1:
            raise ConfigError(f"drive cycles: expected at least 1, got {self.cycles!r}")
        if not self.sample_rate_Hz > 0:
            raise ConfigError(f"drive sample_rate_Hz: expected a positive rate, got {self.sample_rate_Hz!r}")


def field_names(cls: type) -> list[str]:
    return [f.name for f in dataclasses.fields(cls)]


def override(params: P, values: dict[str, Any], where: str) -> P:
    """A copy of `params` with `values` applied (nested tables such as `drive` and `contact` allowed); values may be
    text (`--set`), as the one configuration loader (`hamr_bench.config.load_table`) accepts them here."""
    return load_table(type(params), values, Place(where), base=params, from_text=True)


def parse_set_options(options: list[str]) -> dict[str, Any]:
    """`['voltages_V=100,150', 'drive.cycles=5']` -> {'voltages_V': '100,150', 'drive': {'cycles': '5'}}."""
    values: dict[str, Any] = {}
    for option in options:
        name, sep, value = option.partition("=")
        if not sep or not name:
            raise ConfigError(f"--set {option!r}: expected NAME=VALUE")
        table, dot, key = name.partition(".")
        if dot:
            values.setdefault(table, {})[key] = value
        else:
            values[name] = value
    return values


def load_params(defaults: Any, protocol_file: Path | None, set_options: list[str]) -> Any:
    params = defaults
    if protocol_file is not None:
        doc = load_toml(protocol_file)
        doc.pop("protocol", None)  # the file may name its protocol; the runner checks it separately
        params = override(params, doc, str(protocol_file))
    if set_options:
        params = override(params, parse_set_options(set_options), "--set")
    sources = " and ".join(filter(None, [str(protocol_file) if protocol_file else "", "--set" if set_options else ""]))
    try:
        _validate(params)
    except ConfigError as exc:
        raise ConfigError(f"{sources}: {exc}" if sources else str(exc)) from None
    return params


def _validate(params: Any) -> None:
    """Run `validate()` of the parameters and of every nested parameter table (drive, contact)."""
    for f in dataclasses.fields(params):
        value = getattr(params, f.name)
        if dataclasses.is_dataclass(value):
            _validate(value)
    validate = getattr(params, "validate", None)
    if validate:
        validate()


def as_dict(params: Any) -> dict[str, Any]:
    return dataclasses.asdict(params)
