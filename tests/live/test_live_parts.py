"""The live view's parts on their own: `--live` parsing, peak decimation, the tap's bounded queue, the control
token check."""

from __future__ import annotations

import json

import numpy as np
import pytest

from hamr_bench.errors import ConfigError
from hamr_bench.live.control import AbortControl, ControlRefused
from hamr_bench.live.decimate import peak_indices
from hamr_bench.live.options import LiveOptions
from hamr_bench.live.tap import LiveTap


@pytest.mark.parametrize("text, host, port, local", [
    ("8765", "127.0.0.1", 8765, True), ("0", "127.0.0.1", 0, True), ("localhost:9000", "localhost", 9000, True),
    ("0.0.0.0:8765", "0.0.0.0", 8765, False), ("[::1]:8765", "::1", 8765, True)])
def test_live_address(text, host, port, local):
    options = LiveOptions.parse(text)
    assert (options.host, options.port, options.is_local) == (host, port, local)


@pytest.mark.parametrize("text", ["", "abc", ":80", "host:99999", "[::1]8765"])
def test_bad_live_address_is_one_clear_error(text):
    with pytest.raises(ConfigError, match="--live"):
        LiveOptions.parse(text)


def test_peak_decimation_keeps_a_one_sample_spike_and_the_envelope():
    rng = np.random.default_rng(0)
    values = rng.normal(0.0, 1.0, 10_000)
    values[4321] = 50.0
    values[777] = -40.0
    picked = peak_indices(values, 200)
    assert len(picked) <= 200 and np.all(np.diff(picked) > 0)
    assert 4321 in picked and 777 in picked
    np.testing.assert_array_equal(peak_indices(values[:50], 200), np.arange(50))  # few enough: all of them


def test_the_tap_drops_the_oldest_when_nobody_reads_and_counts_them():
    tap = LiveTap(max_items=100)
    for k in range(250):
        tap.message(0, k * 1e-3, b"x")
    items = tap.take_items()
    assert len(items) == 100 and items[0][1] == pytest.approx(0.150) and tap.dropped == 150
    tap.message(0, 1.0, b"y")
    assert tap.take_items() == [(0, 1.0, b"y")] and tap.dropped == 150


def test_control_needs_the_token_and_passes_the_reason_on():
    asked = []
    control = AbortControl("s3cret")
    control.set_target(asked.append)
    for bad in (b"not json", b"[]", json.dumps({"reason": "x"}).encode(), json.dumps({"token": "s3cre"}).encode()):
        with pytest.raises(ControlRefused, match="refused"):
            control.handle(bad, "#1")
    assert asked == [] and control.refused == 4 and control.requested is None
    reply = control.handle(json.dumps({"token": "s3cret", "reason": "sensor\\nloose"}).encode(), "#2")
    assert reply["accepted"] is True and asked == ["live client #2: sensor\\nloose"]
    assert control.requested == "sensor\\nloose"
