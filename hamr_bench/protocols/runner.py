"""The runner: carries a protocol's plan out on a rig, records every stream, and owns safety and the end of a run.

Whatever happens (success, Ctrl-C, a device fault, a safety limit, a bug), `Runner.run` leaves the rig safe (drive
and bias ramped to 0 V, stage stopped) and the recording closed with `exit_status` (success / aborted / failed) and
a one-line reason. Limits that protect one device live in its driver; the runner adds the ones that need two:
stage moves toward the leg go in steps no longer than `max_stage_step_m` with the force checked between them, and
every force sample is checked against `force_limit_N`.
"""

from __future__ import annotations

import contextlib
import json
import math
from dataclasses import dataclass
from types import ModuleType
from typing import Any, Callable, Protocol

import numpy as np

from hamr_bench.errors import DeviceError, HamrBenchError, SafetyLimitError
from hamr_bench.protocols.plan import (
    Drive,
    Dwell,
    FindContact,
    Home,
    MoveStage,
    ReadForce,
    SetVoltages,
    Step,
    Tare,
)
from hamr_bench.rig import Rig

POLL_INTERVAL_S = 0.02
# Contact search: a back-off step that changes the mean force by less than this fraction of the threshold is flat
FLAT_FRACTION = 0.125
SLOW_STREAM_INTERVAL_S = 0.02  # stage position and amplifier monitors
FORCE_WINDOW_S = 0.1  # averaging window of a force reading during the contact search
# While sampling (drives, dwells) the stage is asked this often whether it still holds its position: a following
# error or a tripped switch while still is otherwise only seen at the next move. One TS exchange per interval.
STAGE_CHECK_INTERVAL_S = 0.25
COMMAND_TOPICS = {"bias": "/amplifier/bias/command", "drive": "/amplifier/drive/command"}
MONITOR_TOPICS = {"bias": "/amplifier/bias/monitor", "drive": "/amplifier/drive/monitor"}


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


