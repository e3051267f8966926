"""The Newport SMC100CC/SMC100PP command set as data, from the user manual rev A812B4 (EDH0206En2054, 06/23,
section 5.5): one row per two-letter command with the controller states it is executed in, what its `?` form
returns, the error letters the manual lists for it, which variant accepts it and whether it may be sent
without an
address; the `TS` state codes and error bits; the `TE` letters with the texts `TB` returns.

Both the driver (`drivers/newport_smc100.py`, `drivers/smc100_codes.py`) and the emulator
(`sim_devices/smc100_protocol.py`) read these tables. The tests in `tests/drivers/test_smc100_protocol.py` and
`tests/sim_devices/test_smc100_reference.py` are written from the manual separately, so a wrong row here fails
them rather than agreeing with itself.

Decisions where the manual is silent or contradicts itself are listed in docs/hardware.md ("SMC100: where the
reference is silent"); the ones that matter most:

- A `?` query is answered in every state (the manual marks only where the *setting* is accepted; public
drivers
  written against real units read `ID?`, `SL?`, `SR?`, `VA?` in NOT REFERENCED and `BA?`, `BH?` outside
  CONFIGURATION).
- A command refused in a state stores that state's letter when the command's error list has it, otherwise `D`
  ("Command not allowed"); `OR` while homing stores `E`.
- `RS` follows its own page (accepted in every state but JOGGING), not the summary table (which leaves out
  CONFIGURATION and MOVING).
"""

from __future__ import annotations

from dataclasses import dataclass, field

# -- states
# ------------------------------------------------------------------------------------------------------
NOT_REFERENCED = "NOT REFERENCED"
CONFIGURATION_STATE = "CONFIGURATION"
DISABLE = "DISABLE"
READY = "READY"
HOMING = "HOMING"
MOVING = "MOVING"
JOGGING = "JOGGING"
FAMILIES: tuple[str, ...] = (NOT_REFERENCED, CONFIGURATION_STATE, DISABLE, READY, HOMING, MOVING, JOGGING)

# `TS` state code -> (family, detail). The detail says where the state was entered from (manual, TS command).
STATE_CODES: dict[int, tuple[str, str]] = {
    0x0A: (NOT_REFERENCED, "from reset"),
    0x0B: (NOT_REFERENCED, "from homing"),
    0x0C: (NOT_REFERENCED, "from configuration"),
    0x0D: (NOT_REFERENCED, "from disable"),
    0x0E: (NOT_REFERENCED, "from ready"),
    0x0F: (NOT_REFERENCED, "from moving"),
    0x10: (NOT_REFERENCED, "ESP stage error"),
    0x11: (NOT_REFERENCED, "from jogging"),
    0x14: (CONFIGURATION_STATE, ""),
    0x1E: (HOMING, "commanded from RS-232"),
    0x1F: (HOMING, "commanded by keypad"),
    0x28: (MOVING, ""),
    0x32: (READY, "from homing"),
    0x33: (READY, "from moving"),
    0x34: (READY, "from disable"),
    0x35: (READY, "from jogging"),
    0x3C: (DISABLE, "from ready"),
    0x3D: (DISABLE, "from moving"),
    0x3E: (DISABLE, "from jogging"),
    0x46: (JOGGING, "from ready"),
    0x47: (JOGGING, "from disable"),
}

# The NOT REFERENCED code the controller falls to when it leaves a state (an end-of-run switch trips, a homing
# search is stopped or times out): "NOT REFERENCED from <family>".
NOT_REFERENCED_FROM: dict[str, int] = {
    NOT_REFERENCED: 0x0A,  # stays where it is; 0A is only the code the emulator starts from
    HOMING: 0x0B,
    CONFIGURATION_STATE: 0x0C,
    DISABLE: 0x0D,
    READY: 0x0E,
    MOVING: 0x0F,
    JOGGING: 0x11,
}

# Bit number in the 16-bit `TS` error field -> meaning. Bits 10-15 are not used.
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
BIT_HOMING_TIME_OUT = 6

# `TE` letters and the texts `TB` returns for them ('@' = no error), as the manual's TE page lists them.
ERROR_TEXTS: dict[str, str] = {
    "@": "No error",
    "A": "Unknown message code or floating point controller address",
    "B": "Controller address not correct",
    "C": "Parameter missing or out of range",
    "D": "Command not allowed",
    "E": "Home sequence already started",
    "F": "ESP stage name unknown",
    "G": "Displacement out of limits",
    "H": "Command not allowed in NOT REFERENCED state",
    "I": "Command not allowed in CONFIGURATION state",
    "J": "Command not allowed in DISABLE state",
    "K": "Command not allowed in READY state",
    "L": "Command not allowed in HOMING state",
    "M": "Command not allowed in MOVING state",
    "N": "Current position out of software limit",
    "S": "Communication Time Out",
    "U": "Error during EEPROM access",
    "V": "Error during command execution",
    "W": "Command not allowed for PP version",
    "X": "Command not allowed for CC version",
}

