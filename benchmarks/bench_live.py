"""Live view and recording size: how late samples reach a Foxglove client at full acquisition load, what the recorder
and the live server cost together, and how many bytes a recorded second takes per protocol.

1. Latency and CPU (`live`): a paced real-time load for `--duration-s` (per second: 10,000 `/force`, 1,000 each of
   `/stage/position`, `/amplifier/drive/monitor`, `/amplifier/bias/monitor`, 100 grey 640x480 frames with a marker,
   handed over in 10 ms ticks as drivers hand over blocks, each frame with its marker position as the runner gives
   it) into a `Recorder` (default camera storage) with a live server (`--live`) and one client in ANOTHER process
   (benchmarks/foxglove_ws_client.py, the `websockets` package) subscribed to every topic. Latency = arrival at
   the client - the sample's own time (so the 0-10 ms of a driver's block is included). Goals: median <= 100 ms for
   samples, <= 200 ms for frames. CPU share of one core = (process CPU with recorder + live server - the same
   producer loop into a null sink) / wall time; goal < 30 %; baseline: the recorder alone, same load, same run.
   Dropped samples in the file: goal 0.
2. Bytes per recorded second (`bytes`): each protocol on the simulated bench, recorded with the default camera
   storage (`roi`) and with `full` (every frame kept raw, as format 1 kept them: the baseline).

Run: `python -m benchmarks.bench_live [--duration-s 20] [--quick] [--json]`.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import bench_recorder as br
from hamr_bench.clock import RealClock
from hamr_bench.recording import Recorder
from hamr_bench.recording.contract import Topic

TICK_S = 0.01
FORCE_HZ, SLOW_HZ, CAMERA_FPS = 10_000, 1_000, 100
PROTOCOLS = ("blocked-force", "sag-sweep", "free-displacement", "static", "actuator")
QUICK_SETTINGS = {  # shorter runs with the same kinds of steps (--quick)
    "blocked-force": ["voltages_V=100,250", "repetitions=1"],
    "sag-sweep": ["sags_m=0,0.002", "repetitions=1"],
    "free-displacement": ["voltages_V=100,250", "repetitions=1"],
    "static": ["max_sag_m=0.001"],
    "actuator": ["voltages_V=100,250", "repetitions=1"],
}


def _produce(sink: Any, tick: int, frames: list[np.ndarray], markers: list[tuple[float, float]]) -> None:
    t0 = tick * TICK_S
    force_t = (t0 + np.arange(int(FORCE_HZ * TICK_S)) / FORCE_HZ).tolist()
    force = (0.05 * np.sin(2 * np.pi * 10 * np.asarray(force_t))).tolist()
    for t, f in zip(force_t, force, strict=True):
        sink.write_scalar(Topic.FORCE, t, force_N=f)
    for t in (t0 + np.arange(int(SLOW_HZ * TICK_S)) / SLOW_HZ).tolist():
        sink.write_scalar(Topic.STAGE_POSITION, t, position_m=1e-3)
        sink.write_scalar(Topic.DRIVE_MONITOR, t, voltage_V=200.0)
        sink.write_scalar(Topic.BIAS_MONITOR, t, voltage_V=200.0)
    k = tick % len(frames)
    sink.write_image(Topic.CAMERA_IMAGE, t0, frames[k], marker_px=markers[k])


class _NullSink:
    def write_scalar(self, topic: str, time_s: float, **fields: float) -> None:
        pass

    def write_image(self, topic: str, time_s: float, image: Any, **options: Any) -> None:
        pass


def _paced(sink: Any, duration_s: float, frames: list[np.ndarray], markers: list[tuple[float, float]]) -> float:
    """Feed `sink` in real time from the clock's zero; returns the process CPU seconds spent."""
    clock = RealClock()
    cpu0 = time.process_time()
    for tick in range(int(round(duration_s / TICK_S))):
        clock.sleep((tick + 1) * TICK_S - clock.now_s())
        _produce(sink, tick, frames, markers)
    return time.process_time() - cpu0


def _frames() -> tuple[list[np.ndarray], list[tuple[float, float]]]:
    frames = br.synthetic_frames()
    markers = [(br.WIDTH / 2 + 20 * np.sin(2 * np.pi * k / len(frames)), br.HEIGHT / 2) for k in range(len(frames))]
    return frames, markers


def _recorded(path: Path, rec: Recorder, duration_s: float, frames: list[np.ndarray],
              markers: list[tuple[float, float]], before: Any = None) -> dict[str, Any]:
    wall0 = time.perf_counter()
    cpu = _paced(rec, duration_s, frames, markers)
    if before is not None:
        before()
    cpu0 = time.process_time()
    stats = rec.close("success")
    cpu += time.process_time() - cpu0
    wall = time.perf_counter() - wall0
    expected = int(round(duration_s / TICK_S)) * (int(FORCE_HZ * TICK_S) + 3 * int(SLOW_HZ * TICK_S))
    written = sum(n for topic, n in stats.written.items() if topic in (
        Topic.FORCE, Topic.STAGE_POSITION, Topic.DRIVE_MONITOR, Topic.BIAS_MONITOR))
    return {"wall_s": wall, "cpu_s": cpu, "dropped": stats.dropped_total, "samples_expected": expected,
            "samples_written": written, "file_MB": path.stat().st_size / 1e6}


