"""The actuator protocol's undriven stiffness sweep: its plan (loading then unloading past contact at 0 V, before
the driven steps), its parameter checks, and the runner's force limit while it pushes."""

import pytest

from hamr_bench.errors import ConfigError
from hamr_bench.protocols import get_protocol
from hamr_bench.protocols.actuator import MAX_PUSH_M, Params, StiffnessParams, plan, step_count
from hamr_bench.protocols.params import load_params
from hamr_bench.protocols.plan import Drive, Dwell, FindContact, MoveStage, SetVoltages, Step
from hamr_bench.protocols.runner import Runner
from tests.protocols.fakes import FakeRecorder, fake_rig

ZERO_M = 2.0e-3


def messages(p: Params) -> list:
    """The plan's messages, answering the contact search with ZERO_M."""
    gen, out, reply = plan(p), [], None
    while True:
        try:
            msg = gen.send(reply)
        except StopIteration:
            return out
        out.append(msg)
        reply = ZERO_M if isinstance(msg, FindContact) else None


def test_sweep_loads_then_unloads_past_contact_undriven_before_any_drive():
    p = Params(repetitions=1, voltages_V=(100.0,))
    msgs = messages(p)
    steps = [m for m in msgs if isinstance(m, Step)]
    sweep = [s for s in steps if s.condition["mode"] == "stiffness"]
    pushes = [s.condition["sag_m"] for s in sweep]
    directions = [s.condition["direction"] for s in sweep]
    # 6 equal pushes up to 30 um, then back down: one reversal at the top
    assert pushes == pytest.approx([5e-6, 10e-6, 15e-6, 20e-6, 25e-6, 30e-6, 25e-6, 20e-6, 15e-6, 10e-6, 5e-6])
    assert directions == ["up"] * 6 + ["down"] * 5
    assert all(s.condition["voltage_V"] == 0.0 for s in sweep)
    assert steps[:len(sweep)] == sweep and [s.index for s in steps] == list(range(len(steps)))
    assert step_count(p) == len(steps)
    # each step's stage target is zero sag + its push, set before the step; nothing is driven before the sweep
    # ends, and the last voltage command before it is 0 V
    first_drive = next(i for i, m in enumerate(msgs) if isinstance(m, Drive))
    for s in sweep:
        i = msgs.index(s)
        move = next(m for m in reversed(msgs[:i]) if isinstance(m, MoveStage))
        assert move.position_m == pytest.approx(ZERO_M + s.condition["sag_m"])
        assert isinstance(msgs[i + 1], Dwell) and msgs[i + 1].duration_s == p.stiffness.hold_s
        assert i < first_drive
        volts = [m for m in msgs[:i] if isinstance(m, SetVoltages)]
        assert volts and volts[-1].bias_V == 0.0 and volts[-1].drive_V == 0.0
    # back at zero sag before the blocked steps, reached from below (past the stage's play, as the contact search
    # leaves it), not coming down from the last push
    after = msgs.index(sweep[-1])
    first_blocked = msgs.index(next(s for s in steps if s.condition["mode"] == "blocked"))
    back = [m.position_m for m in msgs[after:first_blocked] if isinstance(m, MoveStage)]
    assert back == pytest.approx([ZERO_M - p.contact.clearance_m, ZERO_M])


def test_zero_steps_means_no_sweep():
    p = Params(repetitions=1, voltages_V=(100.0,), stiffness=StiffnessParams(steps=0))
    steps = [m for m in messages(p) if isinstance(m, Step)]
    assert steps and all(s.condition["mode"] != "stiffness" for s in steps)
    assert step_count(p) == len(steps)


@pytest.mark.parametrize("option, field", [
    (f"stiffness.max_push_m={2 * MAX_PUSH_M}", "stiffness max_push_m"),
    ("stiffness.max_push_m=-1e-6", "stiffness max_push_m"),
    ("stiffness.steps=-1", "stiffness steps"),
    ("stiffness.hold_s=0", "stiffness hold_s"),
    ("stiffness.settle_s=-0.1", "stiffness settle_s"),
])
def test_bad_sweep_parameters_name_the_field(option, field):
    with pytest.raises(ConfigError) as err:
        load_params(Params(), None, [option])
    assert field in str(err.value) and "\n" not in str(err.value)


def test_runner_force_limit_stops_the_sweep():
    """A tip of 2000 N/m pushed 30 um presses 60 mN: with a 30 mN limit the run aborts during the sweep, the
    overshoot is at most one push increment's worth, and the stage is not moved toward the tip again."""
    k = 2000.0
    rig = fake_rig(force_limit_N=0.03, k_N_per_m=k)
    protocol = get_protocol("actuator")
    params = load_params(protocol.Params(), None, ["repetitions=1", "voltages_V=100", "drive.cycles=1"])
    rec = FakeRecorder()
    result = Runner(rig, rec).run(protocol, params)
    assert result.exit_status == "aborted" and "exceeds the limit" in result.reason
    kinds = [e[1] for e in rec.events]
    assert "drive_start" not in kinds   # stopped in the sweep, before any drive
    over_time = next(t for t, f in rec.scalars["/force"] if f["force_N"] > 0.03)
    later = [f["target_m"] for t, f in rec.scalars["/stage/command"] if t > over_time]
    assert not later
    step_m = params.stiffness.max_push_m / params.stiffness.steps
    assert max(f["force_N"] for _, f in rec.scalars["/force"]) <= 0.03 + k * step_m + 1e-12
    assert rig.amp_drive.zeroed and rig.stage.stopped