# The letter that names each state in the error lists ("Execution not allowed in ... state").
STATE_LETTER: dict[str, str] = {
    NOT_REFERENCED: "H",
    CONFIGURATION_STATE: "I",
    DISABLE: "J",
    READY: "K",
    HOMING: "L",
    MOVING: "M",
}

# -- commands
# ----------------------------------------------------------------------------------------------------
_ALL = frozenset(FAMILIES)
_MOTION = frozenset({HOMING, MOVING})  # the manual's "Motion" column
_CFG = frozenset({CONFIGURATION_STATE})
_CFG_DIS_RDY = frozenset({CONFIGURATION_STATE, DISABLE, READY})
_CFG_DIS = frozenset({CONFIGURATION_STATE, DISABLE})

# What a command's `?` form returns.
QUERY_VALUE = "value"  # the current programmed value
QUERY_TARGET = "target"  # the target position
QUERY_STATE = "state"  # 1 when the state the command enters is the present one, else 0


@dataclass(frozen=True)
class CommandSpec:
    """One command of the reference. `states`: where the command itself (a setting, or a command without a
    parameter) is executed. `query`: what `nnXX?` returns, None when it has no `?` form (then a `?` is a
    parameter, or is ignored when the command takes none). `argument`: none | number | integer | text |
    letter.
    `subcommands`: FR and QI take a letter after the name (`1FRM?`, `1QIL0.5`). `letters`: the error letters
    the
    manual lists for the command besides A and B. `variant`: CC, PP or both. `broadcast`: may be sent without
    an
    address (or with 0) to reach every controller on the chain."""

    name: str
    title: str
    states: frozenset[str]
    query: str | None
    argument: str
    letters: str
    variant: str = "both"
    broadcast: bool = False
    subcommands: str = ""
    refusal_overrides: dict[str, str] = field(default_factory=dict)

    def refusal_letter(self, family: str) -> str:
        """The TE letter stored when this command arrives in `family`, a state it is not executed in."""
        if family in self.refusal_overrides:
            return self.refusal_overrides[family]
        letter = STATE_LETTER.get(family)
        return letter if letter is not None and letter in self.letters else "D"


def _spec(name: str, title: str, states: frozenset[str], query: str | None, argument: str, letters: str,
          **more: object) -> tuple[str, CommandSpec]:
    return name, CommandSpec(name, title, states, query, argument, letters, **more)  # type: ignore[arg-type]


