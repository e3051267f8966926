"""Recordings the replay tests share: short simulated runs made once per session through the real drivers and
emulators (the same path as `hamr-bench run`)."""

from __future__ import annotations

from pathlib import Path

import pytest

from hamr_bench.protocols.session import RunRequest, run_protocol

SHORT = ["repetitions=2", "voltages_V=150,250", "drive.cycles=1", "drive.dwell_high_s=0.2", "drive.dwell_low_s=0.2"]
SOURCE_SEED = 3
SOURCE_EFFECTS = {"amplifier_gain_error": 0.12}


def record(out: Path, protocol: str = "blocked-force", options=SHORT, seed: int = SOURCE_SEED,
           effects=SOURCE_EFFECTS, faults=()) -> Path:
    result = run_protocol(RunRequest(protocol=protocol, out=out, seed=seed, effects=dict(effects),
                                     set_options=list(options), faults=list(faults)))
    assert result.exit_status in ("success", "failed", "aborted")
    return out


@pytest.fixture(scope="session")
def source_run(tmp_path_factory) -> Path:
    return record(tmp_path_factory.mktemp("source") / "run.mcap")
