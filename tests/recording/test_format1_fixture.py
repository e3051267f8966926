"""Old recordings still read: a file written by the format-1 recorder (tests/data/make_format1_fixture.py says how
it was made, from the commit before format 2) reads back, through `RecordingReader` and through the `mcap` package,
with the values that script wrote, recomputed here."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap.reader import make_reader

from hamr_bench.recording import RecordingReader

FIXTURE = Path(__file__).parent.parent / "data" / "format1-recording.mcap"


def test_a_format1_recording_reads_back_as_written():
    r = RecordingReader(FIXTURE)
    assert r.metadata()["recording"]["format_version"] == "1"
    assert r.exit_status == "success" and not r.partial
    i = np.arange(400)
    force = r.scalars("/force")
    np.testing.assert_array_equal(force["time_s"], i * 1e-3)
    np.testing.assert_array_equal(force["force_N"], 1e-3 * np.sin(i / 20))
    np.testing.assert_array_equal(r.scalars("/amplifier/drive/command")["voltage_V"], i / 4)
    np.testing.assert_array_equal(r.scalars("/stage/position")["time_s"], i[::20] * 1e-3)
    disp = r.scalars("/camera/displacement")
    np.testing.assert_array_equal(disp["x_px"], 16.0 + i[::50] / 100)
    frames = list(r.images("/camera/image"))
    assert [f.format for f in frames] == ["raw"] * 8 and all(f.origin_px == (0, 0) for f in frames)
    rng = np.random.default_rng(7)
    for k, frame in zip(i[::50], frames, strict=True):
        expected = rng.integers(0, 4, size=(24, 32), dtype=np.uint8)
        expected[10:14, 14 + k // 100:18 + k // 100] = 200
        np.testing.assert_array_equal(frame.pixels(), expected)
        assert abs(frame.time_s - k * 1e-3) < 1e-9
    events = r.events()
    assert [e.kind for e in events] == ["run_start", "step", "safe_state", "run_end"]
    assert events[1].data == {"voltage_V": 100.0, "repetition": 0, "direction": "up"}
    assert [t.data for t in r.traffic("/traffic/stage")] == [b"1TP?\r\n", b"1TP0.001\r\n"]
    assert "/log" not in r.topics() and "/step" not in r.topics()  # format 1 had neither


def test_the_mcap_package_reads_the_format1_fixture_too():
    with open(FIXTURE, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        counts: dict[str, int] = {}
        for _, channel, _ in reader.iter_messages(log_time_order=True):
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    assert counts["/force"] == 400 and counts["/camera/image"] == 8 and counts["/events"] == 4
