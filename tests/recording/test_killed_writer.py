"""A recorder killed with SIGKILL mid-run loses at most its last second: `recover` gets back every sample that was
handed to it more than one second before the kill.

The writer runs in a child process on a real clock, writing one `/force` sample per millisecond whose value is its
sequence number k and whose time_s is the clock reading when it was handed over. Every 20 samples it prints
"k time_s" after the hand-over, so the test knows, from the child itself, which samples existed by when. The test
kills it once the child has run for >= 2 s, converts the kill's wall time to the child's time axis through the
recording's start epoch, and checks that every sample printed at least 1 s before the kill is in the recovered file.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import numpy as np
import pytest

from hamr_bench.recording import RecordingReader, RecordingWarning
from hamr_bench.recording.recover import RECOVERED_REASON, recover

CHILD = textwrap.dedent(
    """
    import sys, time
    from hamr_bench.clock import RealClock
    from hamr_bench.recording import Recorder

    clock = RealClock()
    start_ns = time.time_ns()  # the wall time of clock.now_s() == 0 (to well under a millisecond)
    rec = Recorder(sys.argv[1], flush_interval_s=0.5, start_time_ns=start_ns)
    rec.add_metadata("rig", {"path": "killed-test"})
    print("start", start_ns, flush=True)
    k = 0
    while True:
        t = clock.now_s()
        rec.write_scalar("/force", t, force_N=float(k))
        if k % 20 == 0:
            print(k, repr(t), flush=True)
        k += 1
        clock.sleep(0.001)
    """
)


@pytest.mark.slow
def test_sigkill_then_recover_keeps_everything_older_than_one_second(tmp_path):
    path = tmp_path / "killed.mcap"
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(path)], stdout=subprocess.PIPE, text=True, env={**os.environ}
    )
    progress: list[tuple[int, float]] = []
    try:
        first = child.stdout.readline().split()
        assert first[0] == "start", first
        start_ns = int(first[1])
        kill_after_s = 2.0 + 0.5 * np.random.default_rng().random()  # a moment >= 2 s into the run
        while True:
            line = child.stdout.readline()
            assert line, "writer exited early"
            k, t = line.split()
            progress.append((int(k), float(t)))
            if (time.time_ns() - start_ns) / 1e9 >= kill_after_s:
                break
        kill_ns = time.time_ns()
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=10)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    t_kill_s = (kill_ns - start_ns) / 1e9
    progress += [tuple(map(float, line.split())) for line in child.stdout.read().splitlines() if line.strip()]

    # The killed file itself reads partially, with a warning.
    with pytest.warns(RecordingWarning, match="writer did not finish"):
        assert RecordingReader(path).partial

    report = recover(path, tmp_path / "recovered.mcap")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the recovered file must read with no warning at all
        r = RecordingReader(tmp_path / "recovered.mcap", validate_crcs=True)
    assert not r.partial
    assert r.exit_status == "failed" and r.exit_reason == RECOVERED_REASON
    assert r.metadata()["rig"] == {"path": "killed-test"}
    force = r.scalars("/force")
    ks = force["force_N"]
    assert report.messages_recovered == len(ks)
    np.testing.assert_array_equal(ks, np.arange(len(ks)))  # a gap-free prefix of what was written
    assert np.all(np.diff(force["time_s"]) > 0)
    must_have = [k for k, t in progress if t <= t_kill_s - 1.0]
    assert must_have, "the run was too short to test the one-second bound"
    assert ks[-1] >= max(must_have), (
        f"lost sample {max(must_have)} handed over >= 1 s before the kill (t_kill={t_kill_s:.3f} s); "
        f"recovered up to {ks[-1]:.0f} at {force['time_s'][-1]:.3f} s"
    )
    print(f"kill at {t_kill_s:.3f} s, newest recovered sample {force['time_s'][-1]:.3f} s")
    assert report.last_time_s == pytest.approx(force["time_s"][-1], abs=1e-6)