COMMANDS: dict[str, CommandSpec] = dict([
    _spec("AC", "set/get acceleration", _CFG_DIS_RDY, QUERY_VALUE, "number", "CDHLM"),
    _spec("BA", "set/get backlash compensation", _CFG, QUERY_VALUE, "number", "CDHJKLM"),
    _spec("BH", "set/get hysteresis compensation", _CFG, QUERY_VALUE, "number", "CDHJKLM"),
    _spec("DV", "set/get driver voltage", _CFG, QUERY_VALUE, "number", "CDHJKLM", variant="CC"),
    _spec("FD", "set/get low-pass filter for Kd", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("FE", "set/get following error limit", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("FF", "set/get friction compensation", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("FR", "set/get stepper motor configuration", _CFG, QUERY_VALUE, "number", "CDHJKLMX", variant="PP",
          subcommands="MS"),
    _spec("HT", "set/get HOME search type", _CFG, QUERY_VALUE, "integer", "CDHJKLM"),
    _spec("ID", "set/get stage identifier", _CFG, QUERY_VALUE, "text", "CDHJKLM"),
    _spec("JD", "leave JOGGING state", frozenset({JOGGING}), None, "none", "DHIJKLM"),
    # JM's page lists A for a value out of range and B for a missing one; there is no C in its list.
    _spec("JM", "enable/disable keypad", _CFG_DIS_RDY, QUERY_VALUE, "integer", "DHLM"),
    _spec("JR", "set/get jerk time", _CFG_DIS_RDY, QUERY_VALUE, "number", "CDHLM"),
    _spec("KD", "set/get derivative gain", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("KI", "set/get integral gain", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("KP", "set/get proportional gain", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("KV", "set/get velocity feed forward", _CFG_DIS, QUERY_VALUE, "number", "CDHKLMW", variant="CC"),
    _spec("MM", "enter/leave DISABLE state", frozenset({DISABLE, READY}), QUERY_STATE, "integer", "CDHILM",
          broadcast=True),
    _spec("OH", "set/get HOME search velocity", _CFG, QUERY_VALUE, "number", "CDHJKLM"),
    _spec("OR", "execute HOME search", frozenset({NOT_REFERENCED}), None, "none", "CDEIJKLM",
          refusal_overrides={HOMING: "E"}),
    _spec("OT", "set/get HOME search time-out", _CFG, QUERY_VALUE, "number", "CDHJKLM"),
    _spec("PA", "move absolute", frozenset({READY}), QUERY_TARGET, "number", "CDGHIJ"),
    _spec("PR", "move relative", frozenset({READY}), QUERY_TARGET, "number", "CDGHIJ"),
    _spec("PT", "get motion time for a relative move", frozenset({DISABLE, READY}) | _MOTION, None, "number",
          "CDHI"),
    _spec("PW", "enter/leave CONFIGURATION state", frozenset({NOT_REFERENCED, CONFIGURATION_STATE}),
          QUERY_STATE,
          "integer", "CDJKLM"),
    _spec("QI", "set/get motor current limits", _CFG, QUERY_VALUE, "number", "CDHJKLM", subcommands="LRT"),
    _spec("RA", "get analog input value", _ALL, None, "none", "DHI"),
    _spec("RB", "get TTL input value", _ALL, None, "none", "DHI"),
    _spec("RS", "reset controller", _ALL - {JOGGING}, None, "none", "DHILM"),
    _spec("SA", "set/get RS-485 address", _CFG, QUERY_VALUE, "integer", "CDHJKLM"),
    _spec("SB", "set/get TTL output value", frozenset({DISABLE, READY, JOGGING}) | _MOTION, QUERY_VALUE,
          "integer",
          "CDHI"),
    _spec("SC", "set/get control loop state", _CFG, QUERY_VALUE, "integer", "CDHJKLMW", variant="CC"),
    _spec("SE", "configure/execute simultaneous started move", frozenset({READY}), QUERY_TARGET, "number",
          "CDHIJLM", broadcast=True),
    _spec("SL", "set/get negative software limit", _CFG_DIS_RDY, QUERY_VALUE, "number", "CDHLM"),
    _spec("SR", "set/get positive software limit", _CFG_DIS_RDY, QUERY_VALUE, "number", "CDHLM"),
    _spec("ST", "stop motion", frozenset({DISABLE, READY}) | _MOTION, None, "none", "DHI", broadcast=True),
    _spec("SU", "set/get encoder increment value", _CFG, QUERY_VALUE, "number", "CDHJKLMW", variant="CC"),
    _spec("TB", "get command error string", _ALL, None, "letter", "CD"),
    _spec("TE", "get last command error", _ALL - {JOGGING}, None, "none", "D"),
    _spec("TH", "get set-point position", _ALL, None, "none", "DHI"),
    _spec("TP", "get current position", _ALL, None, "none", "DHI"),
    _spec("TS", "get positioner error and controller state", _ALL, None, "none", ""),
    _spec("VA", "set/get velocity", _CFG_DIS_RDY, QUERY_VALUE, "number", "CDHLM"),
    _spec("VB", "set/get base velocity", _CFG_DIS_RDY, QUERY_VALUE, "number", "CDHLMX", variant="PP"),
    _spec("VE", "get controller revision information", _ALL, None, "none", ""),
    _spec("ZT", "get all configuration parameters", _ALL - {JOGGING}, None, "none", ""),
    _spec("ZX", "set/get ESP stage configuration", _CFG, QUERY_VALUE, "integer", "CDHJKLM"),
])

# Settings `ZT` lists on a PP controller, in the order of the manual's example (alphabetical). (A CC lists its
# servo settings instead of FRM, FRS and VB; this project has no CC to emulate.)
ZT_PARAMETERS_PP: tuple[str, ...] = ("AC", "BA", "BH", "FRM", "FRS", "HT", "JM", "JR", "OH", "OT", "QIL",
                                     "QIR",
                                     "QIT", "SA", "SL", "SR", "VA", "VB", "ZX")


def accepts(spec: CommandSpec, variant: str) -> bool:
    """Whether a controller of `variant` (CC or PP) knows the command (else it stores W or X)."""
    return spec.variant in ("both", variant)


def variant_letter(variant: str) -> str:
    """The letter a command meant for the other variant stores: W on a PP, X on a CC."""
    return "W" if variant == "PP" else "X"
