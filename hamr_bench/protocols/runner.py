"""The runner: carries a plan out on a rig, records every stream, and owns safety and the end of a run.

Whatever happens (success, Ctrl-C, `request_abort`, a device fault, a safety limit, a bug), `Runner.run` leaves the
rig safe (drive and bias ramped to 0 V, stage stopped) and the recording closed with `exit_status` (success /
aborted / failed) and a one-line reason. Limits that protect one device live in its driver; the runner adds the
ones that need two: stage moves toward the leg go in steps no longer than `max_stage_step_m` with the force checked
between them, and every force sample is checked against `force_limit_N`.

A plan is a generator of messages (`hamr_bench.protocols.plan`). Each message type has a command: a handler the
runner calls with the message (its return value is sent back into the plan), or a sub-plan the message expands
into (`register_plan`: the contact search is one, built from the primitive messages). Code that needs more
vocabulary (replay) registers its own commands on a runner, built on the public primitives below (`move_stage`,
`sample_until`, `mean_force`, `record_stage`, `record_event`, `perform`); safety and the end of the run stay here.
"""

from __future__ import annotations

import contextlib
import json
import math
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import numpy as np

from hamr_bench.errors import DeviceError, HamrBenchError, SafetyLimitError
from hamr_bench.protocols import contact
from hamr_bench.protocols.contact import FORCE_WINDOW_S
from hamr_bench.protocols.plan import (
    Drive,
    Dwell,
    FindContact,
    Home,
    MoveStage,
    Plan,
    ProtocolModule,
    ReadForce,
    ReadStage,
    RecordEvent,
    SetVoltages,
    StageState,
    Step,
    Tare,
)
from hamr_bench.recording.contract import EventKind, Topic, amplifier_topics
from hamr_bench.rig import Rig

__all__ = ["FORCE_WINDOW_S", "POLL_INTERVAL_S", "STAGE_CHECK_INTERVAL_S", "AbortRequested", "NoProgress",
           "Progress", "RunResult", "Runner"]

POLL_INTERVAL_S = 0.02
SLOW_STREAM_INTERVAL_S = 0.02  # stage position and amplifier monitors
# While sampling (drives, dwells) the stage is asked this often whether it still holds its position: a following
# error or a tripped switch while still is otherwise only seen at the next move. One TS exchange per interval.
STAGE_CHECK_INTERVAL_S = 0.25
WAKE_TOLERANCE_S = 1e-9  # a wake time closer than this to now is now (float noise between chained operations)
CHANNELS = ("bias", "drive")

M = TypeVar("M")
Handler = Callable[[Any], Any]


class Progress(Protocol):
    def step(self, index: int, label: str) -> None: ...

    def close(self, completed: bool = True) -> None: ...


class NoProgress:
    def step(self, index: int, label: str) -> None:
        pass

    def close(self, completed: bool = True) -> None:
        pass


@dataclass(frozen=True)
class RunResult:
    exit_status: str  # success | aborted | failed
    reason: str
    steps_done: int

    @property
    def ok(self) -> bool:
        return self.exit_status == "success"


