"""Recorded serial traffic as byte-exact driver tests (PyMeasure's `expected_protocol`, from a recording
instead of a
manual): a run made with `--record-traffic` holds every byte a driver wrote and read on `/traffic/<device>`;
`export_driver_test` turns one device's conversation into a JSON file of driver calls, each with the (sent,
reply)
exchanges it made; `replay_driver_test` makes the same calls on the real driver over a scripted port that
checks every
byte written and serves every reply from the file.

The calls are read back from the bytes with each driver's own vocabulary (the first command of a call names
the
method, its argument the value; polls that belong to a call are counted by the driver's own rule of when to
stop),
so a contributed file needs no notes beside it. A call that raised in the recorded run (a rejected command, a
fault)
raises again on replay: what the test checks is the bytes."""

from __future__ import annotations

import json
import re
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from drivers import smc100_codes
from drivers.loadstar import LoadstarSensor
from drivers.newport_smc100 import NewportSMC100
from drivers.testing import Exchange, expected_protocol
from hamr_bench.errors import DeviceError, RecordingError, SafetyLimitError

FORMAT = "hamr-bench driver traffic 1"
_SMC = re.compile(rb"^(\d+)([A-Z]{2})(.*)\r\n$")


@dataclass
class Call:
    """One driver method call and the exchanges it made."""

    method: str
    args: list[Any] = field(default_factory=list)
    exchanges: list[Exchange] = field(default_factory=list)


def exchanges_from_traffic(items: Sequence[Any]) -> tuple[list[Exchange], list[float]]:
    """tx/rx records -> (sent, reply) pairs, each write with every byte read after it until the next write
    (bytes
    read before the first write: `sent` None), and the time of each write from the first (s, rig clock)."""
    exchanges: list[tuple[bytes | None, bytearray]] = []
    times: list[float] = []
    for item in items:
        if item.direction == "tx":
            exchanges.append((bytes(item.data), bytearray()))
            times.append(float(item.time_s))
        elif not exchanges:
            exchanges.append((None, bytearray(item.data)))
            times.append(float(item.time_s))
        else:
            exchanges[-1][1].extend(item.data)
    start = times[0] if times else 0.0
    pairs: list[Exchange] = [(sent, bytes(reply) if reply else None) for sent, reply in exchanges]
    return pairs, [round(t - start, 9) for t in times]


# -- SMC100
# -------------------------------------------------------------------------------------------------------
def _smc(sent: bytes | None) -> tuple[str, str]:
    match = _SMC.match(sent or b"")
    return (match.group(2).decode(), match.group(3).decode()) if match else ("", "")


def _polls_until_settled(exchanges: Sequence[Exchange], start: int) -> int:
    """Index after the TS polls a motion call makes: the driver stops at the first reply that is READY, has
    an error
    bit, is neither READY nor in motion, or is not a TS reply at all."""
    i = start
    while i < len(exchanges) and _smc(exchanges[i][0])[0] == "TS":
        reply = (exchanges[i][1] or b"").strip()
        i += 1
        try:
            status = smc100_codes.parse_status(reply.decode("ascii")[reply.find(b"TS") + 2:])
        except (ValueError, UnicodeDecodeError):
            return i
        if status.error_bits or not status.is_moving:
            return i
    return i


def _smc100_motion_call(ex: Sequence[Exchange], i: int) -> tuple[str, list[Any], int] | None:
    """The calls that span several exchanges (home, moves, reset, limits), or None."""
    code, arg = _smc(ex[i][0])
    nxt = _smc(ex[i + 1][0])[0] if i + 1 < len(ex) else ""
    mm = 1e-3
    if code == "TS" and nxt == "OR":
        return "home", [], _polls_until_settled(ex, i + 3)
    if code == "TP" and nxt == "PR":
        return "move_by", [float(_smc(ex[i + 1][0])[1]) * mm], _polls_until_settled(ex, i + 3)
    if code == "PA":
        return "move_to", [float(arg) * mm], _polls_until_settled(ex, i + 2)
    if code == "RS":
        end = i + 1
        while end < len(ex) and _smc(ex[end][0])[0] == "TS" and ex[end][1] is None:
            end += 1  # polls the rebooting controller does not answer
        end += 1  # the first answer
        return "reset", [], end + 2 if end < len(ex) and _smc(ex[end][0]) == ("SL", "?") else end
    if code == "SL" and arg == "?":
        return "soft_limits_m", [], i + 2
    if code == "SL":
        return "set_soft_limits", [float(arg) * mm, float(_smc(ex[i + 2][0])[1]) * mm], i + 4
    return None


