"""What a protocol event becomes besides its `/events` message (format 2): a `foxglove.Log` line on `/log`, so
Foxglove's Log panel lists the run's steps as they happen, and, for a `step` event, its condition as typed fields on
`/step`, so a Plot panel draws e.g. `/step.voltage_V` and a State Transitions panel `/step.mode`.

`/events` stays what it was (its `data` is the event's parameters as a JSON object): the analysis reads it, and
files of format 1 have nothing else.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from hamr_bench.recording import schemas
from hamr_bench.recording.contract import EventKind

# foxglove.Log levels (its Level enum)
_INFO, _WARNING, _ERROR = 2, 3, 4
_LEVEL_OF_EXIT = {"success": _INFO, "aborted": _WARNING, "failed": _ERROR}
LOG_NAME = "hamr_bench"


def _format_value(value: Any) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    return str(value)


def log_text(kind: str, step: int, message: str, data: Mapping[str, Any]) -> str:
    """One line: `step 3 | step: 150 V, sag 0.1 mm | voltage_V=150 sag_m=0.0001`."""
    parts = [f"step {step}", kind]
    if message:
        parts[-1] = f"{kind}: {message}"
    if data:
        parts.append(" ".join(f"{k}={_format_value(v)}" for k, v in sorted(data.items())))
    return " | ".join(parts)


def log_level(kind: str, data: Mapping[str, Any]) -> int:
    if kind == EventKind.RUN_END:
        return _LEVEL_OF_EXIT.get(str(data.get("exit_status", "")), _INFO)
    return _INFO


def log_payload(timestamp_ns: int, kind: str, step: int, message: str, data: Mapping[str, Any]) -> bytes:
    """The `foxglove.Log` bytes of one event."""
    cls = schemas.message_class(schemas.LOG_SCHEMA, schemas.log_descriptor_set())
    msg = cls(level=log_level(kind, data), message=log_text(kind, step, message, data), name=LOG_NAME)
    msg.timestamp.FromNanoseconds(int(timestamp_ns))
    return msg.SerializeToString()


def _number(value: Any) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return math.nan
    return number


def _integer(value: Any) -> int:
    try:
        return int(value)
    except (TypeError, ValueError):
        return 0


def step_payload(time_s: float, step: int, label: str, condition: Mapping[str, Any]) -> bytes:
    """The `hamr_bench.StepCondition` bytes of a `step` event's condition."""
    cls = schemas.message_class(schemas.STEP_SCHEMA, schemas.step_descriptor_set())
    return cls(
        time_s=float(time_s), step=int(step), voltage_V=_number(condition.get("voltage_V")),
        sag_m=_number(condition.get("sag_m")), repetition=_integer(condition.get("repetition")),
        direction=str(condition.get("direction", "")), mode=str(condition.get("mode", "")),
        design=_integer(condition.get("design")), layers=_integer(condition.get("layers")),
        specimen=str(condition.get("specimen", "")), label=str(label),
    ).SerializeToString()