class AbortRequested(KeyboardInterrupt):
    """Raised in the runner's own thread at its next check after `request_abort`: a KeyboardInterrupt, so it takes
    exactly the path Ctrl-C takes (past every `except Exception` in device code, into the run's aborted ending)."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class Runner:
    """Executes one plan on one rig into one recorder."""

    def __init__(self, rig: Rig, recorder: Any, progress: Progress | None = None, specimen: str = "") -> None:
        self.rig = rig
        # the mounted specimen's label, carried by every step's condition (the readers make one specimen of the
        # runs that name the same label, or none)
        self.specimen = specimen
        self.rec = recorder
        self.clock = rig.clock
        self.progress = progress or NoProgress()
        self.step_index = -1
        self.steps_done = 0
        self._next_slow_s = 0.0
        self._streaming = False
        self._commanded = {"bias": 0.0, "drive": 0.0}
        self._stage_homed = False
        self._tracking = False  # the last sampling pass grabbed camera frames
        self._next_stage_check_s = 0.0
        self._last_stage_m: float | None = None
        self._stage_query_s = 0.0
        self._abort = threading.Event()
        self._abort_reason = ""
        self._commands: dict[type, Handler] = {
            Step: self._step, Home: self._home, Tare: self._tare, MoveStage: self._move_stage,
            SetVoltages: self._set_voltages, Drive: self._drive, Dwell: self._dwell, ReadForce: self._read_force,
            ReadStage: self._read_stage, RecordEvent: self._record_event,
        }
        self._plans: dict[type, Callable[[Any], Plan]] = {FindContact: contact.search}

    # ----------------------------------------------------------------- the command registry
    def register_command(self, message_type: type[M], handler: Callable[[M], Any]) -> None:
        """Carry out messages of `message_type` with `handler` (its return value is sent back into the plan),
        replacing any command the type had. `command(message_type)` gives the one replaced, to wrap it."""
        self._plans.pop(message_type, None)
        self._commands[message_type] = handler

    def register_plan(self, message_type: type[M], expand: Callable[[M], Plan]) -> None:
        """Carry out messages of `message_type` as the sub-plan `expand(message)`; what it returns is sent back."""
        self._commands.pop(message_type, None)
        self._plans[message_type] = expand

    def command(self, message_type: type) -> Handler:
        """The present command of `message_type` as a handler (a sub-plan is carried out to its end)."""
        if message_type in self._plans:
            expand = self._plans[message_type]
            return lambda message: self._execute(expand(message))
        try:
            return self._commands[message_type]
        except KeyError:
            raise TypeError(f"the runner has no command for {message_type.__name__} messages") from None

    def perform(self, message: Any) -> Any:
        """Carry out one message now, as if a plan had yielded it; returns its reply."""
        return self.command(type(message))(message)

    # ----------------------------------------------------------------- the run and its end
    def run(self, protocol: ProtocolModule, params: Any) -> RunResult:
        return self.run_plan(protocol.plan(params), protocol.NAME)

    def run_plan(self, plan: Plan, name: str) -> RunResult:
        """Carry `plan` out and end the run (always safe, always recorded as ended)."""
        status, reason = "success", "completed"
        try:
            self.record_event(EventKind.RUN_START, message=f"protocol {name}")
            self.rig.force_sensor.start_stream()
            self._streaming = True
            self._execute(plan)
            self._check_stage()  # a stage that faulted while still (no move since) must not end in "success"
            if self.step_index >= 0:
                self.steps_done = self.step_index + 1
        except AbortRequested as exc:
            status, reason = "aborted", f"abort requested: {exc.reason}"
        except KeyboardInterrupt:
            status, reason = "aborted", "interrupted by the operator (Ctrl-C)"
        except SafetyLimitError as exc:
            status, reason = "aborted", f"safety limit: {exc}"
        except DeviceError as exc:
            status, reason = "failed", f"device fault ({exc.device}): {exc}"
        except HamrBenchError as exc:
            status, reason = "failed", str(exc)
        except Exception as exc:  # a bug: still leave the rig safe and the file closed, then re-raise
            status, reason = "failed", f"internal error: {type(exc).__name__}: {exc}"
            self._finish(status, reason)
            raise
        status, reason = self._finish(status, reason)
        return RunResult(status, reason, self.steps_done)

    def request_abort(self, reason: str) -> None:
        """Ask the run to stop (from any thread): at its next check (before each message, every sampling pass,
        every stage step, every force poll) the run ends as on Ctrl-C, aborted, with `reason`. A device call in
        progress (a stage move blocks until READY) finishes first. The first reason given is the one recorded."""
        if not self._abort.is_set():
            self._abort_reason = reason
            self._abort.set()

    def _check_abort(self) -> None:
        if self._abort.is_set():
            raise AbortRequested(self._abort_reason)

    def _finish(self, status: str, reason: str) -> tuple[str, str]:
        """Make the rig safe and close the recording; returns the run's final (status, reason): a run that
        completed but could not be made safe has failed."""
        if status != "success":
            # Closing a faulted rig fails the same way the run did; the reason recorded here is the message.
            self.rig.faulted = True
        problems = self.make_safe()
        if problems:
            reason = f"{reason}; while making safe: {'; '.join(problems)}"
            if status == "success":
                status = "failed"
        with contextlib.suppress(HamrBenchError):
            self.record_event(EventKind.RUN_END, message=reason, exit_status=status)
        self.rec.close(status, reason)
        self.progress.close(completed=status == "success")
        return status, reason

    def make_safe(self) -> list[str]:
        """0 V on both channels (drive first), stage stopped, stream stopped. Each device is tried even if another
        fails; returns what went wrong."""
        problems = []
        for name, amp in (("drive", self.rig.amp_drive), ("bias", self.rig.amp_bias)):
            try:
                amp.zero()
            except Exception as exc:  # noqa: BLE001 - the next device must still be made safe
                problems.append(f"{name} amplifier: {exc}")
            self._commanded[name] = 0.0
            with contextlib.suppress(HamrBenchError):
                self.rec.write_scalar(amplifier_topics(name)[0], self.clock.now_s(), voltage_V=0.0)
        try:
            self.rig.stage.stop()
        except Exception as exc:  # noqa: BLE001
            problems.append(f"stage: {exc}")
        if self._streaming:
            problems += self._stop_stream()
        with contextlib.suppress(HamrBenchError):
            self.record_event(EventKind.SAFE_STATE, message="0 V commanded, stage stopped")
        return problems

    def _stop_stream(self) -> list[str]:
        # Samples the sensor took before the end (e.g. while a stage move that then failed was blocking) are still
        # in the port buffer: record them before the stream stops. Best effort - if the sensor is what failed, the
        # reason already says so.
        try:
            for sample in self.rig.force_sensor.read_stream():
                self.rec.write_scalar(Topic.FORCE, sample.time_s, force_N=sample.force_N)
        except Exception:  # noqa: BLE001, S110 - salvage only; the stream is stopped next either way
            pass
        self._streaming = False
        try:
            self.rig.force_sensor.stop_stream()
        except Exception as exc:  # noqa: BLE001
            return [f"force sensor: {exc}"]
        return []

    # ----------------------------------------------------------------- plan execution
    def _execute(self, plan: Plan) -> Any:
        """Send each message of `plan` to its command and the reply back; returns what the plan returns."""
        reply = None
        while True:
            self._check_abort()
            try:
                message = plan.send(reply)
            except StopIteration as stop:
                return stop.value
            reply = self.perform(message)

    def _check_stage(self) -> None:
        """Ask the stage whether it still holds its position (drivers raise DeviceFault when it does not); only
        once this run has homed it (before that, NOT REFERENCED is its normal state)."""
        if self._stage_homed:
            self.rig.stage.is_moving()

    def _step(self, msg: Step) -> None:
        self._check_stage()
        if self.step_index >= 0:
            self.steps_done = self.step_index + 1
        self.step_index = msg.index
        condition = {**msg.condition, "specimen": self.specimen} if self.specimen else msg.condition
        self.record_event(EventKind.STEP, message=msg.label, **condition)
        self.progress.step(msg.index, msg.label)

    def _home(self, _msg: Home) -> None:
        self.record_event(EventKind.HOME)
        self.rig.stage.home()
        self._stage_homed = True
        self.record_stage()

    def _tare(self, _msg: Tare) -> None:
        # Streaming must pause: a sensor cannot tare while it streams.
        self.rig.force_sensor.stop_stream()
        self.rig.force_sensor.tare()
        self.rig.force_sensor.start_stream()
        self.record_event(EventKind.TARE)

    def _move_stage(self, msg: MoveStage) -> None:
        self.move_stage(msg.position_m)

    def _read_stage(self, _msg: ReadStage) -> StageState:
        return StageState(self.rig.stage.position_m(), self.rig.stage.limits_m, self.rig.stage_toward_leg_sign)

    def _record_event(self, msg: RecordEvent) -> None:
        self.record_event(msg.kind, msg.message, **msg.data)

    def _set_voltages(self, msg: SetVoltages) -> None:
        # Order the ramps so the foot moves away from the sensor first: lower the drive before the bias.
        order = ("drive", "bias") if msg.bias_V <= self._commanded["bias"] else ("bias", "drive")
        targets = {"bias": msg.bias_V, "drive": msg.drive_V}
        self.record_event(EventKind.SET_VOLTAGES, bias_V=msg.bias_V, drive_V=msg.drive_V)
        for name in order:
            amp = self.rig.amp_bias if name == "bias" else self.rig.amp_drive
            self.rec.write_scalar(amplifier_topics(name)[0], self.clock.now_s(), voltage_V=targets[name])
            amp.set_voltage(targets[name])
            self._commanded[name] = targets[name]
            self._sample(self.clock.now_s(), track=False)

    def _drive(self, msg: Drive) -> None:
        waveform = np.asarray(msg.waveform_V, dtype=float)
        start_s = self.rig.amp_drive.play_waveform(waveform, msg.sample_rate_Hz)
        self.record_event(EventKind.DRIVE_START, sample_rate_Hz=msg.sample_rate_Hz, n_samples=len(waveform),
                          peak_V=float(waveform.max(initial=0.0)), track=msg.track)
        end_s = start_s + (len(waveform) - 1) / msg.sample_rate_Hz
        self._sample(end_s, track=msg.track, waveform=(start_s, msg.sample_rate_Hz, waveform))
        self.rig.amp_drive.wait_done()
        self._commanded["drive"] = float(waveform[-1]) if len(waveform) else self._commanded["drive"]
        self.record_event(EventKind.DRIVE_END)

    def _dwell(self, msg: Dwell) -> None:
        self._sample(self.clock.now_s() + msg.duration_s, track=msg.track)

    def _read_force(self, msg: ReadForce) -> float:
        return self.mean_force(msg.duration_s)

    # ----------------------------------------------------------------- primitives (public: commands build on them)
    def move_stage(self, target_m: float, *, from_m: float | None = None, step_slack_m: float = 0.0) -> None:
        """Move the stage to `target_m` within its soft limits, toward the leg in steps no longer than the rig's
        `max_stage_step_m`, recording each set-point and the position and checking the force after each.
        `from_m`: where the stage is known to be (no query); a move from there within one step (plus
        `step_slack_m`) is one command, issued even if it is zero."""
        low, high = self.rig.stage.limits_m
        if not (math.isfinite(target_m) and low <= target_m <= high):
            raise SafetyLimitError(
                f"stage target {target_m * 1e3:.4f} mm is outside the soft limits "
                f"[{low * 1e3:.3f}, {high * 1e3:.3f}] mm"
            )
        step_m = self.rig.limits.max_stage_step_m
        if from_m is not None:
            toward_leg = (target_m - from_m) * self.rig.stage_toward_leg_sign > 0
            if not toward_leg or abs(target_m - from_m) <= step_m + step_slack_m:
                self._stage_step(target_m)
                return
        position = self.rig.stage.position_m()
        while abs(target_m - position) > 1e-9:
            toward_leg = (target_m - position) * self.rig.stage_toward_leg_sign > 0
            nxt = target_m if (not toward_leg or abs(target_m - position) <= step_m) else (
                position + math.copysign(step_m, target_m - position))
            self._stage_step(nxt)
            position = nxt

    def _stage_step(self, target_m: float) -> None:
        self._check_abort()
        self.rec.write_scalar(Topic.STAGE_COMMAND, self.clock.now_s(), target_m=target_m)
        self.rig.stage.move_to(target_m)
        self.record_stage()
        self._drain_force()

    def sample_until(self, end_s: float, *, track: bool = False, wake_times_s: Sequence[float] = ()) -> None:
        """Record every stream until the rig clock reaches `end_s` (at least one pass), as a dwell does.
        `wake_times_s` (a virtual clock only): each wait ends at the next of these times instead of after the poll
        interval, so passes fall at given moments (replay puts them where the source's fell)."""
        self._sample(end_s, track=track, wake_times_s=wake_times_s)

    def mean_force(self, duration_s: float) -> float:
        """The mean of the force stream over `duration_s` (at least one sample), checking the limit on each."""
        end_s = self.clock.now_s() + duration_s
        values = self._drain_force()
        while self.clock.now_s() < end_s or not values:
            self._check_abort()
            self.clock.sleep(POLL_INTERVAL_S)
            values += self._drain_force()
            now = self.clock.now_s()
            if now >= self._next_stage_check_s:
                # A long contact search never samples the other streams: check on the stage and the amplifiers
                # (a trip shows on their monitors) as often as a drive would.
                self._check_stage()
                self._record_monitors(now)
                self._next_stage_check_s = now + STAGE_CHECK_INTERVAL_S
            if self.clock.now_s() > end_s + 1.0 and not values:
                raise DeviceError("force sensor stream delivered no samples for 1 s", device="force_sensor")
        return float(np.mean(values))

    def record_stage(self) -> float:
        """Query and record the stage position (stamped when the query starts); returns it."""
        now = self.clock.now_s()
        position_m = self.rig.stage.position_m()
        self._stage_query_s = self.clock.now_s() - now
        self._last_stage_m = position_m
        self.rec.write_scalar(Topic.STAGE_POSITION, now, position_m=position_m)
        return position_m

    @property
    def last_stage_position_m(self) -> float | None:
        """The position the last `record_stage` read (None before the first)."""
        return self._last_stage_m

    @property
    def stage_query_s(self) -> float:
        """How long the last stage position query took on the rig clock."""
        return self._stage_query_s

    def record_event(self, kind: str, message: str = "", **data: Any) -> None:
        """An `/events` message at the present time, in the present step."""
        clean = {k: (float(v) if isinstance(v, (np.floating, np.integer)) else v) for k, v in data.items()}
        json.dumps(clean)  # fail here, not in the writer thread, if a value cannot be recorded
        self.rec.write_event(self.clock.now_s(), kind, max(self.step_index, 0), message, **clean)

    # ----------------------------------------------------------------- sampling
    def _sample(self, end_s: float, track: bool, waveform: tuple[float, float, np.ndarray] | None = None,
                wake_times_s: Sequence[float] = ()) -> None:
        """Record every stream until the rig clock reaches `end_s` (at least one pass)."""
        written = 0
        camera = self.rig.camera if track else None
        tracking = camera is not None
        if camera is not None and not self._tracking:
            # between tracked drives nobody grabs (bias ramps, stage moves): the camera's frames from then are
            # not drops, however long a slow amplifier took
            camera.skip_to_live()
        self._tracking = tracking
        y0_px: float | None = None
        try:
            while True:
                self._check_abort()
                now = self.clock.now_s()
                if waveform is not None:
                    written = self._record_waveform(waveform, now, written)
                self._sample_pass(now)
                if tracking:
                    y0_px = self._grab_and_track(y0_px)
                if now >= end_s:
                    break
                if not tracking:
                    self._wait(min(POLL_INTERVAL_S, end_s - now), wake_times_s)
        except BaseException:
            # The DAQ played the waveform up to now whatever failed: record those command samples too.
            if waveform is not None:
                with contextlib.suppress(HamrBenchError):
                    self._record_waveform(waveform, self.clock.now_s(), written)
            raise
        if waveform is not None:
            self._record_waveform(waveform, end_s, written)

    def _sample_pass(self, now: float) -> None:
        """One pass over the streams that are not the camera: force always, the slow ones when due."""
        self._drain_force()
        if now >= self._next_slow_s:
            self.record_stage()
            self._record_monitors(now)
            self._next_slow_s = now + SLOW_STREAM_INTERVAL_S
        if now >= self._next_stage_check_s:
            self._check_stage()
            self._next_stage_check_s = now + STAGE_CHECK_INTERVAL_S

    def _wait(self, duration_s: float, wake_times_s: Sequence[float]) -> None:
        advance_to = getattr(self.clock, "advance_to", None)
        if wake_times_s and advance_to is not None:
            now = self.clock.now_s()
            upcoming = [t for t in wake_times_s if t > now + WAKE_TOLERANCE_S]
            if upcoming:
                advance_to(upcoming[0])
                return
        self.clock.sleep(duration_s)

    def _record_waveform(self, waveform: tuple[float, float, np.ndarray], until_s: float, written: int) -> int:
        start_s, rate_Hz, samples = waveform
        due = min(len(samples), int(math.floor((until_s - start_s) * rate_Hz + 1e-9)) + 1)
        topic = amplifier_topics("drive")[0]
        for i in range(written, due):
            self.rec.write_scalar(topic, start_s + i / rate_Hz, voltage_V=float(samples[i]))
        return max(written, due)

    def _drain_force(self) -> list[float]:
        values = []
        limit = self.rig.limits.force_limit_N
        try:
            samples = self.rig.force_sensor.read_stream()
        except DeviceError as exc:
            # Good readings taken before the fault in the same batch (drivers attach them) are kept.
            for sample in exc.samples_before:
                self.rec.write_scalar(Topic.FORCE, sample.time_s, force_N=sample.force_N)
            raise
        for sample in samples:
            self.rec.write_scalar(Topic.FORCE, sample.time_s, force_N=sample.force_N)
            values.append(sample.force_N)
            if abs(sample.force_N) > limit:
                self.rig.stage.stop()
                raise SafetyLimitError(
                    f"force {sample.force_N * 1e3:.2f} mN exceeds the limit {limit * 1e3:.2f} mN")
        return values

    def _record_monitors(self, now: float) -> None:
        for name, amp in (("bias", self.rig.amp_bias), ("drive", self.rig.amp_drive)):
            self.rec.write_scalar(amplifier_topics(name)[1], now, voltage_V=amp.monitor_voltage_V())

    def _grab_and_track(self, y0_px: float | None) -> float | None:
        assert self.rig.camera is not None  # only called while tracking with a camera
        frame = self.rig.camera.grab()
        if self.rig.track_px is None:
            self.rec.write_image(Topic.CAMERA_IMAGE, frame.time_s, frame.image)
            return y0_px
        x_px, y_px = self.rig.track_px(frame.image)
        # the recorder keeps the frame as its camera storage says, around the marker just tracked
        self.rec.write_image(Topic.CAMERA_IMAGE, frame.time_s, frame.image, marker_px=(x_px, y_px))
        if y0_px is None:
            y0_px = y_px
        displacement_m = (y_px - y0_px) * self.rig.metres_per_pixel * self.rig.displacement_sign
        self.rec.write_scalar(Topic.CAMERA_DISPLACEMENT, frame.time_s, displacement_m=displacement_m,
                              x_px=x_px, y_px=y_px)
        return y0_px
