"""Sustained acquisition: the recorder under the bench's full instrument load for a minute of real time, beside the
raw `mcap` writer doing the same job in the same run.

Load (per second, paced by `RealClock` in 10 ms ticks as a driver's read_stream would hand it over): 10,000 `/force`
samples, 1,000 `/stage/position`, 1,000 `/amplifier/drive/monitor`, 100 grey 640x480 frames on `/camera/image`
(arrays with sensor noise, so PNG encoding is part of the cost). See benchmarks/bench_recorder.py for the pieces.

Figures:
- dropped samples of the `Recorder` (its queue drops rather than stall a real-time caller; goal 0);
- recorder CPU share of one core = (process CPU with the recorder - process CPU of the same producer loop feeding
  a null sink) / wall time (goal < 25 %); the baseline is the same measurement for a synchronous raw
  `mcap.writer.Writer` sink (same encoding of every message, LZ4 chunks, CRCs, flush + fsync every 0.5 s);
- throughput: the same messages written as fast as possible, Recorder vs raw Writer (best of 3 alternating passes;
  goal ratio >= 0.8).

Run: `python -m benchmarks.bench_acquisition [--duration-s 60] [--json]`.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks import bench_recorder as br
from hamr_bench.recording import schemas
from hamr_bench.recording.images import encode_image


class RawWriterSink:
    """The baseline: what a program writing the same streams straight into `mcap.writer.Writer` does, in the
    caller's thread (every message encoded as the recorder encodes it; flush + fsync every `flush_interval_s`)."""

    def __init__(self, path: Path, compression: str = "lz4", flush_interval_s: float = 0.5) -> None:
        from mcap.writer import CompressionType, Writer

        self._file = open(path, "wb")
        self._w = Writer(self._file, chunk_size=256 * 1024,
                         compression={"lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD,
                                      "none": CompressionType.NONE}[compression],
                         enable_crcs=True, enable_data_crcs=True)
        self._w.start()
        self._channels: dict[str, tuple[int, Any]] = {}
        self._start_ns = time.time_ns()
        self._interval = flush_interval_s
        self._next_flush = time.monotonic() + flush_interval_s

    def _channel(self, topic: str, packer: Any) -> tuple[int, Any]:
        if topic not in self._channels:
            schema_id = self._w.register_schema(topic, "protobuf", b"")
            self._channels[topic] = (self._w.register_channel(topic, "protobuf", schema_id), packer)
        return self._channels[topic]

    def _add(self, channel_id: int, time_s: float, payload: bytes) -> None:
        log_ns = self._start_ns + round(time_s * 1e9)
        self._w.add_message(channel_id, log_ns, payload, log_ns, 0)
        if time.monotonic() >= self._next_flush:
            self._w.flush()
            os.fsync(self._file.fileno())
            self._next_flush = time.monotonic() + self._interval

    def write_scalar(self, topic: str, time_s: float, **fields: float) -> None:
        channel_id, pack = self._channels.get(topic) or self._channel(
            topic, schemas.scalar_schema_for(topic, tuple(fields)).packer())
        self._add(channel_id, time_s, pack(time_s, fields))

    def write_image(self, topic: str, time_s: float, image: np.ndarray, format: str = "png") -> None:  # noqa: A002
        from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

        channel_id, _ = self._channels.get(topic) or self._channel(topic, None)
        msg = CompressedImage(frame_id="camera", format=format, data=encode_image(image, format))
        msg.timestamp.FromNanoseconds(self._start_ns + round(time_s * 1e9))
        self._add(channel_id, time_s, msg.SerializeToString())

    def close(self) -> None:
        self._w.finish()
        self._file.flush()
        os.fsync(self._file.fileno())
        self._file.close()


def raw_sustained(duration_s: float, out_dir: Path, frames: list[np.ndarray], null_cpu_per_s: float) -> dict:
    sink = RawWriterSink(out_dir / "raw-sustained.mcap")
    cpu0, wall0 = time.process_time(), time.perf_counter()
    br._paced_run(sink, duration_s, frames)
    sink.close()
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    return {"duration_s": duration_s, "wall_s": wall, "cpu_share_of_one_core": (cpu - null_cpu_per_s * wall) / wall}


def run(duration_s: float = 60.0, throughput_s: float = 5.0, baseline_s: float | None = None) -> dict[str, Any]:
    """Sustained run of `duration_s` (recorder), the raw-writer baseline over `baseline_s` (default: the same,
    capped at 20 s: a CPU share is a rate), and the throughput comparison over `throughput_s` of messages."""
    frames = br.synthetic_frames()
    baseline_s = min(duration_s, 20.0) if baseline_s is None else baseline_s
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        sustained = br.sustained(duration_s, tmp_path, "lz4", frames)
        null_cpu_per_s = sustained["producer_null_sink_cpu_share"]
        (tmp_path / "sustained.mcap").unlink(missing_ok=True)
        raw = raw_sustained(baseline_s, tmp_path, frames, null_cpu_per_s)
        (tmp_path / "raw-sustained.mcap").unlink(missing_ok=True)
        throughput = br.throughput(throughput_s, tmp_path, "lz4", frames)
    return {"load_average_before": load0, "load_average_after": os.getloadavg()[0],
            "sustained": sustained, "raw_writer_sustained": raw, "throughput": throughput}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration-s", type=float, default=60.0)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    r = run(args.duration_s)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    s, raw, t = r["sustained"], r["raw_writer_sustained"], r["throughput"]
    print(f"load average {r['load_average_before']:.1f} -> {r['load_average_after']:.1f} on {os.cpu_count()} CPUs")
    print(f"sustained {s['duration_s']:.0f} s: recorder CPU {100 * s['recorder_cpu_share_of_one_core']:.1f} % of one "
          f"core (raw Writer sink {100 * raw['cpu_share_of_one_core']:.1f} %), dropped {s['dropped']}, "
          f"{s['messages_written']} messages, {s['file_MB']:.0f} MB")
    print(f"throughput: Recorder {t['recorder_msg_per_s']:.0f} msg/s vs raw Writer {t['raw_writer_msg_per_s']:.0f} "
          f"msg/s: ratio {t['throughput_ratio']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
