"""Decoding the Newport SMC100's `TS` and `TE` replies for the driver. The facts themselves (state codes,
error
bits, error letters and texts, the command table) are in `hamr_bench.instruments.smc100_reference`, which the
emulator reads too; this module turns a reply into a typed status and says what it means. `TS` replies
`nnTSabcdef`: `abcd` are 16 error bits in hex, `ef` the controller state."""

from __future__ import annotations

from dataclasses import dataclass

from hamr_bench.instruments.smc100_reference import ERROR_BITS, ERROR_TEXTS, STATE_CODES

# `TE` letter -> the text `TB` gives for it ('@' = no error).
ERROR_LETTERS: dict[str, str] = ERROR_TEXTS

__all__ = ["ERROR_BITS", "ERROR_LETTERS", "STATE_CODES", "Smc100Status", "decode_error_bits", "encode_status",
           "parse_status"]


@dataclass(frozen=True)
class Smc100Status:
    """A decoded `TS` reply."""

    raw: str
    state_code: int
    error_bits: int

    @property
    def state(self) -> str:
        return STATE_CODES.get(self.state_code, ("UNKNOWN", ""))[0]

    @property
    def state_detail(self) -> str:
        return STATE_CODES.get(self.state_code, ("UNKNOWN", f"code {self.state_code:02X}"))[1]

    @property
    def errors(self) -> tuple[str, ...]:
        return decode_error_bits(self.error_bits)

    @property
    def is_ready(self) -> bool:
        return self.state == "READY"

    @property
    def is_moving(self) -> bool:
        return self.state in ("MOVING", "HOMING", "JOGGING")

    def describe(self) -> str:
        detail = f" ({self.state_detail})" if self.state_detail else ""
        errors = f", errors: {', '.join(self.errors)}" if self.errors else ""
        return f"{self.state}{detail} [TS {self.raw}]{errors}"


def decode_error_bits(bits: int) -> tuple[str, ...]:
    return tuple(ERROR_BITS.get(b, f"undocumented bit {b}") for b in range(16) if bits >> b & 1)


def parse_status(value: str) -> Smc100Status:
    """Decode the six hex digits after `nnTS`. Raises ValueError when they are not six hex digits or the state
    code is not one the manual lists."""
    if len(value) != 6:
        raise ValueError(f"TS value {value!r} is not 6 hex digits")
    bits = int(value[:4], 16)
    state = int(value[4:], 16)
    if state not in STATE_CODES:
        raise ValueError(f"TS state code {value[4:]!r} is not in the manual's table")
    return Smc100Status(raw=value, state_code=state, error_bits=bits)


def encode_status(state_code: int, error_bits: int) -> str:
    return f"{error_bits:04X}{state_code:02X}"
