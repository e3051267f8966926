"""The Loadstar Sensors command sets as data, per interface family, from Loadstar's published pages: "DI-100U
&
DI-1000U command set" (loadstarsensors.com/di-100u-di-1000u-command-set.html), "Basic command set for iLoad
digital
sensors" (loadstarsensors.com/basic-command-set-for-iload-digital-sensors.html), "Writing your own software"
(loadstarsensors.com/writingsoftware.html) and the DI-1000HS-1K output formats page. One row per role: every
spelling the firmware accepts, what it answers, and where the fact comes from. The driver
(`drivers/loadstar.py`) sends the first spelling of a row; the emulator (`sim_devices/loadstar_emulator.py`)
accepts
all of them.

Commands end with CR; replies end with CR LF; a CR alone answers `A`. Commands are case-insensitive (the
HS-1K page
says so; a published client sends lower case); that the iLoad firmware is too is UNVERIFIED. What a sensor
answers to
a command it does not know is not published: the emulator stays silent (UNVERIFIED)."""

from __future__ import annotations

from dataclasses import dataclass

# Newtons per unit a sensor reports in (exact definitions of the pound-force, kilogram-force and ounce-force).
NEWTONS_PER_UNIT: dict[str, float] = {
    "LB": 4.4482216152605,
    "LBF": 4.4482216152605,
    "MLB": 4.4482216152605e-3,
    "KG": 9.80665,
    "KGF": 9.80665,
    "G": 9.80665e-3,
    "N": 1.0,
    "KN": 1e3,
    "OZ": 4.4482216152605 / 16,
}


@dataclass(frozen=True)
class Role:
    """One thing the interface does: the spellings it accepts (the first is the one to send), the reply, and
    the
    source. `reply` is a description for the docs, not a literal."""

    spellings: tuple[str, ...]
    reply: str
    source: str


@dataclass(frozen=True)
class Family:
    """One interface family. `reading_unit`/`capacity_unit` None: the unit UNITS reports. `tare_replies`:
    what the
    firmware answers to a tare (the first is what the page documents)."""

    name: str
    title: str
    roles: dict[str, Role]
    tare_replies: tuple[str, ...]
    reading_unit: str | None
    capacity_unit: str | None
    model_reply: str

    def command(self, role: str) -> str | None:
        """The spelling to send for `role`, None when the family has no such command."""
        found = self.roles.get(role)
        return found.spellings[0] if found else None


_DI_PAGE = "DI-100U & DI-1000U command set page"
_ILOAD_PAGE = "iLoad basic command set page"

FAMILIES: dict[str, Family] = {
    "di1000": Family(
        name="di1000",
        title="DI-100U / DI-1000U load cell interface",
        roles={
            "ready": Role(("",), "A", _DI_PAGE + " (send CR twice, the second answers A)"),
            "model": Role(("MODEL",), "FCM DI-1000 (FCM DI-100 on a DI-100)", _DI_PAGE),
            "identify": Role(("ID",), "unique identifier, up to 16 characters (e.g. W1234-5678)", _DI_PAGE),
            # UNIT: the spelling the published Python client (loadstar-sensors-interface, written and tested
            # against a DI-1000 family unit) sends; not on Loadstar's page: UNVERIFIED.
            "units": Role(("UNITS", "UNIT"), "the calibrated units (e.g. LB, KG, N)",
                          _DI_PAGE + "; UNIT: loadstar-sensors-interface 2.1.1"),
            "capacity": Role(("LC",), "the capacity, in the calibrated units", _DI_PAGE),
            "tare": Role(("CT0", "TARE"), "Tared", _DI_PAGE),
            "read": Role(("W",), "one reading in the calibrated units (e.g. 3.04)", _DI_PAGE),
            "stream": Role(("WC",), "readings until a CR arrives (~150 Hz; ~575 Hz on HS interfaces)",
                           _DI_PAGE + "; DI-1000HS-1K output formats page"),
        },
        # "A": the published client's first release expected A after a tare on its DI unit (later both).
        tare_replies=("Tared", "A"),
        reading_unit=None,
        capacity_unit=None,
        model_reply="FCM DI-1000",
    ),
    "iload": Family(
        name="iload",
        title="iLoad digital sensors (iLoad, iLoad Pro, iLoad TR) and DQ-1000U",
        roles={
            "ready": Role(("",), "A", _ILOAD_PAGE),
            # SS0: in the older LoadVUE user guide only (model number): UNVERIFIED on current firmware.
            "model": Role(("SS0",), "the model number", "LoadVUE user guide, basic command set"),
            "identify": Role(("SS1",), "the factory ID of the sensor", _ILOAD_PAGE),
            "capacity": Role(("SLC",), "the capacity in lb (a floating point number)", _ILOAD_PAGE),
            "tare": Role(("CT0",), "A", _ILOAD_PAGE + "; writing-software page (wait for the A)"),
            # W: "not supported in all firmware versions", so the driver sends O0W1.
            "read": Role(("O0W1", "W"), "one reading in millipounds (e.g. 2345 = 2.345 lb)", _ILOAD_PAGE),
            "stream": Role(("O0W0",), "readings in millipounds until a CR arrives", _ILOAD_PAGE),
        },
        tare_replies=("A",),
        reading_unit="MLB",
        capacity_unit="LB",
        model_reply="ILOAD",  # UNVERIFIED: no published example of the SS0 reply
    ),
}

# Spellings some firmware versions of a family do not accept (the emulator can be set to refuse them).
OPTIONAL_SPELLINGS: dict[str, tuple[str, ...]] = {"iload": ("W",), "di1000": ("UNIT",)}