class Runner:
    """Executes one protocol on one rig into one recorder."""

    def __init__(self, rig: Rig, recorder: Any, progress: Progress | None = None) -> None:
        self.rig = rig
        self.rec = recorder
        self.clock = rig.clock
        self.progress = progress or NoProgress()
        self.step_index = -1
        self.steps_done = 0
        self._next_slow_s = 0.0
        self._streaming = False
        self._commanded = {"bias": 0.0, "drive": 0.0}
        self._stage_homed = False
        self._next_stage_check_s = 0.0

    # ----------------------------------------------------------------- the run and its end
    def run(self, protocol: ModuleType, params: Any) -> RunResult:
        status, reason = "success", "completed"
        try:
            self._event("run_start", message=f"protocol {protocol.NAME}")
            self.rig.force_sensor.start_stream()
            self._streaming = True
            self._execute(protocol.plan(params))
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
        try:
            self._event("run_end", message=reason, exit_status=status)
        except HamrBenchError:
            pass
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
            try:
                self.rec.write_scalar(COMMAND_TOPICS[name], self.clock.now_s(), voltage_V=0.0)
            except HamrBenchError:
                pass
        try:
            self.rig.stage.stop()
        except Exception as exc:  # noqa: BLE001
            problems.append(f"stage: {exc}")
        if self._streaming:
            # Samples the sensor took before the end (e.g. while a stage move that then failed was blocking) are
            # still in the port buffer: record them before the stream stops. Best effort - if the sensor is what
            # failed, the reason already says so.
            try:
                for sample in self.rig.force_sensor.read_stream():
                    self.rec.write_scalar("/force", sample.time_s, force_N=sample.force_N)
            except Exception:  # noqa: BLE001, S110 - salvage only; the stream is stopped next either way
                pass
            try:
                self.rig.force_sensor.stop_stream()
            except Exception as exc:  # noqa: BLE001
                problems.append(f"force sensor: {exc}")
            self._streaming = False
        try:
            self._event("safe_state", message="0 V commanded, stage stopped")
        except HamrBenchError:
            pass
        return problems

    # ----------------------------------------------------------------- plan execution
    def _execute(self, plan) -> None:
        handlers: dict[type, Callable[[Any], Any]] = {
            Step: self._step,
            Home: self._home,
            Tare: self._tare,
            MoveStage: self._move_stage,
            FindContact: self._find_contact,
            SetVoltages: self._set_voltages,
            Drive: self._drive,
            Dwell: self._dwell,
            ReadForce: self._read_force,
        }
        reply = None
        while True:
            try:
                message = plan.send(reply)
            except StopIteration:
                break
            reply = handlers[type(message)](message)
        self._check_stage()  # a stage that faulted while still (no move since) must not end in "success"
        if self.step_index >= 0:
            self.steps_done = self.step_index + 1

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
        self._event("step", message=msg.label, **msg.condition)
        self.progress.step(msg.index, msg.label)

    def _home(self, _msg: Home) -> None:
        self._event("home")
        self.rig.stage.home()
        self._stage_homed = True
        self._record_stage()

    def _tare(self, _msg: Tare) -> None:
        # Streaming must pause: a sensor cannot tare while it streams.
        self.rig.force_sensor.stop_stream()
        self.rig.force_sensor.tare()
        self.rig.force_sensor.start_stream()
        self._event("tare")

    def _move_stage(self, msg: MoveStage) -> None:
        self._move_in_safe_steps(msg.position_m)

    def _move_in_safe_steps(self, target_m: float) -> None:
        low, high = self.rig.stage.limits_m
        if not (math.isfinite(target_m) and low <= target_m <= high):
            raise SafetyLimitError(
                f"stage target {target_m * 1e3:.4f} mm is outside the soft limits "
                f"[{low * 1e3:.3f}, {high * 1e3:.3f}] mm"
            )
        step_m = self.rig.limits.max_stage_step_m
        position = self.rig.stage.position_m()
        while abs(target_m - position) > 1e-9:
            toward_leg = (target_m - position) * self.rig.stage_toward_leg_sign > 0
            nxt = target_m if (not toward_leg or abs(target_m - position) <= step_m) else (
                position + math.copysign(step_m, target_m - position))
            self.rec.write_scalar("/stage/command", self.clock.now_s(), target_m=nxt)
            self.rig.stage.move_to(nxt)
            position = nxt
            self._record_stage()
            self._drain_force()

    def _find_contact(self, msg: FindContact) -> float:
        sign = msg.direction_sign * self.rig.stage_toward_leg_sign
        start = self.rig.stage.position_m()
        position = start
        force = self._mean_force(FORCE_WINDOW_S)
        if force >= msg.threshold_N / 2:
            # The tare just before assumed nothing touches here. A sensor that reads half the threshold anyway (a
            # tare that did not take, a sensor already pressed) would see contact everywhere and put the zero
            # anywhere: refuse rather than record a wrong zero.
            raise DeviceError(
                f"the force sensor reads {force * 1e3:.3f} mN where the contact search starts, right after its tare "
                f"(expected ~0, out of contact; the threshold is {msg.threshold_N * 1e3:.2f} mN): check that nothing "
                "touches the sensor and that its tare takes", device="force_sensor")
        while force < msg.threshold_N:
            if abs(position - start) >= msg.max_travel_m:
                raise DeviceError(
                    f"no contact within {msg.max_travel_m * 1e3:.2f} mm of travel (force stayed below "
                    f"{msg.threshold_N * 1e3:.2f} mN): check that the leg is above the sensor",
                    device="force_sensor",
                )
            position += sign * msg.coarse_step_m
            self._move_in_safe_steps(position)
            force = self._mean_force(FORCE_WINDOW_S)
        # Back off until contact is released, then by more than the stage's play, and approach again in fine steps,
        # keeping the (position, force) pairs in contact. Every pair is then taken moving toward the leg, with the
        # play taken up as in the loading moves that follow; pairs taken while backing off through the contact (as
        # before) left the carriage still for the first `play` of the back-off, a force plateau that tilted the line
        # and moved the zero by up to the play. The zero-sag point is where a straight line through the pairs
        # reaches zero force (the leg is linear over a few steps): finer than the step, and not biased by the
        # release threshold.
        release_N = msg.threshold_N / 4
        backed = 0.0
        # The force with nothing touching: the tare's zero, unless the sensor's baseline drifts during the search (a
        # load cell's does, ~0.1 mN in a minute). Contact force falls as the search backs off, a baseline does not:
        # two back-off steps in a row that leave the reading within FLAT_FRACTION of the threshold mean the leg is
        # clear and the reading is the baseline, and the rest of the search measures from it. (Without this, a
        # baseline above the release level kept the search backing off to the end of the stage's travel.) A leg
        # in contact loses k x coarse step a step once the stage's play is taken up: 0.12 mN for the softest
        # design, against a flat band of 0.05 mN.
        baseline_N = 0.0
        flat_steps = 0
        while force - baseline_N > release_N and backed < 2 * msg.coarse_step_m + msg.max_travel_m:
            position -= sign * msg.coarse_step_m
            backed += msg.coarse_step_m
            self._move_in_safe_steps(position)
            previous_N, force = force, self._mean_force(FORCE_WINDOW_S)
            # Within the stage's play (at most `clearance_m`) the carriage has not moved yet: no telling from there.
            flat = backed > msg.clearance_m and abs(force - previous_N) < FLAT_FRACTION * msg.threshold_N
            flat_steps = flat_steps + 1 if flat else 0
            if flat_steps >= 2 and force - baseline_N > release_N:
                baseline_N = force
        released = position
        self._move_in_safe_steps(self._clamp_to_limits(released - sign * msg.clearance_m))
        self._move_in_safe_steps(released)
        force = self._mean_force(FORCE_WINDOW_S) - baseline_N
        touching = [(position, force)] if force > release_N else []
        travelled = 0.0
        while force < msg.threshold_N:
            if travelled >= backed + 2 * msg.coarse_step_m:
                raise DeviceError(
                    f"contact moved between the coarse and the fine approach (force stayed below "
                    f"{msg.threshold_N * 1e3:.2f} mN over {travelled * 1e3:.3f} mm, past where it had touched): is "
                    "the force sensor drifting, or the leg loose?", device="force_sensor")
            position += sign * msg.fine_step_m
            travelled += msg.fine_step_m
            self._move_in_safe_steps(position)
            force = self._mean_force(FORCE_WINDOW_S) - baseline_N
            if force > release_N:
                touching.append((position, force))
        # With fewer than three pairs (a very stiff tip) the zero is taken half a step before the first touch.
        first_touch = touching[0][0] if touching else position
        zero_sag_m = self._extrapolate_zero_force(touching[::-1], fallback_m=first_touch - sign * msg.fine_step_m / 2,
                                                  window_m=2 * msg.coarse_step_m)
        zero_sag_m = self._clamp_to_limits(zero_sag_m)
        # The approach ended past the zero: reach the zero from the same side too.
        self._move_in_safe_steps(self._clamp_to_limits(zero_sag_m - sign * msg.clearance_m))
        self._move_in_safe_steps(zero_sag_m)
        position = zero_sag_m
        message, data = f"zero sag at stage {position * 1e3:.4f} mm", {"stage_position_m": position}
        if baseline_N:
            message += (f" (force measured from a baseline of {baseline_N * 1e3:.3f} mN: the sensor drifted since "
                        "its tare)")
            data["baseline_N"] = baseline_N
        self._event("contact_found", message=message, **data)
        return position

    def _clamp_to_limits(self, position_m: float) -> float:
        low, high = self.rig.stage.limits_m
        return min(max(position_m, low), high)

    @staticmethod
    def _extrapolate_zero_force(points: list[tuple[float, float]], fallback_m: float, window_m: float) -> float:
        positions = np.array([p for p, _ in points])
        forces = np.array([f for _, f in points])
        if len(points) < 3 or np.ptp(positions) == 0:
            return fallback_m
        slope, intercept = np.polyfit(positions, forces, 1)
        if slope == 0 or not np.isfinite(slope):
            return fallback_m
        estimate = -intercept / slope
        # Trust the line only near the last position that still touched (noise can tilt a short line badly).
        return float(estimate) if abs(estimate - positions[-1]) <= window_m else fallback_m

    def _set_voltages(self, msg: SetVoltages) -> None:
        # Order the ramps so the foot moves away from the sensor first: lower the drive before the bias.
        order = ("drive", "bias") if msg.bias_V <= self._commanded["bias"] else ("bias", "drive")
        targets = {"bias": msg.bias_V, "drive": msg.drive_V}
        self._event("set_voltages", bias_V=msg.bias_V, drive_V=msg.drive_V)
        for name in order:
            amp = self.rig.amp_bias if name == "bias" else self.rig.amp_drive
            self.rec.write_scalar(COMMAND_TOPICS[name], self.clock.now_s(), voltage_V=targets[name])
            amp.set_voltage(targets[name])
            self._commanded[name] = targets[name]
            self._sample_until(self.clock.now_s(), track=False)

    def _drive(self, msg: Drive) -> None:
        waveform = np.asarray(msg.waveform_V, dtype=float)
        start_s = self.rig.amp_drive.play_waveform(waveform, msg.sample_rate_Hz)
        self._event("drive_start", sample_rate_Hz=msg.sample_rate_Hz, n_samples=len(waveform),
                    peak_V=float(waveform.max(initial=0.0)), track=msg.track)
        end_s = start_s + (len(waveform) - 1) / msg.sample_rate_Hz
        self._sample_until(end_s, track=msg.track, waveform=(start_s, msg.sample_rate_Hz, waveform))
        self.rig.amp_drive.wait_done()
        self._commanded["drive"] = float(waveform[-1]) if len(waveform) else self._commanded["drive"]
        self._event("drive_end")

    def _dwell(self, msg: Dwell) -> None:
        self._sample_until(self.clock.now_s() + msg.duration_s, track=msg.track)

    def _read_force(self, msg: ReadForce) -> float:
        return self._mean_force(msg.duration_s)

    # ----------------------------------------------------------------- sampling
    def _sample_until(self, end_s: float, track: bool, waveform: tuple | None = None) -> None:
        """Record every stream until the rig clock reaches `end_s` (at least one pass)."""
        written = 0
        y0_px = None
        try:
            while True:
                now = self.clock.now_s()
                if waveform is not None:
                    written = self._record_waveform(waveform, now, written)
                self._drain_force()
                if now >= self._next_slow_s:
                    self._record_stage()
                    self._record_monitors(now)
                    self._next_slow_s = now + SLOW_STREAM_INTERVAL_S
                if now >= self._next_stage_check_s:
                    self._check_stage()
                    self._next_stage_check_s = now + STAGE_CHECK_INTERVAL_S
                if track and self.rig.camera is not None:
                    y0_px = self._grab_and_track(y0_px)
                if now >= end_s:
                    break
                if not (track and self.rig.camera is not None):
                    self.clock.sleep(min(POLL_INTERVAL_S, end_s - now))
        except BaseException:
            # The DAQ played the waveform up to now whatever failed: record those command samples too.
            if waveform is not None:
                with contextlib.suppress(HamrBenchError):
                    self._record_waveform(waveform, self.clock.now_s(), written)
            raise
        if waveform is not None:
            self._record_waveform(waveform, end_s, written)

    def _record_waveform(self, waveform: tuple, until_s: float, written: int) -> int:
        start_s, rate_Hz, samples = waveform
        due = min(len(samples), int(math.floor((until_s - start_s) * rate_Hz + 1e-9)) + 1)
        for i in range(written, due):
            self.rec.write_scalar(COMMAND_TOPICS["drive"], start_s + i / rate_Hz, voltage_V=float(samples[i]))
        return max(written, due)

    def _drain_force(self) -> list[float]:
        values = []
        limit = self.rig.limits.force_limit_N
        try:
            samples = self.rig.force_sensor.read_stream()
        except DeviceError as exc:
            # Good readings taken before the fault in the same batch (drivers attach them) are kept.
            for sample in getattr(exc, "samples_before", ()):
                self.rec.write_scalar("/force", sample.time_s, force_N=sample.force_N)
            raise
        for sample in samples:
            self.rec.write_scalar("/force", sample.time_s, force_N=sample.force_N)
            values.append(sample.force_N)
            if abs(sample.force_N) > limit:
                self.rig.stage.stop()
                raise SafetyLimitError(
                    f"force {sample.force_N * 1e3:.2f} mN exceeds the limit {limit * 1e3:.2f} mN")
        return values

    def _mean_force(self, duration_s: float) -> float:
        end_s = self.clock.now_s() + duration_s
        values = self._drain_force()
        while self.clock.now_s() < end_s or not values:
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

    def _record_stage(self) -> None:
        self.rec.write_scalar("/stage/position", self.clock.now_s(), position_m=self.rig.stage.position_m())

    def _record_monitors(self, now: float) -> None:
        for name, amp in (("bias", self.rig.amp_bias), ("drive", self.rig.amp_drive)):
            self.rec.write_scalar(MONITOR_TOPICS[name], now, voltage_V=amp.monitor_voltage_V())

    def _grab_and_track(self, y0_px: float | None) -> float | None:
        frame = self.rig.camera.grab()
        if self.rig.track_px is None:
            self.rec.write_image("/camera/image", frame.time_s, frame.image)
            return y0_px
        x_px, y_px = self.rig.track_px(frame.image)
        # the recorder keeps the frame as its camera storage says, around the marker just tracked
        self.rec.write_image("/camera/image", frame.time_s, frame.image, marker_px=(x_px, y_px))
        if y0_px is None:
            y0_px = y_px
        displacement_m = (y_px - y0_px) * self.rig.metres_per_pixel * self.rig.displacement_sign
        self.rec.write_scalar("/camera/displacement", frame.time_s, displacement_m=displacement_m,
                              x_px=x_px, y_px=y_px)
        return y0_px

    def _event(self, kind: str, message: str = "", **data: Any) -> None:
        clean = {k: (float(v) if isinstance(v, (np.floating, np.integer)) else v) for k, v in data.items()}
        json.dumps(clean)  # fail here, not in the writer thread, if a value cannot be recorded
        self.rec.write_event(self.clock.now_s(), kind, max(self.step_index, 0), message, **clean)
