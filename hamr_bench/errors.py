"""The error types every part of hamr-bench raises, so the command line can turn any of them into one line.

A `HamrBenchError` carries a message written for the person at the bench: it names the file, field, device or
value at fault. The CLI prints `hamr-bench: error: <message>` and exits non-zero; it never shows a traceback for
these. Anything that is not a `HamrBenchError` is a bug and keeps its traceback.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from hamr_bench.interfaces import ForceSample


class HamrBenchError(Exception):
    """Base of every expected failure: the message is complete on one line."""


class ConfigError(HamrBenchError):
    """A rig, protocol, parameter or CSV file (or a command-line value) is malformed or out of range."""


class ModelError(HamrBenchError):
    """A model parameter is physically impossible (negative thickness, a linkage that cannot close, ...)."""


class SafetyLimitError(HamrBenchError):
    """A command would take the rig past a configured limit (voltage, slew, stage travel, force)."""


class DeviceError(HamrBenchError):
    """A device misbehaved. `device` names it (e.g. 'stage', 'force_sensor')."""

    def __init__(self, message: str, device: str = "device") -> None:
        super().__init__(message)
        self.device = device
        # Good force readings taken in the same batch before the error (a force sensor driver fills it), so the
        # runner records them instead of losing them.
        self.samples_before: list[ForceSample] = []


class DeviceTimeout(DeviceError):
    """A device did not answer within the driver's timeout."""


class DeviceProtocolError(DeviceError):
    """A device answered with bytes the driver cannot parse (garbage, dropped bytes, wrong echo)."""


class DeviceFault(DeviceError):
    """A device reported a fault state (stage error, amplifier trip, sensor overload, disconnect)."""


class RecordingError(HamrBenchError):
    """A recording cannot be written, read or recovered."""
