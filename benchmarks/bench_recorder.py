"""Recorder benchmark: sustained synthetic bench load, CPU share, drops, and throughput against the raw MCAP writer.

Load (per second of run): 10,000 `/force` samples, 1,000 `/stage/position`, 1,000 `/amplifier/drive/monitor`, and
100 grey 640x480 frames on `/camera/image` (arrays, so the recorder's PNG encoding is part of its cost).

Figures printed:
1. Encoding candidates for one scalar sample (encode alone, and encode + `Writer.add_message`): why scalars are
   protobuf written through a fixed struct layout.
2. Sustained real-time load for `--duration-s` (paced by `RealClock`): recorder CPU share of one core = (process
   CPU with the recorder - process CPU of the same producer loop writing to a null sink) / wall time; the writer
   thread's own share (from /proc); dropped samples; file size. Once with the camera, once scalars only.
3. Throughput: the same messages (5 s of load) written as fast as possible, best of 3 alternating passes, once
   through the raw `mcap.writer.Writer` (payloads encoded beforehand, same chunk size, compression and CRCs, fsync
   at the end) and once through `Recorder` (scalars as numbers, frames as the same PNG bytes, `when_full="block"`
   with a 20,000-message / 16 MiB queue); ratio = raw time / recorder time, also given in CPU time.

Run: `python -m benchmarks.bench_recorder [--duration-s 60] [--compression lz4|zstd|none]
[--image-format png|jpeg] [--json]`.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from hamr_bench.clock import RealClock
from hamr_bench.recording import Recorder
from hamr_bench.recording import schemas
from hamr_bench.recording.contract import Topic
from hamr_bench.recording.images import encode_png_stored

FORCE_HZ, STAGE_HZ, VOLTAGE_HZ, CAMERA_FPS = 10_000, 1_000, 1_000, 100
TICK_S = 0.01  # the producer hands over one tick's worth of samples at a time, like a driver's read_stream()
WIDTH, HEIGHT = 640, 480
IMAGE_FORMAT = ["png"]  # format the sustained run asks write_image for (set from --image-format)


def synthetic_frames(n: int = 8, seed: int = 0) -> list[np.ndarray]:
    """Grey frames with a Gaussian marker and sensor noise (noise is what makes camera images hard to compress)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:HEIGHT, 0:WIDTH]
    frames = []
    for k in range(n):
        cx = WIDTH / 2 + 20 * np.sin(2 * np.pi * k / n)
        img = 80 + 120 * np.exp(-((xx - cx) ** 2 + (yy - HEIGHT / 2) ** 2) / (2 * 12.0**2))
        frames.append(np.clip(img + rng.normal(0, 2.0, img.shape), 0, 255).astype(np.uint8))
    return frames