def _smc100_call(ex: Sequence[Exchange], i: int) -> tuple[str, list[Any], int]:
    """(method, args, index after the call) for the call that starts at exchange `i`."""
    motion = _smc100_motion_call(ex, i)
    if motion is not None:
        return motion
    code, arg = _smc(ex[i][0])
    mm = 1e-3
    if code == "VE":
        return "identify", [], i + 2
    simple = {"TS": "status", "TP": "position_m", "TE": "error_letter", "VA?": "velocity_m_per_s",
              "AC?": "acceleration_m_per_s2", "ST": "stop", "MM1": "enable", "MM0": "disable"}
    key = code + arg if arg in ("?", "0", "1") and code in ("VA", "AC", "MM") else code
    if key in simple:
        return simple[key], [], i + (2 if key in ("ST", "MM1", "MM0") else 1)
    if code in ("VA", "AC"):
        method = "set_velocity" if code == "VA" else "set_acceleration"
        return method, [float(arg) * mm], i + 2
    if code == "PT":
        return "motion_time_s", [float(arg) * mm], i + 1
    raise RecordingError(f"no SMC100 driver call starts with {ex[i][0]!r} (exchange {i})")


def smc100_calls(exchanges: Sequence[Exchange]) -> tuple[dict[str, Any], list[Call]]:
    """Settings to open the driver with, and its calls, from an SMC100 conversation."""
    if not exchanges:
        raise RecordingError("the SMC100 conversation is empty")
    match = _SMC.match(exchanges[0][0] or b"")
    address = int(match.group(1)) if match else 1
    reads_limits = len(exchanges) >= 2 and [_smc(s) for s, _ in exchanges[:2]] == [("SL", "?"), ("SR", "?")]
    # Without SL?/SR? at the start the run configured its limits: any that hold every recorded target will do.
    settings: dict[str, Any] = {"address": address, "limits_m": None if reads_limits else [-1.0, 1.0]}
    calls = [Call("open", [], list(exchanges[:2]))] if reads_limits else []
    i = 2 if reads_limits else 0
    while i < len(exchanges):
        method, args, end = _smc100_call(exchanges, i)
        calls.append(Call(method, args, list(exchanges[i:end])))
        i = end
    return settings, calls


# -- Loadstar
# -----------------------------------------------------------------------------------------------------
_STREAM = {b"WC\r", b"O0W0\r"}
_READ = {b"W\r", b"O0W1\r"}
_TARE = {b"CT0\r", b"TARE\r"}


def loadstar_calls(exchanges: Sequence[Exchange]) -> tuple[dict[str, Any], list[Call]]:
    """Settings and calls of a Loadstar conversation: the open (CR, drain, CR -> A, units, capacity), readings,
    identify, and streams (start, everything streamed, stop). The driver tares with readings, so its tares replay
    as readings; a sensor tare (CT0) was sent by an earlier driver, whose conversation this one cannot make."""
    sent = [s for s, _ in exchanges]
    family = "iload" if b"SLC\r" in sent or b"O0W1\r" in sent else "di1000"
    open_length = next((k + 1 for k, s in enumerate(sent) if s in (b"LC\r", b"SLC\r")), 0)
    if open_length == 0:
        message = "no capacity query (LC or SLC): the conversation does not start with the driver's open"
        raise RecordingError(message)
    calls = [Call("open", [], list(exchanges[:open_length]))]
    i = open_length
    while i < len(exchanges):
        s = sent[i]
        if s in _TARE:
            message = (f"exchange {i} is a sensor tare ({s!r}): recorded with a driver that tared in the sensor; "
                       "this one keeps the zero itself and sends readings instead (re-record the run)")
            raise RecordingError(message)
        if s in _READ:
            calls.append(Call("read_N", [], [exchanges[i]]))
            i += 1
        elif s in _STREAM:
            calls.append(Call("start_stream", [], [exchanges[i]]))
            calls.append(Call("read_stream", [], []))
            calls.append(Call("stop_stream", [], list(exchanges[i + 1:i + 3])))
            i += 3
        elif s in (b"MODEL\r", b"SS0\r"):
            calls.append(Call("identify", [], list(exchanges[i:i + 2])))
            i += 2
        elif s in (b"UNITS\r", b"UNIT\r"):
            calls.append(Call("units", [], [exchanges[i]]))
            i += 1
        else:
            raise RecordingError(f"no Loadstar driver call starts with {s!r} (exchange {i})")
    return {"command_set": family}, calls


