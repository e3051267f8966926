"""Shared by the reliability tests and `benchmarks/reliability_campaign.py`: run a protocol through the real command
line (`hamr_bench.cli.main`) on the simulated bench, keep hold of the simulated bench the run used, and measure from
the emulators (not from what the runner says about itself) whether and when the rig reached its safe state.

What the emulators tell us, independently of the runner's own events:
- the DAQ analog outputs (`SimDaq.ao_value_V`) are what the amplifier drivers actually commanded; x gain = HV;
- the SMC100 emulator's motion history says when the carriage last moved (`_Motion.t_end`).
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from unittest import mock

import numpy as np

from hamr_bench.cli import main
from hamr_bench.protocols import PROTOCOLS, session
from hamr_bench.protocols.runner import STAGE_CHECK_INTERVAL_S as STAGE_CHECK_S
from sim_devices.faults import (
    AMPLIFIER_FAULTS,
    CAMERA_FAULTS,
    FORCE_SENSOR_FAULTS,
    SERIAL_FAULTS,
    STAGE_FAULTS,
)

# Short versions of each protocol (a few virtual seconds each) so a full fault matrix fits in a test run.
SHORT_SETTINGS: dict[str, list[str]] = {
    "actuator": ["voltages_V=250", "repetitions=1", "drive.cycles=1"],
    "blocked-force": ["voltages_V=250", "repetitions=1", "drive.cycles=1"],
    "sag-sweep": ["sags_m=0,0.001", "repetitions=1", "drive.cycles=1"],
    "free-displacement": ["voltages_V=100,250", "repetitions=1", "drive.cycles=1"],
    "static": ["max_sag_m=0.001", "hold_s=0.2", "settle_s=0.1"],
}
PROTOCOL_NAMES: tuple[str, ...] = tuple(PROTOCOLS)

# Every fault each emulator can inject, by --fault target (the emulators' own vocabularies, sim_devices/faults.py).
FAULTS_BY_TARGET: dict[str, tuple[str, ...]] = {
    "stage": SERIAL_FAULTS + STAGE_FAULTS,
    "force_sensor": SERIAL_FAULTS + FORCE_SENSOR_FAULTS,
    "daq": AMPLIFIER_FAULTS,
    "camera": CAMERA_FAULTS,
}
ALL_FAULTS: tuple[str, ...] = tuple(f"{t}:{n}" for t, names in FAULTS_BY_TARGET.items() for n in names)

REPO = Path(__file__).resolve().parents[2]
AO_CHANNELS = {"bias": "ao0", "drive": "ao1"}  # sim_devices/bench.py wiring
# "0 V" on a DAQ output: exactly what was written, up to the float residue of a ramp's last step (~1e-11 V).
ZERO_DAQ_V = 1e-9


@dataclass
class CliRun:
    code: int
    stderr: str
    out: Path
    bench: Any  # the SimBench the run used (closed, but its emulators keep their state)
    end_s: float  # the rig clock when the command returned
    calls: dict[str, list[float]] = field(default_factory=dict)  # device -> rig times the run called it

    @property
    def stderr_lines(self) -> list[str]:
        return [line for line in self.stderr.splitlines() if line.strip()]


def run_cli(protocol: str, out: Path, *, faults: tuple[str, ...] = (), seed: int = 0,
            settings: list[str] | None = None, extra: list[str] | None = None, rig: Path | None = None) -> CliRun:
    """`hamr-bench run PROTOCOL --sim --quiet` (or `--rig RIG` for a simulated rig file) in this process,
    capturing stderr and the simulated bench."""
    captured: list[Any] = []
    real_load_rig = session.load_rig

    calls: dict[str, list[float]] = {"daq": [], "camera": []}

    def capture(*args: Any, **kwargs: Any) -> Any:
        rig = real_load_rig(*args, **kwargs)
        captured.append(rig)
        bench: Any = rig.bench  # the simulated bench itself (its emulators), beyond the backend surface
        if bench is not None:  # log when the run talks to the devices that can sit idle for long
            for method in ("read_ai", "write_ao_scalar", "write_ao_waveform", "wait_ao_done", "stop_ao",
                           "start_ai_stream", "read_ai_stream"):
                _log_calls(bench.daq, method, calls["daq"], bench.clock)
            _log_calls(bench.camera, "grab", calls["camera"], bench.clock)
        return rig

    where = ["--rig", str(rig)] if rig is not None else ["--sim"]
    argv = ["run", protocol, *where, "--quiet", "--seed", str(seed), "--out", str(out)]
    for item in (SHORT_SETTINGS[protocol] if settings is None else settings):
        argv += ["--set", item]
    for fault in faults:
        argv += ["--fault", fault]
    argv += list(extra or [])
    err = io.StringIO()
    with mock.patch.object(session, "load_rig", capture), contextlib.redirect_stderr(err):
        code = main(argv)
    bench = captured[0].bench if captured else None
    return CliRun(code, err.getvalue(), out, bench, bench.clock.now_s() if bench else math.nan, calls)


def _log_calls(obj: Any, name: str, log: list[float], clock: Any) -> None:
    real = getattr(obj, name)

    def logged(*args: Any, **kwargs: Any) -> Any:
        log.append(clock.now_s())
        return real(*args, **kwargs)

    setattr(obj, name, logged)


@dataclass(frozen=True)
class SafeMeasure:
    """When the emulated hardware reached its safe state, on the rig clock."""

    zero_V_at_s: dict[str, float]  # channel -> time from which the DAQ output stays at 0 V (inf: never)
    hv_below_1V_at_s: dict[str, float]  # channel -> time from which the amplifier output stays below 1 V
    stage_still_at_s: float  # end of the carriage's last motion
    end_s: float
    peak_hv_V: dict[str, float] = field(default_factory=dict)


def _settled_from(times_s: np.ndarray, ok: np.ndarray) -> float:
    """The first time from which `ok` holds for every later sample (inf if not at the last one)."""
    if not ok[-1]:
        return math.inf
    bad = np.flatnonzero(~ok)
    return float(times_s[0] if bad.size == 0 else times_s[min(bad[-1] + 1, len(times_s) - 1)])


def measure_safe(bench: Any, since_s: float, end_s: float, dt_s: float = 1e-4) -> SafeMeasure:
    """Look at the emulators between `since_s` and `end_s`: DAQ outputs, amplifier outputs, stage motion."""
    since_s = max(since_s, end_s - 50.0)  # the DAQ keeps 60 s of output history
    times = np.append(np.arange(since_s, end_s, dt_s), end_s)
    zero_at, hv_at, peak = {}, {}, {}
    for name, channel in AO_CHANNELS.items():
        ao = np.array([bench.daq.ao_value_V(channel, float(t)) for t in times])
        hv = np.asarray(bench.daq.output_voltage_V(channel, times), dtype=float)
        zero_at[name] = _settled_from(times, np.abs(ao) < ZERO_DAQ_V)
        hv_at[name] = _settled_from(times, np.abs(hv) < 1.0)
        peak[name] = float(np.max(np.abs(hv)))
    motion = bench.stage._history[-1]
    return SafeMeasure(zero_at, hv_at, float(max(motion.t_end, motion.t0)), end_s, peak)


def fault_time_s(spec: str) -> float:
    return float(spec.rsplit("@", 1)[1]) if "@" in spec else 0.0


# A sensor sample is timed when the sensor takes it, then crosses the wire (a Loadstar line at 9600 baud: ~10 ms)
# and waits for the runner's next poll (20 ms). A fault that cuts the link (disconnect, line noise) loses what was
# still on its way: samples up to this old never reached the computer. Anything older must be in the recording.
IN_TRANSIT_S = 0.03
DRIVER_DATED_TOPICS = ("/force",)
# A force sensor whose port goes away (USB pulled) takes with it the lines the runner had not read yet. The runner
# reads the stream every 20 ms poll, but not while a stage move blocks: one safe step (0.25 mm at 5 mm/s = 50 ms,
# plus acceleration) and the driver's 50 ms TS polls. Samples up to this old may be lost on a disconnect.
LINK_LOSS_BOUND_S = 0.2

_MOMENTS: dict[str, dict[str, float]] = {}


def fault_moments(protocol: str, tmp_factory: Any) -> dict[str, float]:
    """The two moments the matrix injects faults at, read off a run of the short protocol (cached per process):
    'search' halfway through the contact search (free-displacement, which has none: its first moves), 'drive' 0.3 s
    into the first drive (static: into its second loading step). Read off a run rather than written down, because
    every change to a protocol, a driver's exchanges or the bench moves these moments (a fault meant for the drive
    then lands between steps and goes unnoticed)."""
    if protocol in _MOMENTS:
        return _MOMENTS[protocol]
    from hamr_bench.recording import RecordingReader

    out = tmp_factory.mktemp("moments") / f"{protocol}.mcap"
    run_cli(protocol, out)
    events = RecordingReader(out).events()
    first: dict[str, float] = {}
    for event in events:
        first.setdefault(event.kind, event.time_s)
    steps = [e.time_s for e in events if e.kind == "step"]
    search = (first["tare"] + first["contact_found"]) / 2 if "contact_found" in first else first["home"] + 0.1
    drive = (steps[1] if protocol == "static" else first["drive_start"]) + 0.3
    _MOMENTS[protocol] = {"search": round(search, 3), "drive": round(drive, 3)}
    return _MOMENTS[protocol]


def phase_at(events: list, at_s: float) -> str:
    """'search' before contact is found (or before the first step), 'drive' inside a drive or a loading step."""
    before = [e.kind for e in events if e.time_s <= at_s]
    if "step" not in before:
        return "search"
    last = [k for k in before if k in ("drive_start", "drive_end", "step")]
    return "drive" if last and last[-1] in ("drive_start", "step") else "between"


SCALAR_TOPICS = ("/force", "/stage/position", "/stage/command", "/amplifier/bias/command",
                 "/amplifier/drive/command", "/amplifier/bias/monitor", "/amplifier/drive/monitor",
                 "/camera/displacement")


def scalar_samples(reader: Any) -> dict[str, np.ndarray]:
    """topic -> 2-D array (samples x fields, time_s first) of every scalar topic in a recording."""
    out = {}
    topics = reader.topics()
    for topic in SCALAR_TOPICS:
        if topic in topics:
            columns = reader.scalars(topic)
            out[topic] = np.column_stack([columns["time_s"]] + [v for k, v in columns.items() if k != "time_s"])
    return out


def lost_before(reference: dict[str, np.ndarray], got: dict[str, np.ndarray], before_s: float) -> dict[str, int]:
    """Per topic, how many samples the reference has with time_s < before_s that `got` does not reproduce as
    the same prefix (value for value). A recording of the same seed is identical up to the moment they differ."""
    lost = {}
    for topic, ref in reference.items():
        ref_before = ref[ref[:, 0] < before_s]
        mine = got.get(topic, np.empty((0, ref.shape[1])))
        n = min(len(ref_before), len(mine))
        same = np.all(ref_before[:n, 1:] == mine[:n, 1:], axis=1)
        # A streamed sensor's sample times are estimated from when its lines are read (the Loadstar sends no
        # time): a batch read at another moment (after a blocking move, or once the stream fell silent) is dated
        # differently. Its samples, in order, and their values must still be identical.
        if topic not in DRIVER_DATED_TOPICS:
            same &= ref_before[:n, 0] == mine[:n, 0]
        first_diff = int(np.argmin(same)) if n and not same.all() else n
        if len(ref_before) - first_diff:
            lost[topic] = len(ref_before) - first_diff
    return lost


@dataclass(frozen=True)
class FaultOutcome:
    protocol: str
    fault: str
    code: int
    stderr_lines: list[str]
    exit_status: str | None
    reason: str | None
    crc_ok: bool
    fault_s: float
    safe_event_s: float | None
    safe: SafeMeasure | None  # None: not modelled (see `modelled`)
    lost: dict[str, int]  # samples with time_s < the fault time missing (vs the reference)
    lost_early: dict[str, int]  # ... with time_s < the fault time - IN_TRANSIT_S: must be none
    first_use_s: float = math.nan  # when the fault could first be noticed (see `fault_first_matters_s`)
    oldest_lost_s: float = math.nan  # reference time of the oldest sample missing (nan: none)
    phase: str = ""  # what the run was doing when the fault struck: search | drive | between

    @property
    def lost_in_transit(self) -> int:
        return sum(self.lost.values()) - sum(self.lost_early.values())

    @property
    def time_to_safe_s(self) -> float:
        """From the fault to the moment both DAQ outputs sit at 0 V and the stage has stopped (rig clock)."""
        if self.safe is None:
            raise ValueError("no safe-state measure: the fault is not modelled")
        done = max(max(self.safe.zero_V_at_s.values()), self.safe.stage_still_at_s)
        return max(done - self.first_use_s, 0.0)

    @property
    def latent_s(self) -> float:
        """How long the fault sat unnoticeable (device idle) before the run next used the device."""
        return self.first_use_s - self.fault_s

    @property
    def modelled(self) -> bool:
        """False when the emulator behind the target does not have this fault (e.g. the actuator rig's force
        sensor is on the DAQ, which has no serial line to garble): refused with one line before the run."""
        return self.safe is not None

    @property
    def triggered(self) -> bool:
        return self.modelled and self.exit_status != "success"


def run_fault_case(protocol: str, fault: str, out: Path, reference: dict[str, np.ndarray],
                   seed: int = 0) -> FaultOutcome:
    from hamr_bench.recording import RecordingReader

    run = run_cli(protocol, out, faults=(fault,), seed=seed)
    if run.bench is None:  # refused before the bench existed: that emulator does not model the fault
        return FaultOutcome(protocol, fault, run.code, run.stderr_lines, None, None, False, fault_time_s(fault),
                            None, None, {}, {})
    reader = RecordingReader(out, validate_crcs=True)  # raises on a CRC mismatch
    events = reader.events()
    safe_events = [e.time_s for e in events if e.kind == "safe_state"]
    fault_s = fault_time_s(fault)
    got = scalar_samples(reader)
    lost = lost_before(reference, got, fault_s)
    lost_early = lost_before(reference, got, fault_s - IN_TRANSIT_S)
    oldest = math.nan
    if lost:  # the first reference sample not reproduced, per topic; the oldest of those
        cut = {t: n for t, n in lost.items()}
        oldest = min(float(reference[t][reference[t][:, 0] < fault_s][-n, 0]) for t, n in cut.items())
    first_use = fault_first_matters_s(fault, run)
    safe = measure_safe(run.bench, min(fault_s, first_use), run.end_s)
    return FaultOutcome(protocol, fault, run.code, run.stderr_lines, reader.exit_status, reader.exit_reason,
                        True, fault_s, safe_events[-1] if safe_events else None, safe, lost, lost_early, first_use,
                        oldest, phase_at(events, fault_s))


def fault_first_matters_s(fault: str, run: CliRun) -> float:
    """The serial devices are talked to every few tens of ms, so their faults matter at once. The DAQ and the
    camera can sit idle for seconds (no drive during a contact search, no camera outside tracked drives): a fault
    there can only be noticed when the run next calls the device - and an amplifier trip while both outputs are at
    0 V changes nothing until a voltage is commanded (measured on the emulated DAQ's outputs)."""
    fault_s = fault_time_s(fault)
    device = fault.split(":")[0]
    if device not in ("daq", "camera"):
        return fault_s
    later = [t for t in run.calls.get(device, []) if t >= fault_s]
    first = later[0] if later else run.end_s
    if fault.startswith("daq:amp_trip"):
        first = run.end_s
        for channel in AO_CHANNELS.values():
            times, daq_V = daq_output_staircase(run.bench.daq, channel)
            on = np.flatnonzero((times >= fault_s) & (np.abs(daq_V) > ZERO_DAQ_V))
            before = np.flatnonzero(times < fault_s)
            if before.size and abs(daq_V[before[-1]]) > ZERO_DAQ_V:
                return fault_s  # a voltage was on when the amplifier tripped
            first = min(first, float(times[on[0]]) if on.size else run.end_s)
        return max(first, fault_s)
    return first


def daq_output_staircase(daq: Any, channel: str) -> tuple[np.ndarray, np.ndarray]:
    """(times, DAQ volts) of every value the channel actually put out, in order: each segment plays until the next
    one starts (a later write replaces what was scheduled after it)."""
    ch = daq._ao[channel]
    times, values = [0.0], [0.0]  # the output is 0 V before the first write
    for i, seg in enumerate(ch.segments):
        end = ch.segments[i + 1].t0_s if i + 1 < len(ch.segments) else math.inf
        n = len(seg.daq_V) if math.isfinite(seg.dt_s) else 1
        t = seg.t0_s + np.arange(n) * (seg.dt_s if math.isfinite(seg.dt_s) else 0.0)
        keep = t < end
        times.extend(t[keep])
        values.extend(seg.daq_V[keep])
    return np.asarray(times), np.asarray(values)


# ---------------------------------------------------------------------------------------------------- SIGKILL
def topic_payloads(path: Path) -> dict[str, list[bytes]]:
    """Every message of a finished recording, per topic, in file order, as what identifies the sample: the payload
    bytes (camera frames: the encoded image only, and log lines without their timestamp, since those timestamps
    carry the run's start epoch)."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from foxglove_schemas_protobuf.Log_pb2 import Log
    from mcap.reader import make_reader

    out: dict[str, list[bytes]] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f, validate_crcs=True).iter_messages(log_time_order=False):
            data = message.data
            if channel.topic == "/camera/image":
                data = CompressedImage.FromString(data).data
            elif schema is not None and schema.name == "foxglove.Log":
                line = Log.FromString(data)
                line.ClearField("timestamp")
                data = line.SerializeToString()
            out.setdefault(channel.topic, []).append(data)
    return out


@dataclass(frozen=True)
class Witness:
    wall_ns: int
    counts: dict[str, int]


@dataclass(frozen=True)
class KillOutcome:
    protocol: str
    kill_fraction: float  # of the reference's messages handed over when the kill was decided
    kill_ns: int
    flush_interval_s: float
    handed_at_kill: int  # messages handed to the recorder by the last witness line before the kill
    recovered: int
    must_have_short: dict[str, int]  # topic -> samples handed over >= flush interval before the kill but missing
    mismatched: dict[str, int]  # topic -> index of the first recovered message that differs from the reference
    lost_window_s: float  # wall time between the newest recovered sample's hand-over and the kill (nan: none)
    crc_ok: bool
    recovered_status: str | None

    @property
    def lost(self) -> int:
        return max(self.handed_at_kill - self.recovered, 0)

    @property
    def ok(self) -> bool:
        return not self.must_have_short and not self.mismatched and self.crc_ok


def _witness_lines(stream: Any, until: Any) -> list[Witness]:
    lines = []
    for raw in stream:
        if raw.startswith("W "):
            _, ns, counts = raw.split(" ", 2)
            lines.append(Witness(int(ns), json.loads(counts)))
            if until(lines[-1]):
                break
    return lines


def run_child(args: list[str], cwd: Path | None = None) -> Any:
    import subprocess
    import sys

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    return subprocess.Popen([sys.executable, "-m", "tests.reliability.kill_child", *args], cwd=cwd or REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)


def cli_args(protocol: str, out: Path, seed: int, settings: list[str] | None) -> list[str]:
    argv = ["run", protocol, "--sim", "--quiet", "--seed", str(seed), "--out", str(out)]
    for item in (SHORT_SETTINGS[protocol] if settings is None else settings):
        argv += ["--set", item]
    return argv


def make_reference(protocol: str, out: Path, seed: int, settings: list[str] | None) -> dict[str, list[bytes]]:
    """The same run to completion (same code path, same witness) - what a killed run is compared against."""
    child = run_child(cli_args(protocol, out, seed, settings))
    _, err = child.communicate(timeout=600)
    if child.returncode != 0:
        raise RuntimeError(f"reference run of {protocol} failed: {err.strip()}")
    return topic_payloads(out)


def kill_and_recover(protocol: str, tmp: Path, reference: dict[str, list[bytes]], fraction: float, seed: int,
                     settings: list[str] | None = None) -> KillOutcome:
    """Start the run, SIGKILL it once `fraction` of the reference's messages have been handed to the recorder,
    `hamr-bench recover` the file, and compare it sample by sample with the reference."""
    import signal
    import subprocess
    import sys
    import warnings

    from hamr_bench.recording import RecordingReader

    killed, recovered_path = tmp / f"killed-{protocol}.mcap", tmp / f"recovered-{protocol}.mcap"
    total = sum(len(v) for v in reference.values())
    threshold = int(fraction * total)
    child = run_child(cli_args(protocol, killed, seed, settings))
    try:
        seen = _witness_lines(child.stdout, lambda w: sum(w.counts.values()) >= threshold)
        if child.poll() is not None:
            raise RuntimeError(f"{protocol}: the run ended before the kill: {child.stderr.read().strip()}")
        kill_ns = time.time_ns()
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    seen += _witness_lines(child.stdout, lambda w: False)  # lines already in the pipe (printed before the kill)
    handed_at_kill = sum(seen[-1].counts.values()) if seen else 0

    recover = subprocess.run([sys.executable, "-m", "hamr_bench", "recover", str(killed), "-o", str(recovered_path)],
                             capture_output=True, text=True, cwd=REPO, timeout=120)
    if recover.returncode != 0:
        raise RuntimeError(f"recover failed: {recover.stderr.strip()}")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a recovered file reads with no warning at all
        reader = RecordingReader(recovered_path, validate_crcs=True)
    flush_s = float(reader.metadata()["recording"]["flush_interval_s"])
    got = topic_payloads(recovered_path)

    # Every message recovered is the reference's, in order (a prefix per topic).
    mismatched = {}
    for topic, messages in got.items():
        if topic == "/log":
            # foxglove.Log repeats each /events record with an absolute timestamp (the two runs started at different
            # wall times); /events, compared here, holds the same records with run-relative times
            continue
        ref = reference.get(topic, [])
        for i, payload in enumerate(messages):
            if i >= len(ref) or payload != ref[i]:
                mismatched[topic] = i
                break
    # Everything handed over at least one flush interval before the kill is there.
    old = [w for w in seen if w.wall_ns <= kill_ns - flush_s * 1e9]
    must = old[-1].counts if old else {}
    short = {t: n - len(got.get(t, [])) for t, n in must.items() if len(got.get(t, [])) < n}
    # When was the newest recovered sample handed over? The first witness that counted at least that many.
    n_rec = sum(len(v) for v in got.values())
    after = [w for w in seen if sum(w.counts.values()) >= n_rec]
    window_s = max(kill_ns - after[0].wall_ns, 0) / 1e9 if after and n_rec else math.nan  # nan: nothing recovered
    return KillOutcome(protocol, fraction, kill_ns, flush_s, handed_at_kill, n_rec, short, mismatched,
                       window_s, True, reader.exit_status)


# ---------------------------------------------------------------------------------------------------- bounds
# Faults that take the DAQ away: no software can command 0 V through it any more (the report says so).
UNREACHABLE_BY_SOFTWARE = ("daq:disconnect", "daq:no_reply")


def takes_the_daq(protocol: str, fault: str) -> bool:
    """True when the fault removes the DAQ (the actuator rig reads its force sensor through the DAQ, so a force
    sensor that disconnects or stops answering there is the DAQ doing so)."""
    name = fault.split("@")[0]
    if name in UNREACHABLE_BY_SOFTWARE:
        return True
    return protocol == "actuator" and name in ("force_sensor:disconnect", "force_sensor:no_reply")


def loss_allowed(protocol: str, fault: str, outcome: FaultOutcome) -> bool:
    """Samples missing from before the fault are allowed only where they never reached the computer: within
    IN_TRANSIT_S of the fault (an exchange straddling it), or - when the port of the force sensor (or the DAQ it is
    read through) goes away - the lines still unread in it, up to LINK_LOSS_BOUND_S. Commands are never lost: the
    runner knows them before it sends them."""
    if any(topic.endswith("/command") for topic in outcome.lost):
        return False
    if not outcome.lost_early:
        return True
    name = fault.split("@")[0]
    port_gone = name == "force_sensor:disconnect" or (protocol == "actuator" and takes_the_daq(protocol, fault))
    return (port_gone and set(outcome.lost_early) == {"/force"}
            and outcome.fault_s - outcome.oldest_lost_s <= LINK_LOSS_BOUND_S)
LONGEST_DEVICE_TIMEOUT_S = 1.0  # the camera's frame timeout; serial replies 0.5 s, the force stream 0.5 s



def expected_safe_bound_s(max_voltage_V: float = 250.0, slew_V_per_s: float = 10000.0,
                          stage_step_m: float = 0.25e-3, stage_speed_m_per_s: float = 5e-3) -> float:
    """The longest a fault may take to leave the rig safe, from its parts: the slowest detection (a device that
    stops answering is noticed after its timeout) or the stage check interval, whichever is longer; a move in
    progress completing (one safe step at the stage speed); the HV ramp to 0 V at the slew limit on both channels
    (drive first, then bias); and 0.1 s for the polls and exchanges between (serial replies, 20 ms poll)."""
    detection_s = max(LONGEST_DEVICE_TIMEOUT_S, STAGE_CHECK_S)
    return detection_s + stage_step_m / stage_speed_m_per_s + 2 * max_voltage_V / slew_V_per_s + 0.1


STAGE_LINK_FAULTS = tuple(f"stage:{name}" for name in SERIAL_FAULTS)


def stage_stopped_in_time(bench: Any, fault: str | None, since_s: float, end_s: float) -> bool:
    """The stage is still by `since_s` + the bound (by the end of the run if no fault). A stage whose serial link
    failed cannot be sent ST: its controller finishes the move it was given (toward the leg at most one safe step)
    - then what must hold is that no move began after the fault."""
    motions = bench.stage._history
    still_s = max(motions[-1].t_end, motions[-1].t0)
    if fault is None:
        return still_s <= end_s
    if still_s - since_s <= expected_safe_bound_s():
        return True
    fault_s = fault_time_s(fault)
    return fault.split("@")[0] in STAGE_LINK_FAULTS and not any(
        m.t0 > fault_s and m.kind in ("move", "home") for m in motions)


_REFERENCES: dict[tuple[str, float], dict[str, np.ndarray]] = {}


def reference_samples(protocol: str, until_s: float, tmp_factory: Any) -> dict[str, np.ndarray]:
    """Samples of a run of the same seed that nothing disturbs before `until_s` + 2 s (it is cut there by a stage
    disconnect, so a reference for a late moment costs no more than needed). Cached per process."""
    from hamr_bench.recording import RecordingReader

    key = (protocol, until_s)
    if key not in _REFERENCES:
        out = tmp_factory.mktemp("ref") / f"{protocol}.mcap"
        run_cli(protocol, out, faults=(f"stage:disconnect@{until_s + 2.0}",))
        _REFERENCES[key] = scalar_samples(RecordingReader(out))
    return _REFERENCES[key]