def _tick_samples(tick: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t0 = tick * TICK_S
    force_t = t0 + np.arange(int(FORCE_HZ * TICK_S)) / FORCE_HZ
    slow_t = t0 + np.arange(int(STAGE_HZ * TICK_S)) / STAGE_HZ
    return force_t, slow_t, 0.05 * np.sin(2 * np.pi * 10 * force_t)


class _NullSink:
    def write_scalar(self, topic: str, time_s: float, **fields: float) -> None:
        pass

    def write_image(self, topic: str, time_s: float, image: Any, format: str = "png") -> None:  # noqa: A002
        pass


def _produce_tick(sink: Any, tick: int, frames: list[np.ndarray] | None) -> None:
    force_t, slow_t, force = _tick_samples(tick)
    for t, f in zip(force_t.tolist(), force.tolist(), strict=True):
        sink.write_scalar(Topic.FORCE, t, force_N=f)
    for t in slow_t.tolist():
        sink.write_scalar(Topic.STAGE_POSITION, t, position_m=1e-3 * t)
        sink.write_scalar(Topic.DRIVE_MONITOR, t, voltage_V=200.0)
    if frames:
        sink.write_image(Topic.CAMERA_IMAGE, tick * TICK_S, frames[tick % len(frames)], IMAGE_FORMAT[0])


def _thread_cpu_s(native_id: int | None) -> float:
    if native_id is None:  # the thread has not started
        return float("nan")
    try:
        fields = Path(f"/proc/self/task/{native_id}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def _paced_run(sink: Any, duration_s: float, frames: list[np.ndarray] | None) -> tuple[float, float]:
    """Feed `sink` in real time; returns (wall s, process CPU s)."""
    clock = RealClock()
    cpu0, wall0 = time.process_time(), time.perf_counter()
    for tick in range(int(round(duration_s / TICK_S))):
        clock.sleep((tick + 1) * TICK_S - clock.now_s())
        _produce_tick(sink, tick, frames)
    return time.perf_counter() - wall0, time.process_time() - cpu0


def sustained(duration_s: float, out_dir: Path, compression: str, frames: list[np.ndarray] | None) -> dict[str, Any]:
    """Real-time load; `frames=None` leaves the camera out (the protocols that do not film)."""
    _, null_cpu = _paced_run(_NullSink(), duration_s, frames)
    path = out_dir / "sustained.mcap"
    cpu0, wall0 = time.process_time(), time.perf_counter()
    rec = Recorder(path, overwrite=True, compression=compression)
    wall_run, _ = _paced_run(rec, duration_s, frames)
    writer_cpu = _thread_cpu_s(rec._thread.native_id)  # read before close: the thread ends there
    stats = rec.close("success")
    wall = time.perf_counter() - wall0
    cpu = time.process_time() - cpu0
    return {
        "duration_s": duration_s,
        "wall_s": wall,
        "recorder_cpu_share_of_one_core": (cpu - null_cpu) / wall,
        "writer_thread_cpu_share": writer_cpu / wall_run,
        "producer_null_sink_cpu_share": null_cpu / wall,
        "messages_written": sum(stats.written.values()),
        "dropped": stats.dropped_total,
        "dropped_by_topic": stats.dropped,
        "file_MB": path.stat().st_size / 1e6,
    }


def _all_messages(duration_s: float, frames: list[np.ndarray]) -> list[tuple[str, float, Any]]:
    png = [encode_png_stored(f) for f in frames]
    messages: list[tuple[str, float, Any]] = []
    for tick in range(int(round(duration_s / TICK_S))):
        force_t, slow_t, force = _tick_samples(tick)
        messages += [(Topic.FORCE, t, f) for t, f in zip(force_t.tolist(), force.tolist(), strict=True)]
        for t in slow_t.tolist():
            messages.append((Topic.STAGE_POSITION, t, 1e-3 * t))
            messages.append((Topic.DRIVE_MONITOR, t, 200.0))
        messages.append((Topic.CAMERA_IMAGE, tick * TICK_S, png[tick % len(png)]))
    return messages


_FIELD: dict[str, str] = {Topic.FORCE: "force_N", Topic.STAGE_POSITION: "position_m", Topic.DRIVE_MONITOR: "voltage_V"}


def throughput(
    duration_s: float, out_dir: Path, compression: str, frames: list[np.ndarray], repeats: int = 3
) -> dict[str, Any]:
    """Best of `repeats` alternating passes over `duration_s` worth of messages."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    messages = _all_messages(duration_s, frames)
    start_ns = time.time_ns()

    # Raw writer: every payload encoded beforehand (the same bytes the recorder produces).
    encoded = []
    for topic, t, value in messages:
        if topic == Topic.CAMERA_IMAGE:
            msg = CompressedImage(frame_id="camera", format="png", data=value)
            msg.timestamp.FromNanoseconds(start_ns + round(t * 1e9))
            payload = msg.SerializeToString()
        else:
            payload = schemas.KNOWN_SCALAR_TOPICS[topic].packer()(t, {_FIELD[topic]: value})
        encoded.append((topic, start_ns + round(t * 1e9), payload))
    raw_times, rec_times, raw_cpu, rec_cpu = [], [], [], []
    for _ in range(repeats):  # alternate the two so load from other processes hits both alike
        cpu0 = time.process_time()
        raw_times.append(_raw_writer_pass(encoded, out_dir / "raw.mcap", compression))
        cpu1 = time.process_time()
        rec_s, stats = _recorder_pass(messages, out_dir / "throughput.mcap", compression, start_ns)
        rec_cpu.append(time.process_time() - cpu1)
        raw_cpu.append(cpu1 - cpu0)
        rec_times.append(rec_s)
    raw_s, rec_s = min(raw_times), min(rec_times)
    return {
        "messages": len(messages),
        "raw_writer_msg_per_s": len(messages) / raw_s,
        "recorder_msg_per_s": len(messages) / rec_s,
        "throughput_ratio": raw_s / rec_s,
        # The same comparison in CPU seconds: separates the recorder's own work from waiting on the GIL/scheduler.
        "cpu_ratio": min(raw_cpu) / min(rec_cpu),
        "dropped": stats.dropped_total,
        "repeats": repeats,
    }


def _raw_writer_pass(encoded: list[tuple[str, int, bytes]], path: Path, compression: str) -> float:
    from mcap.writer import CompressionType, Writer

    t0 = time.perf_counter()
    with open(path, "wb") as f:
        w = Writer(
            f,
            chunk_size=256 * 1024,
            compression={"lz4": CompressionType.LZ4, "zstd": CompressionType.ZSTD, "none": CompressionType.NONE}[
                compression
            ],
            enable_crcs=True,
            enable_data_crcs=True,
        )
        w.start()
        ids: dict[str, int] = {}
        for name in (Topic.FORCE, Topic.STAGE_POSITION, Topic.DRIVE_MONITOR, Topic.CAMERA_IMAGE):
            ids[name] = w.register_channel(name, "protobuf", w.register_schema(name, "protobuf", b""))
        for topic, log_ns, payload in encoded:
            w.add_message(ids[topic], log_ns, payload, log_ns, 0)
        w.finish()
        f.flush()
        os.fsync(f.fileno())
    return time.perf_counter() - t0


def _recorder_pass(
    messages: list[tuple[str, float, Any]], path: Path, compression: str, start_ns: int
) -> tuple[float, Any]:
    t0 = time.perf_counter()
    # As fast as possible means the producer outruns the writer: block on a bounded queue (what an offline writer
    # such as the importer does) rather than drop or pile up hundreds of MB of frames in memory.
    rec = Recorder(
        path, overwrite=True, compression=compression, start_time_ns=start_ns,
        max_queue_messages=20_000, max_queue_bytes=16 * 1024 * 1024, when_full="block",
    )
    for topic, t, value in messages:
        if topic == Topic.CAMERA_IMAGE:
            rec.write_image(topic, t, value, "png")
        elif topic == Topic.FORCE:
            rec.write_scalar(topic, t, force_N=value)
        elif topic == Topic.STAGE_POSITION:
            rec.write_scalar(topic, t, position_m=value)
        else:
            rec.write_scalar(topic, t, voltage_V=value)
    stats = rec.close("success")
    return time.perf_counter() - t0, stats


def encoding_candidates(n: int = 50_000, repeats: int = 5) -> dict[str, dict[str, float]]:
    """Per-sample cost (us) of encoding one force sample, alone and followed by `Writer.add_message` into an
    in-memory MCAP writer. Candidates are interleaved and the best of `repeats` kept, so load from other processes
    biases them alike."""
    from mcap.writer import CompressionType, Writer

    pack = schemas.FORCE.packer()
    cls = schemas.message_class(schemas.FORCE.name, schemas.FORCE.descriptor_set())
    candidates = {
        "protobuf_struct_layout": lambda t, f: pack(t, {"force_N": f}),
        "protobuf_message_class": lambda t, f: cls(time_s=t, force_N=f).SerializeToString(),
        "json_format_string": lambda t, f: ('{"time_s":%r,"force_N":%r}' % (t, f)).encode(),
        "json_dumps": lambda t, f: json.dumps({"time_s": t, "force_N": f}).encode(),
    }
    times = np.arange(n) / FORCE_HZ
    values = (0.05 * np.sin(times)).tolist()
    times_list = times.tolist()
    encode_only = {name: float("inf") for name in candidates}
    with_writer = {name: float("inf") for name in candidates}
    for _ in range(repeats):
        for name, encode in candidates.items():
            t0 = time.perf_counter()
            for t, f in zip(times_list, values):
                encode(t, f)
            encode_only[name] = min(encode_only[name], (time.perf_counter() - t0) / n * 1e6)
            w = Writer(io.BytesIO(), chunk_size=256 * 1024, compression=CompressionType.LZ4, enable_data_crcs=True)
            w.start()
            ch = w.register_channel(Topic.FORCE, "protobuf", w.register_schema("x", "protobuf", b""))
            t0 = time.perf_counter()
            for t, f in zip(times_list, values):
                log_ns = round(t * 1e9)
                w.add_message(ch, log_ns, encode(t, f), log_ns, 0)
            w.finish()
            with_writer[name] = min(with_writer[name], (time.perf_counter() - t0) / n * 1e6)
    return {"encode_only_us": encode_only, "encode_and_add_message_us": with_writer}


def run(duration_s: float = 10.0, compression: str = "lz4", out_dir: Path | None = None) -> dict[str, Any]:
    frames = synthetic_frames()
    with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
        tmp_path = Path(tmp)
        return {
            "load_average_before": os.getloadavg()[0],
            "compression": compression,
            "encoding": encoding_candidates(),
            "sustained": sustained(duration_s, tmp_path, compression, frames),
            "sustained_scalars_only": sustained(duration_s, tmp_path, compression, None),
            "throughput": throughput(min(duration_s, 5.0), tmp_path, compression, frames),
            "load_average_after": os.getloadavg()[0],
        }


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--duration-s", type=float, default=10.0)
    parser.add_argument("--compression", choices=("lz4", "zstd", "none"), default="lz4")
    parser.add_argument("--image-format", choices=("png", "jpeg"), default="png",
                        help="how the sustained run's frames are encoded (png: lossless, jpeg: quality 95)")
    parser.add_argument("--out-dir", type=Path, default=None, help="where the temporary files go (default: /tmp)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args(argv)
    IMAGE_FORMAT[0] = args.image_format
    result = run(args.duration_s, args.compression, args.out_dir)
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(
        f"load average (1 min) before/after: {result['load_average_before']:.2f} / "
        f"{result['load_average_after']:.2f} on this 2-core machine (other processes inflate every figure below)"
    )
    for label, key in (("encode only", "encode_only_us"), ("encode + add_message", "encode_and_add_message_us")):
        figures = result["encoding"][key]
        print(f"scalar sample, {label} (us): " + ", ".join(f"{k} {v:.2f}" for k, v in figures.items()))
    for label, key in (("with camera", "sustained"), ("scalars only", "sustained_scalars_only")):
        s = result[key]
        print(
            f"sustained {s['duration_s']:.0f} s {label} ({args.compression}, {args.image_format}): recorder CPU "
            f"{100 * s['recorder_cpu_share_of_one_core']:.1f} % of one core (writer thread "
            f"{100 * s['writer_thread_cpu_share']:.1f} %), dropped {s['dropped']}, {s['messages_written']} messages, "
            f"{s['file_MB']:.1f} MB"
        )
    t = result["throughput"]
    print(
        f"throughput: raw mcap Writer {t['raw_writer_msg_per_s']:.0f} msg/s, Recorder {t['recorder_msg_per_s']:.0f} "
        f"msg/s, ratio {t['throughput_ratio']:.2f} (in CPU time {t['cpu_ratio']:.2f}), dropped {t['dropped']}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
