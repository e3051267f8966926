"""Replaying a recorded timeline on a rig: the plan messages a replay adds to the runner's vocabulary, the commands
that carry them out (registered on a plain `Runner`, built on its public primitives), and the session that builds
the (simulated) rig and writes the twin's metadata.

A replay plan is not a protocol: it is the list of operations a recording shows, each at its recorded time
(`analysis.replay` builds it from a recording). Operations the runner already knows (Home, Tare, Step,
SetVoltages, RecordEvent) are reused, so the twin's devices see the same driver calls as the source run did. Three
messages are added here, carried out by `ReplayCommands` (safety, sampling and the end of the run stay the
runner's):

- `WaitUntil(time_s, ...)`: idle until an absolute rig-clock time, reading what the source read in that gap: every
  stream at the source's dwell passes (the runner's dwell, paced by them), the force stream as the contact
  search's force averaging does (the runner's `mean_force`), or nothing (the source was waiting on a device query).
  Reading as the source did keeps the twin's DAQ reads (each draws DAQ noise, in blocks the size of the read) and
  its force-read times (a serial sensor's read stamps the samples it collects) identical to the source's.
- `StageCommand(target_m)`: one recorded stage set-point, issued at once (no position query first: the source's
  query happened before the recorded command time). A move toward the leg longer than the safe step still goes
  through the runner's stepped move with the force checked in between.
- `ReplayDrive(waveform_V, sample_rate_Hz, start_s, track)`: the recorded drive samples; if the twin reaches the
  drive after its recorded start (slower devices than the source's), the samples already due are skipped so the rest
  plays at its recorded times.
- `Note` is the runner's `RecordEvent`: it copies a source event that marks a result rather than an operation
  (contact_found).
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hamr_bench import backends
from hamr_bench.recording.contract import TRAFFIC_PREFIX, MetadataName
from hamr_bench.recording.run_metadata import RunMetadata
from hamr_bench.errors import ConfigError, SafetyLimitError
from hamr_bench.protocols.contact import FORCE_WINDOW_S
from hamr_bench.protocols.plan import Drive, Home, Plan, ReadStage, RecordEvent
from hamr_bench.protocols.runner import RunResult, Runner

STEP_SLACK_M = 1e-6  # 1 um: above the positioning error of a queried position, far below what the force limit sees
WAIT_TOLERANCE_S = 1e-9  # a wait shorter than this is float noise between chained operations, not idle time
Note = RecordEvent


@dataclass(frozen=True)
class WaitUntil:
    """Idle until `time_s` (if the twin is not already past it), reading what the source read before its next
    operation. Judged from where the twin is when it gets here:
    - source dwell passes still to come (`pass_times_s`: when the runner recorded the amplifier monitors, which it
      does once per pass of a dwell) -> the runner's own dwell, one pass at each of those times;
    - else `poll_force` (the source's force stream ran, no dwell) -> the contact search's force averaging
      (`Runner.mean_force(FORCE_WINDOW_S)`), after a stage query if `after_query` (the search's first step);
    - else `dwell` (a source without monitor streams, e.g. an imported trace) -> the runner's plain dwell;
    - else nothing is read (the source was busy with a device query)."""

    time_s: float
    pass_times_s: tuple[float, ...] = ()
    poll_force: bool = False
    after_query: bool = False
    dwell: bool = False
    track: bool = False


@dataclass(frozen=True)
class StageCommand:
    target_m: float


@dataclass(frozen=True)
class ReplayDrive:
    waveform_V: tuple[float, ...]
    sample_rate_Hz: float
    start_s: float
    track: bool = False


class ReplayCommands:
    """The replay messages as commands of one runner (`register` adds them), and what they remember between
    messages: where the last stage command left the stage (a command needs it without a query)."""

    def __init__(self, runner: Runner) -> None:
        self.runner = runner
        self._stage_at_m: float | None = None
        self.drive_samples_skipped = 0

    def register(self) -> None:
        runner = self.runner
        runner.register_command(WaitUntil, self.wait_until)
        runner.register_command(StageCommand, self.stage_command)
        runner.register_command(ReplayDrive, self.replay_drive)
        home = runner.command(Home)

        def home_again(msg: Home) -> Any:
            self._stage_at_m = None  # known again from the reading the runner takes after homing
            return home(msg)

        runner.register_command(Home, home_again)

    def _advance_to(self, time_s: float) -> None:
        clock = self.runner.clock
        now = clock.now_s()
        advance_to = getattr(clock, "advance_to", None)
        if clock.is_virtual and advance_to is not None:
            advance_to(time_s)  # land exactly on the recorded time, not on now + (t - now)
        elif time_s > now:
            clock.sleep(time_s - now)

    def wait_until(self, msg: WaitUntil) -> None:
        runner, clock = self.runner, self.runner.clock
        now = clock.now_s()
        passes = [t for t in msg.pass_times_s if t > now + WAIT_TOLERANCE_S]
        if passes and clock.is_virtual and hasattr(clock, "advance_to"):
            # The runner's own dwell, paced by the source's passes; it ends after the pass at the last one.
            runner.sample_until(passes[-1], track=msg.track, wake_times_s=passes)
        elif passes or (msg.dwell and msg.time_s - now >= WAIT_TOLERANCE_S):
            runner.sample_until(msg.time_s, track=msg.track)
        elif msg.poll_force:
            # The contact search's force averaging (FORCE_WINDOW_S long) between its stage steps; its first one
            # follows a stage query (the search asks where it starts from).
            start = now + (runner.stage_query_s if msg.after_query else 0.0)
            if msg.time_s - start >= FORCE_WINDOW_S - WAIT_TOLERANCE_S:
                self._advance_to(start)
                runner.mean_force(FORCE_WINDOW_S)
        if msg.time_s - clock.now_s() >= WAIT_TOLERANCE_S:
            self._advance_to(msg.time_s)

    def stage_command(self, msg: StageCommand) -> None:
        runner = self.runner
        target = float(msg.target_m)
        low, high = runner.rig.stage.limits_m
        if not (math.isfinite(target) and low <= target <= high):
            raise SafetyLimitError(
                f"recorded stage target {target * 1e3:.4f} mm is outside the soft limits "
                f"[{low * 1e3:.3f}, {high * 1e3:.3f}] mm")
        position = self._stage_at_m if self._stage_at_m is not None else runner.last_stage_position_m
        if position is None:
            position = runner.perform(ReadStage()).position_m
        # The source split its moves from a queried position (reported to the controller's resolution), so its
        # recorded steps can exceed the safe step by that rounding; STEP_SLACK_M allows for it. An imported trace
        # may jump: the runner then steps, with the force check between steps.
        runner.move_stage(target, from_m=position, step_slack_m=STEP_SLACK_M)
        self._stage_at_m = target

    def replay_drive(self, msg: ReplayDrive) -> None:
        samples = tuple(msg.waveform_V)
        late_s = self.runner.clock.now_s() - msg.start_s
        if late_s > WAIT_TOLERANCE_S and len(samples) > 1:
            skip = min(len(samples) - 1, math.ceil(late_s * msg.sample_rate_Hz - 1e-9))
            samples = samples[skip:]
            self.drive_samples_skipped += skip
        self.runner.perform(Drive(samples, msg.sample_rate_Hz, msg.track))


@dataclass
class ReplayRequest:
    """A replay run: the plan, what the source was, and how the twin's bench is set up."""

    items: list[Any]
    out: Path
    protocol: str
    protocol_params_json: str
    design: int | None
    layers: int
    fixture: str
    seed: int
    effects: dict[str, float]
    replay_metadata: dict[str, str]
    model_overrides: dict[str, dict[str, Any]] = field(default_factory=dict)
    rig_path: Path | None = None
    overwrite: bool = False
    record_traffic: bool = False
    step_count: int = 0
    quiet: bool = True
    # Serve the serial devices (stage, force sensor) from this recording's /traffic/<device> streams instead of the
    # emulators and run the source's protocol again: the drivers then talk to what the devices said in that run
    # (driver-change testing); the first write that differs from the recording fails the run, naming it.
    traffic_from: Path | None = None
    camera_storage: Any = None  # a hamr_bench.recording.camera_storage.CameraStorage; None: the default (roi)
    live: Any = None  # a hamr_bench.live.session.LiveView that serves the twin while it is recorded


def _plan(items: Iterable[Any]) -> Plan:
    # a plain loop, not `yield from`: the runner sends each message's reply back, and a list iterator has no send()
    for item in items:  # noqa: UP028 (see above)
        yield item


def run_replay(req: ReplayRequest) -> RunResult:
    """Build the simulated rig (or the rig file's), record the twin's metadata, and carry the plan out."""
    from hamr_bench.protocols.session import TqdmProgress, software_versions
    from hamr_bench.recording import Recorder
    from hamr_bench.rig import load_rig, sim_rig_path

    if req.fixture not in ("leg", "actuator"):
        raise ConfigError(f"replay: the source's design.fixture is {req.fixture!r}; expected 'leg' or 'actuator'")
    rig_path = req.rig_path or sim_rig_path()
    served: list[tuple[str, Any]] = []
    port_overrides = _traffic_ports(req.traffic_from, served) if req.traffic_from else None
    recorder = Recorder(Path(req.out), overwrite=req.overwrite, camera=req.camera_storage)
    try:
        rig = load_rig(rig_path, design=req.design, layers=req.layers, effects=req.effects, seed=req.seed,
                       fixture=req.fixture, record_traffic=recorder.write_bytes if req.record_traffic else None,
                       model_overrides=req.model_overrides or None, port_overrides=port_overrides)
        if not rig.is_simulated:
            rig.close()
            raise ConfigError(f"{rig_path}: replay drives the simulated bench; this rig file is a real rig")
    except BaseException as exc:
        recorder.close("failed", f"rig could not be built: {exc}")
        raise
    try:
        RunMetadata(
            rig_name=rig.name, rig_path=rig.source_path, rig_text=rig.source_text, rig_kind="sim",
            design=req.design if req.fixture == "leg" else None, layers=req.layers, fixture=req.fixture,
            params_set=rig.settings.get("params_set", "effective"), model_params=rig.settings.get("model_params", {}),
            protocol=req.protocol, protocol_params=_params_of_source(req), software=software_versions(),
            seed=str(req.seed), clock="virtual", effects=dict(req.effects), faults=(),
            started_utc=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            run_extra={k: str(v) for k, v in rig.settings.get("run_metadata", {}).items()},
        ).write(recorder)
        recorder.add_metadata(MetadataName.REPLAY, dict(req.replay_metadata))
        progress = None if req.quiet or not req.step_count else TqdmProgress(req.step_count, f"replay {req.protocol}")
        if req.traffic_from:
            # Against recorded traffic the drivers must make the very calls the source run made, so the source's
            # protocol runs again with its recorded parameters on the plain runner (the replies, hence every
            # decision the plan takes, come from the recording).
            from hamr_bench.protocols import get_protocol
            from hamr_bench.protocols.session import params_from_recording

            protocol = get_protocol(req.protocol)
            params = params_from_recording(req.protocol, req.protocol_params_json)
            runner = Runner(rig, recorder, progress)
            if req.live is not None:
                req.live.follow(recorder, runner.request_abort)
            result = runner.run(protocol, params)
        else:
            runner = Runner(rig, recorder, progress)
            ReplayCommands(runner).register()
            if req.live is not None:
                req.live.follow(recorder, runner.request_abort)
            result = runner.run_plan(_plan(req.items), f"replay of {req.protocol}")
    finally:
        if req.live is not None:
            req.live.unfollow()
        rig.close()
        for url, _endpoint in served:
            backends.traffic_server().close_served(url)
    unfinished = [f"{e.device} ({e.writes} of {e.recorded_writes} writes)" for _u, e in served if not e.complete]
    if result.ok and unfinished:  # the driver stopped short of the recorded conversation: also a difference
        return RunResult("failed", "traffic replay: the drivers made fewer writes than recorded: "
                         + ", ".join(unfinished), result.steps_done)
    return result


def _params_of_source(req: ReplayRequest) -> dict[str, Any]:
    """The source run's protocol parameters (its metadata's JSON object), recorded again as the twin's."""
    try:
        params = json.loads(req.protocol_params_json)
    except ValueError:
        params = None
    if not isinstance(params, dict):
        raise ConfigError(f"replay: the source's protocol parameters are not a JSON object: "
                          f"{req.protocol_params_json[:80]!r}")
    return params


def _traffic_ports(source: Path, served: list[tuple[str, Any]]) -> dict[str, Callable[[Any], str]]:
    """Port factories for the rig: each serial role with a recorded /traffic stream is served from it."""
    server = backends.traffic_server()
    ports: dict[str, Callable[[Any], str]] = {}
    for topic in server.traffic_topics(source):
        role = server.role_of(topic)
        if role is None:
            continue

        def make_port(clock: Any, topic: str = topic) -> str:
            url, endpoint = server.serve_traffic(source, topic, clock)
            served.append((url, endpoint))
            return url

        ports[role] = make_port
    if not ports:
        raise ConfigError(f"{source}: no {TRAFFIC_PREFIX}<device> streams of a serial device to serve (record the run "
                          "with --record-traffic)")
    return ports