DRIVERS = {"smc100": (NewportSMC100, smc100_calls), "loadstar": (LoadstarSensor, loadstar_calls)}


def _text(data: bytes | None) -> str | None:
    return None if data is None else data.decode("latin-1")


def _bytes(text: str | None) -> bytes | None:
    return None if text is None else text.encode("latin-1")


def export_driver_test(items: Sequence[Any], driver: str, device: str, source: str, out: Path) -> int:
    """Write one device's recorded conversation as a driver test file; returns the number of calls."""
    if driver not in DRIVERS:
        raise RecordingError(f"driver {driver!r}: expected one of {', '.join(DRIVERS)}")
    exchanges, times = exchanges_from_traffic(items)
    settings, calls = DRIVERS[driver][1](exchanges)
    clock = iter(times)
    document = {
        "format": FORMAT, "driver": driver, "device": device, "source": source, "settings": settings,
        # Settings of the emulator that reproduce the recorded device, for the check of the emulator against
        # this
        # file (a lab fills in what it knows of its stage or sensor; see docs/hardware.md).
        "emulator": {},
        "calls": [{"method": c.method, "args": c.args,
                   "exchanges": [[_text(s), _text(r), next(clock)] for s, r in c.exchanges]} for c in calls],
    }
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(document, indent=1) + "\n")
    return len(calls)


@dataclass
class DriverTest:
    """A driver test file, read back."""

    path: Path
    driver: str
    settings: dict[str, Any]
    calls: list[Call]
    times_s: list[float]  # of each exchange's write, from the first
    emulator: dict[str, Any]

    @property
    def exchanges(self) -> list[Exchange]:
        return [exchange for call in self.calls for exchange in call.exchanges]


def load_driver_test(path: Path) -> DriverTest:
    document = json.loads(path.read_text())
    if document.get("format") != FORMAT or document.get("driver") not in DRIVERS:
        raise RecordingError(f"{path}: not a driver traffic file ({FORMAT!r} for {', '.join(DRIVERS)})")
    calls = [Call(c["method"], list(c["args"]), [(_bytes(e[0]), _bytes(e[1])) for e in c["exchanges"]])
             for c in document["calls"]]
    times = [float(e[2]) for c in document["calls"] for e in c["exchanges"]]
    return DriverTest(path, document["driver"], dict(document["settings"]), calls, times,
                      dict(document.get("emulator", {})))


def replay_driver_test(test: DriverTest) -> Iterator[tuple[Call, BaseException | None]]:
    """Make every recorded call on the real driver over a scripted port serving the file's exchanges; yields
    each
    call with the typed error it raised (None: it returned). A byte the driver writes that the file does not
    hold
    raises AssertionError at once; leaving recorded writes unsent fails at the end."""
    driver_class = DRIVERS[test.driver][0]
    settings = {key: value for key, value in test.settings.items() if value is not None}
    if "limits_m" in settings:
        settings["limits_m"] = tuple(settings["limits_m"])
    with expected_protocol(driver_class, test.exchanges, **settings) as driver:
        for call in test.calls:
            if call.method == "open":
                yield call, None
                continue
            try:
                getattr(driver, call.method)(*call.args)
            except (DeviceError, SafetyLimitError) as exc:
                yield call, exc
            else:
                yield call, None