def live_latency(duration_s: float, out_dir: Path) -> dict[str, Any]:
    from hamr_bench.live.options import LiveOptions
    from hamr_bench.live.session import LiveView

    frames, markers = _frames()
    null_cpu = _paced(_NullSink(), min(duration_s, 10.0), frames, markers) / min(duration_s, 10.0)
    alone = _recorded(out_dir / "alone.mcap", Recorder(out_dir / "alone.mcap", overwrite=True),
                      min(duration_s, 10.0), frames, markers)
    (out_dir / "alone.mcap").unlink()
    view = LiveView(LiveOptions("127.0.0.1", 0))
    view.start()
    client = subprocess.Popen([sys.executable, "-m", "benchmarks.foxglove_ws_client", view.url, "--seconds",
                               str(duration_s + 30)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              cwd=Path(__file__).resolve().parent.parent)
    try:
        time.sleep(1.0)  # the client connects before the load starts (its start-up is not what is measured)
        path = out_dir / "live.mcap"
        rec = Recorder(path, overwrite=True)
        view.follow(rec, lambda reason: None)
        live = _recorded(path, rec, duration_s, frames, markers, before=view.unfollow)
        published, tap_dropped = view.server.published, view.server.dropped_by_tap
        delays = sorted(view.server.publish_delays_ms)
    finally:
        view.stop()  # the client sees the connection close and prints its summary
        out, err = client.communicate(timeout=60)
    report: dict[str, Any] = json.loads(out) if out.strip() else {"topics": {}, "errors": [err[-500:]]}
    topics: dict[str, dict[str, float]] = report["topics"]
    scalars = (Topic.FORCE, Topic.STAGE_POSITION, Topic.DRIVE_MONITOR)
    images = (Topic.CAMERA_IMAGE, Topic.CAMERA_ROI)
    return {
        "duration_s": duration_s,
        "samples_median_ms": _worst(topics, scalars, "median_ms"),
        "samples_p95_ms": _worst(topics, scalars, "p95_ms"),
        "frames_median_ms": _worst(topics, images, "median_ms"),
        "frames_p95_ms": _worst(topics, images, "p95_ms"),
        "client_topics": topics, "client_errors": report.get("errors", []),
        "cpu_share_recorder_and_live": (live["cpu_s"] - null_cpu * live["wall_s"]) / live["wall_s"],
        "cpu_share_recorder_alone": (alone["cpu_s"] - null_cpu * alone["wall_s"]) / alone["wall_s"],
        "dropped_in_file": live["dropped"], "samples_expected": live["samples_expected"],
        "samples_written": live["samples_written"], "file_MB": live["file_MB"],
        "published_to_server": published, "dropped_by_live_tap": tap_dropped,
        "server_publish_age_median_ms": delays[len(delays) // 2] if delays else None,
    }


def _worst(topics: dict[str, dict[str, float]], names: tuple[str, ...], key: str) -> float | None:
    """The largest `key` among the topics of `names` that reached the client (None if none did)."""
    values = [topics[t][key] for t in names if t in topics]
    return max(values) if values else None


def bytes_per_second(quick: bool, out_dir: Path) -> dict[str, dict[str, float]]:
    """Per protocol: bytes per recorded second with the default camera storage and with `full`."""
    from hamr_bench.protocols.session import RunRequest, run_protocol
    from hamr_bench.recording import RecordingReader
    from hamr_bench.recording.camera_storage import CameraStorage

    out: dict[str, dict[str, float]] = {}
    for protocol in PROTOCOLS:
        row: dict[str, float] = {}
        for mode in ("roi", "full"):
            path = out_dir / f"{protocol}-{mode}.mcap"
            result = run_protocol(RunRequest(protocol=protocol, out=path, overwrite=True, seed=1,
                                             camera_storage=CameraStorage(mode),
                                             set_options=QUICK_SETTINGS[protocol] if quick else []))
            if not result.ok:
                raise RuntimeError(f"{protocol}: {result.reason}")
            spans = [(i.first_time_s, i.last_time_s) for i in RecordingReader(path).topics().values()
                     if i.first_time_s is not None and i.last_time_s is not None]
            seconds = max(b for _, b in spans) - min(a for a, _ in spans)
            row[f"{mode}_bytes_per_s"] = path.stat().st_size / seconds
            row["recorded_s"] = seconds
            path.unlink()
        row["ratio"] = row["roi_bytes_per_s"] / row["full_bytes_per_s"]
        out[protocol] = row
    return out


def run(duration_s: float = 20.0, quick: bool = False) -> dict[str, Any]:
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        live = live_latency(duration_s, Path(tmp))
        sizes = bytes_per_second(quick, Path(tmp))
    return {"load_average_before": load0, "load_average_after": os.getloadavg()[0], "live": live,
            "bytes_per_recorded_s": sizes}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--quick", action="store_true", help="shorter protocol runs for the bytes figures")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    r = run(args.duration_s, args.quick)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    live = r["live"]
    print(f"load average {r['load_average_before']:.1f} -> {r['load_average_after']:.1f} on {os.cpu_count()} CPUs")
    print(f"live, {live['duration_s']:.0f} s of full load: samples median {live['samples_median_ms']:.1f} ms "
          f"(p95 {live['samples_p95_ms']:.1f}), frames median {live['frames_median_ms']:.1f} ms "
          f"(p95 {live['frames_p95_ms']:.1f}); age when handed to the server's SDK: median "
          f"{live['server_publish_age_median_ms']:.1f} ms")
    print(f"CPU: recorder + live server {100 * live['cpu_share_recorder_and_live']:.1f} % of one core "
          f"(recorder alone {100 * live['cpu_share_recorder_alone']:.1f} %); dropped in the file "
          f"{live['dropped_in_file']} ({live['samples_written']} of {live['samples_expected']} samples written)")
    for protocol, row in r["bytes_per_recorded_s"].items():
        print(f"{protocol:18s} {row['roi_bytes_per_s'] / 1e3:9.1f} kB/s recorded (camera roi) vs "
              f"{row['full_bytes_per_s'] / 1e3:9.1f} kB/s (full frames): x{row['ratio']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
