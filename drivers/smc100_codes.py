"""Protocol facts of the Newport SMC100 controller (manual rev A812B4, `TS` and `TE` commands) kept as data.

The driver decodes replies with these tables and the emulator encodes its state with the same tables, so a
code is written down once. `TS` replies `nnTSabcdef`: `abcd` are 16 error bits in hex, `ef` the controller
state."""

from __future__ import annotations

from dataclasses import dataclass

# State code -> (state family, detail). Families are what a caller branches on; the detail is for messages.
STATE_CODES: dict[int, tuple[str, str]] = {
    0x0A: ("NOT REFERENCED", "from reset"),
    0x0B: ("NOT REFERENCED", "from homing"),
    0x0C: ("NOT REFERENCED", "from configuration"),
    0x0D: ("NOT REFERENCED", "from disable"),
    0x0E: ("NOT REFERENCED", "from ready"),
    0x0F: ("NOT REFERENCED", "from moving"),
    0x10: ("NOT REFERENCED", "stage error"),
    0x11: ("NOT REFERENCED", "from jogging"),
    0x14: ("CONFIGURATION", ""),
    0x1E: ("HOMING", "commanded from RS-232"),
    0x1F: ("HOMING", "commanded by keypad"),
    0x28: ("MOVING", ""),
    0x32: ("READY", "from homing"),
    0x33: ("READY", "from moving"),
    0x34: ("READY", "from disable"),
    0x35: ("READY", "from jogging"),
    0x3C: ("DISABLE", "from ready"),
    0x3D: ("DISABLE", "from moving"),
    0x3E: ("DISABLE", "from jogging"),
    0x46: ("JOGGING", "from ready"),
    0x47: ("JOGGING", "from disable"),
}

# Named codes the emulator uses when it changes state (same numbers as above, named for readability).
NOT_REFERENCED_FROM_RESET = 0x0A
NOT_REFERENCED_FROM_HOMING = 0x0B
NOT_REFERENCED_FROM_CONFIGURATION = 0x0C
NOT_REFERENCED_STAGE_ERROR = 0x10
CONFIGURATION = 0x14
HOMING_RS232 = 0x1E
MOVING = 0x28
READY_FROM_HOMING = 0x32
READY_FROM_MOVING = 0x33
READY_FROM_DISABLE = 0x34
DISABLE_FROM_READY = 0x3C
DISABLE_FROM_MOVING = 0x3D

# Bit number in the 16-bit error field -> meaning. Bits 10-15 are not used by the SMC100PP.
ERROR_BITS: dict[int, str] = {
    0: "negative end of run",
    1: "positive end of run",
    2: "peak current limit",
    3: "RMS current limit",
    4: "short circuit detection",
    5: "following error",
    6: "homing time-out",
    7: "wrong ESP stage",
    8: "DC voltage too low",
    9: "80 W output power exceeded",
}
BIT_NEGATIVE_END_OF_RUN = 0
BIT_POSITIVE_END_OF_RUN = 1
BIT_FOLLOWING_ERROR = 5

# `TE` error letters ('@' = no error). Reading TE clears the stored letter.
ERROR_LETTERS: dict[str, str] = {
    "@": "no error",
    "A": "unknown message code or floating point controller address",
    "B": "controller address not correct",
    "C": "parameter missing or out of range",
    "D": "command not allowed",
    "E": "home sequence already started",
    "F": "ESP stage name unknown",
    "G": "displacement out of limits",
    "H": "command not allowed in NOT REFERENCED state",
    "I": "command not allowed in CONFIGURATION state",
    "J": "command not allowed in DISABLE state",
    "K": "command not allowed in READY state",
    "L": "command not allowed in HOMING state",
    "M": "command not allowed in MOVING state",
    "N": "current position out of software limit",
    "S": "communication time out",
    "U": "error during EEPROM access",
    "V": "error during command execution",
    "W": "command not allowed for PP version",
    "X": "command not allowed for CC version",
}

# The letter a command gets when it arrives in a state that does not accept it.
STATE_REJECTION_LETTER: dict[str, str] = {
    "NOT REFERENCED": "H",
    "CONFIGURATION": "I",
    "DISABLE": "J",
    "READY": "K",
    "HOMING": "L",
    "MOVING": "M",
    "JOGGING": "D",
}


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
