"""The runner's public primitives: the command registry (commands and sub-plans), `perform`, and `request_abort`,
which must end a run exactly as Ctrl-C does (aborted, rig safe, recording closed with the reason)."""

from __future__ import annotations

import threading
from dataclasses import dataclass

import pytest

from hamr_bench.protocols import get_protocol
from hamr_bench.protocols.params import load_params
from hamr_bench.protocols.plan import Dwell, MoveStage, ReadForce, RecordEvent, Step
from hamr_bench.protocols.runner import Runner
from tests.protocols.fakes import FakeRecorder, fake_rig


@dataclass(frozen=True)
class Ping:
    value: float


@dataclass(frozen=True)
class Probe:
    position_m: float


def run_plan(plan, rig=None, setup=None):
    rig = rig or fake_rig()
    rec = FakeRecorder()
    runner = Runner(rig, rec)
    if setup:
        setup(runner)
    return runner.run_plan(plan, "test"), rec, rig


def test_a_registered_command_answers_the_plan():
    seen = []

    def plan():
        seen.append((yield Ping(2.0)))

    result, _, _ = run_plan(plan(), setup=lambda r: r.register_command(Ping, lambda msg: msg.value * 3))
    assert result.ok and seen == [6.0]


def test_a_registered_plan_runs_through_the_runners_own_commands():
    # Probe expands into a stage move and a force average: the move goes through the runner (recorded set-point,
    # force checked), and what the sub-plan returns is the reply.
    def probe(msg):
        yield MoveStage(msg.position_m)
        force = yield ReadForce(0.05)
        yield RecordEvent("probe", "probed", {"force_N": force})
        return force

    replies = []

    def plan():
        replies.append((yield Probe(1e-3)))

    result, rec, rig = run_plan(plan(), setup=lambda r: r.register_plan(Probe, probe))
    assert result.ok and len(replies) == 1
    assert rig.stage.position == pytest.approx(1e-3)
    assert rec.scalars["/stage/command"], "the move was recorded as a set-point"
    assert [e for e in rec.events if e[1] == "probe"][0][4]["force_N"] == replies[0]


def test_a_message_without_a_command_fails_the_run_and_ends_safe():
    def plan():
        yield Ping(1.0)

    rig, rec = fake_rig(), FakeRecorder()
    with pytest.raises(TypeError, match="no command for Ping"):  # a bug in a plan: re-raised after the safe end
        Runner(rig, rec).run_plan(plan(), "test")
    assert rec.closed[0] == "failed" and "no command for Ping" in rec.closed[1]
    assert rig.amp_drive.zeroed and rig.amp_bias.zeroed and rig.stage.stopped


def test_command_gives_the_handler_to_wrap():
    calls = []

    def setup(runner):
        dwell = runner.command(Dwell)

        def counted(msg):
            calls.append(msg.duration_s)
            return dwell(msg)

        runner.register_command(Dwell, counted)

    def plan():
        yield Dwell(0.1)
        yield Dwell(0.2)

    result, rec, _ = run_plan(plan(), setup=setup)
    assert result.ok and calls == [0.1, 0.2] and rec.scalars["/force"]


def test_request_abort_from_another_thread_ends_the_run_as_ctrl_c_does():
    # A long protocol; another thread asks for an abort once the run is under way (the fake rig's virtual clock
    # moves only as the runner waits, so the request is made when the virtual clock has passed 2 s).
    rig = fake_rig()
    protocol = get_protocol("static")
    params = load_params(protocol.Params(), None, [])
    rec = FakeRecorder()
    runner = Runner(rig, rec)
    done = threading.Event()
    requested = threading.Event()
    clock_sleep = rig.clock.sleep

    def sleep_until_requested(duration_s):
        # past 2 s the run waits for the other thread's request, so a loaded machine that schedules that thread
        # late cannot let the whole protocol finish first
        clock_sleep(duration_s)
        if rig.clock.now_s() >= 2.0:
            requested.wait(10.0)

    rig.clock.sleep = sleep_until_requested

    def abort_when_running():
        while rig.clock.now_s() < 2.0 and not done.is_set():
            done.wait(0.001)
        runner.request_abort("stop pressed in the live view")
        runner.request_abort("a second request")  # the first reason is the one recorded
        requested.set()

    thread = threading.Thread(target=abort_when_running)
    thread.start()
    try:
        result = runner.run(protocol, params)
    finally:
        done.set()
        thread.join()
    assert result.exit_status == "aborted"
    assert result.reason == "abort requested: stop pressed in the live view"
    assert rec.closed == ("aborted", result.reason)
    assert rig.amp_drive.zeroed and rig.amp_bias.zeroed and rig.stage.stopped
    kinds = [e[1] for e in rec.events]
    assert kinds[-2:] == ["safe_state", "run_end"]


def test_abort_requested_before_the_run_starts_stops_it_before_the_first_step():
    def plan():
        yield Step(0, "never", {})

    rig = fake_rig()
    rec = FakeRecorder()
    runner = Runner(rig, rec)
    runner.request_abort("operator left")
    result = runner.run_plan(plan(), "test")
    assert result.exit_status == "aborted" and "operator left" in result.reason
    assert not [e for e in rec.events if e[1] == "step"]
    assert rig.stage.stopped
