"""Every fault the emulators can inject (sim_devices/faults.py, per --fault target), through the real command line:
the run ends with 0 V on both DAQ outputs and the stage stopped within SAFE_BOUND_S of the fault (measured on the
emulators, not taken from the runner's own events), the recording is closed with exit_status and the reason, the
message is one line, the exit code non-zero, and no sample taken before the fault is lost (compared sample by
sample with a run of the same seed that the fault did not touch).

Each fault runs once here, on a protocol that uses the device it breaks; every protocol appears. The full fault x
protocol matrix, at two moments of each protocol, is `python -m benchmarks.reliability_campaign --matrix`.
"""

from __future__ import annotations

import pytest

from tests.reliability.harness import (
    ALL_FAULTS,
    IN_TRANSIT_S,
    PROTOCOL_NAMES,
    loss_allowed,
    takes_the_daq,
    expected_safe_bound_s,
    fault_moments,
    reference_samples,
    run_fault_case,
)

# (protocol, fault target:name, moment). Camera faults go where the camera is used; the rest spread over protocols.
CASES = (
    [("blocked-force", f, "drive") for f in ALL_FAULTS if not f.startswith("camera:")]
    + [("free-displacement", f, "drive") for f in ALL_FAULTS if f.startswith("camera:")]
    + [("sag-sweep", "stage:following_error", "search"), ("sag-sweep", "force_sensor:overload", "search"),
       ("static", "stage:end_of_run", "drive"), ("static", "force_sensor:no_reply", "drive"),
       ("actuator", "force_sensor:disconnect", "search"), ("actuator", "stage:following_error", "search"),
       ("free-displacement", "daq:amp_trip", "drive")]
)


def test_cases_cover_every_fault_and_every_protocol():
    assert {f for _, f, _ in CASES} == set(ALL_FAULTS)
    assert {p for p, _, _ in CASES} == set(PROTOCOL_NAMES)


@pytest.mark.parametrize("protocol, fault, moment", CASES, ids=[f"{p}-{f}-{m}" for p, f, m in CASES])
def test_fault_ends_safe_and_keeps_earlier_samples(tmp_path_factory, protocol, fault, moment):
    at_s = fault_moments(protocol, tmp_path_factory)[moment]
    reference = reference_samples(protocol, at_s, tmp_path_factory)
    outcome = run_fault_case(protocol, f"{fault}@{at_s}", tmp_path_factory.mktemp("f") / "run.mcap", reference)

    # the fault landed in the phase it is meant to test (guards against the protocols' timelines moving)
    assert outcome.triggered, f"{fault} in {protocol} at {at_s} s went unnoticed"
    assert outcome.phase == moment, f"{fault} at {at_s} s hit {protocol} in its {outcome.phase} phase"
    assert outcome.code != 0
    assert len(outcome.stderr_lines) == 1 and outcome.stderr_lines[0].startswith("hamr-bench: run failed")
    assert outcome.exit_status == "failed" and outcome.reason
    assert outcome.safe_event_s is not None and outcome.safe_event_s >= at_s
    assert loss_allowed(protocol, fault, outcome), (
        f"samples taken before the fault are missing: {outcome.lost} (older than {IN_TRANSIT_S} s: "
        f"{outcome.lost_early}, oldest {outcome.fault_s - outcome.oldest_lost_s:.3f} s before the fault)")
    t0_s = outcome.first_use_s  # the fault time, or when an idle DAQ / camera was next used
    assert outcome.safe.stage_still_at_s <= outcome.safe.end_s
    assert outcome.safe.stage_still_at_s - t0_s <= expected_safe_bound_s()
    zeroed = all(z <= outcome.safe.end_s for z in outcome.safe.zero_V_at_s.values())
    if takes_the_daq(protocol, fault) and not zeroed:
        # The DAQ itself is gone with a voltage on: 0 V cannot be commanded through it; the reason must say so.
        assert "while making safe" in outcome.reason
        return
    for channel, zero_s in outcome.safe.zero_V_at_s.items():
        assert zero_s - t0_s <= expected_safe_bound_s(), f"{channel} not at 0 V {zero_s - t0_s:.3f} s after"
