"""A short soak: simulated runs back to back in one process, each with a random fault at a random moment (or none),
every one ending safe with a closed, CRC-valid recording, and nothing left behind from one run to the next: no
recorder thread, no open file, no simulated port still registered. The >= 10 virtual-minute soak per protocol with
its memory figure is `python -m benchmarks.reliability_campaign --soak 10`."""

from __future__ import annotations

import os
import threading

import numpy as np

from hamr_bench.recording import RecordingReader
from sim_devices import serial_link
from tests.reliability.harness import (
    ALL_FAULTS,
    UNREACHABLE_BY_SOFTWARE,
    fault_first_matters_s,
    measure_safe,
    run_cli,
    stage_stopped_in_time,
)

# Virtual length of the short runs (tests/reliability/harness.SHORT_SETTINGS), to put a fault inside one.
SPAN_S = {"blocked-force": 17.0, "free-displacement": 2.4}


def resources() -> tuple[int, int, int]:
    return threading.active_count(), len(os.listdir("/proc/self/fd")), len(serial_link._ENDPOINTS)


def test_runs_back_to_back_with_random_faults_end_safe_and_leave_nothing_behind(tmp_path):
    seed = int(np.random.SeedSequence().entropy % (1 << 32))
    rng = np.random.default_rng(seed)
    print(f"soak seed {seed}")
    baseline = None
    for k in range(6):
        protocol = ("free-displacement", "blocked-force")[k % 2]
        faults = () if k == 0 else (f"{ALL_FAULTS[rng.integers(len(ALL_FAULTS))]}@"
                                    f"{rng.uniform(0.0, SPAN_S[protocol]):.3f}",)
        out = tmp_path / f"run{k}.mcap"
        run = run_cli(protocol, out, faults=faults, seed=int(rng.integers(1 << 16)))
        reader = RecordingReader(out, validate_crcs=True)
        if run.bench is None:  # a device broken before the rig was even built (fault at ~0 s): refused, one line
            assert run.code == 2 and len(run.stderr_lines) == 1
            assert reader.exit_status == "failed" and reader.exit_reason.startswith("rig could not be built")
            continue
        assert reader.exit_status in ("success", "failed"), (faults, reader.exit_status)
        assert (run.code == 0) == (reader.exit_status == "success")
        assert len(run.stderr_lines) == (0 if run.code == 0 else 1)
        measure = measure_safe(run.bench, max(run.end_s - 5.0, 0.0), run.end_s)
        fault_s = min(fault_first_matters_s(faults[0], run), run.end_s) if faults else run.end_s
        assert stage_stopped_in_time(run.bench, faults[0] if faults else None, fault_s, run.end_s), faults
        zeroed = all(z <= run.end_s for z in measure.zero_V_at_s.values())
        assert zeroed or (faults[0].split("@")[0] in UNREACHABLE_BY_SOFTWARE and "while making safe" in
                          reader.exit_reason), (faults, reader.exit_reason)
        del reader, run
        if baseline is None:
            baseline = resources()
    assert resources() == baseline, f"threads, open files, registered ports: {resources()} vs {baseline}"
