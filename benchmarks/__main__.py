"""`python -m benchmarks [--quick] [--only NAME[,NAME...]] [--json]`: every benchmark in one run, each figure beside
a baseline measured in the same run (or, where none can be, the reference it is judged against, named in
`baseline_label`).

One record per figure: `name`, `value`, `unit`, `baseline`, `baseline_label`, `ratio` (its meaning in
`ratio_label`), `goal` ({"on": "value" | "ratio", "op": "<=" | ">=" | "==", "target": x} or null), `met`
(true / false, or null when there is no goal or the figure could not be measured), `note`, `details`. With
`--json` one JSON object is printed: {"machine": {...}, "quick": bool, "records": [...], "errors": {...}}.
A benchmark that fails is reported in `errors` (and its records carry met=null); the others still run.

`--quick` shortens everything (a few minutes in all): a 10 s acquisition run instead of 60 s, a reduced campaign
(design 4, 2 layers, every protocol), fewer tracking frames and replay repetitions. The machine is usually shared:
`machine` gives the load average before and after; figures in wall time suffer from other load, CPU-time figures
(given in `details`) much less.

Benchmarks (names for --only): model, tracking, serial, acquisition, live, campaign, replay, fit, gap, scaleout.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import shutil
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

ORDER = ("model", "tracking", "serial", "acquisition", "live", "campaign", "replay", "fit", "gap", "scaleout")


def goal(on: str, op: str, target: float) -> dict[str, Any]:
    return {"on": on, "op": op, "target": target}


def record(name: str, value: float | None, unit: str, baseline: float | None = None, baseline_label: str = "",
           ratio: float | None = None, ratio_label: str = "", goal_: dict | None = None, note: str = "",
           **details: Any) -> dict[str, Any]:
    """One figure; `met` follows from the goal and the value or ratio it is on."""
    met = None
    if goal_ is not None:
        x = value if goal_["on"] == "value" else ratio
        if x is not None and math.isfinite(x):
            t = goal_["target"]
            met = {"<=": x <= t, ">=": x >= t, "==": x == t, "<": x < t, ">": x > t}[goal_["op"]]
    return {"name": name, "value": value, "unit": unit, "baseline": baseline, "baseline_label": baseline_label,
            "ratio": ratio, "ratio_label": ratio_label, "goal": goal_, "met": met, "note": note,
            "details": details}


class Context:
    """What several benchmarks share: a scratch directory and the campaign's recordings."""

    def __init__(self, quick: bool, root: Path) -> None:
        self.quick = quick
        self.root = root
        self.campaign_dir: Path | None = None
        self.campaign_result: dict | None = None

    def campaign_subset(self) -> dict[str, tuple]:
        return {"designs": (4,), "layers": (2,)} if self.quick else {}

    def ensure_campaign(self) -> Path:
        """The campaign's recordings (run now if the campaign benchmark has not run)."""
        if self.campaign_dir is None:
            from benchmarks import bench_campaign

            out = self.root / "campaign"
            out.mkdir()
            # every named parameter given, so the subset's keys (designs, layers) can only be the subset's
            self.campaign_result = bench_campaign.run(jobs=None, set_options=None, out_dir=out, effects=None,
                                                      **self.campaign_subset())
            self.campaign_dir = out
        return self.campaign_dir


# ------------------------------------------------------------------------------------------------- benchmarks
def bench_model(ctx: Context) -> list[dict]:
    import numpy as np

    from benchmarks import bench_model
    from hamr_bench.model import powertrain

    r = bench_model.run()
    n = r["conditions"]
    vectorised = n / (r["blocked_force_ms"] / 1e3)
    # Baseline: the same model asked one condition per call (what a caller looping in Python gets).
    p = powertrain(4)
    rng = np.random.default_rng(1)
    m = 100 if ctx.quick else 300
    v, s = rng.uniform(0, 250, m), rng.uniform(0, 3e-3, m)
    t0 = time.process_time()
    for i in range(m):
        p.blocked_force_N(v[i], s[i])
    scalar = m / (time.process_time() - t0)
    return [record("model.leg_conditions_per_s", vectorised, "conditions/s", scalar,
                   "the same blocked-force model one condition per call", vectorised / scalar,
                   "vectorised / per-call", goal("value", ">=", 1e5),
                   note="10,000 random (voltage, sag) conditions of design 4, blocked force, best of 7, one core",
                   **{k: v for k, v in r.items()})]


def bench_tracking(ctx: Context) -> list[dict]:
    from benchmarks import bench_tracking

    r = bench_tracking.run(quick=ctx.quick)
    out = []
    # The estimator the rig builder uses: MarkerTracker(sigma) with its default ML refinement (gain unknown).
    for case in ("bright_8bit", "dim_8bit", "shot_limited_16bit"):
        c = r[case]
        e = c["ml_uniform"]
        out.append(record(f"tracking.crb_ratio.{case}", e["rms_error_px"], "px", c["crb_px"],
                          "Cramer-Rao bound of the rendered image model", e["ratio"], "RMS error / CRB",
                          goal("ratio", "<=", 1.5),
                          note=f"{c['frames']} frames; ratio uncertainty +/- {e['ratio_stat_uncertainty']:.3f}",
                          frames=c["frames"], signal_e=c["signal_e"], estimators={
                              k: c[k]["ratio"] for k in ("matched_filter", "ml_uniform", "ml_gain_known")}))
    sp = r["speed"]
    out.append(record("tracking.fps_640x480", sp["tracked_fps"], "frames/s", sp["full_search_fps"],
                      "full-frame search without a prior position (locate)",
                      sp["tracked_fps"] / sp["full_search_fps"], "tracked / full search",
                      goal("value", ">=", 1000), note="MarkerTracker.update on one core (cv2 single thread)",
                      max_error_px=sp["max_error_px"]))
    return out


def bench_serial(ctx: Context) -> list[dict]:
    import numpy as np

    from benchmarks.bench_serial import _pty_raw_round_trips_s
    from drivers.newport_smc100 import NewportSMC100
    from hamr_bench.clock import RealClock
    from sim_devices.pty_server import PtyServer
    from sim_devices.smc100_emulator import Smc100Emulator, Smc100Params
    from sim_devices.smc100_protocol import Smc100Protocol

    n = 100 if ctx.quick else 300
    clock = RealClock()

    def median_ms(params: Smc100Params, driver: bool = False) -> tuple[float, float]:
        with PtyServer(Smc100Protocol(Smc100Emulator(clock, params))) as server:
            raw = _pty_raw_round_trips_s(server.path, n)
            via = []
            if driver:
                stage = NewportSMC100(server.path, clock)
                for _ in range(n):
                    t0 = time.perf_counter()
                    stage.position_m()
                    via.append(time.perf_counter() - t0)
                stage.close()
        return 1e3 * float(np.median(raw)), (1e3 * float(np.median(via)) if via else float("nan"))

    default = Smc100Params()
    modelled_ms = 1e3 * (default.reply_latency_s + len(b"1TP0\r\n") * 10 / default.baudrate)
    # Transport alone: the same emulator with its modelled controller latency and wire time set to zero.
    bare = Smc100Params(reply_latency_s=0.0, baudrate=10**9)
    transport_ms, transport_driver_ms = median_ms(bare, driver=True)
    with_model_ms, _ = median_ms(default)
    return [record("serial.pty_round_trip_transport_ms", transport_ms, "ms", with_model_ms,
                   f"the same round trip with the emulator's modelled controller latency + wire time "
                   f"({modelled_ms:.2f} ms; the real SMC100 takes ~10 ms)", transport_ms / with_model_ms,
                   "transport / modelled round trip", goal("value", "<", 2.0),
                   note="1TP? over the pseudo-terminal, raw os.read/os.write, median; emulator latency 0",
                   through_driver_ms=transport_driver_ms, modelled_latency_ms=modelled_ms, exchanges=n)]


def bench_acquisition(ctx: Context) -> list[dict]:
    from benchmarks import bench_acquisition

    r = bench_acquisition.run(duration_s=10.0 if ctx.quick else 60.0, throughput_s=2.0 if ctx.quick else 5.0)
    s, raw, t = r["sustained"], r["raw_writer_sustained"], r["throughput"]
    load = {"load_average_before": r["load_average_before"], "load_average_after": r["load_average_after"]}
    return [
        record("acquisition.dropped_samples", s["dropped"], "samples", None, "", None, "", goal("value", "==", 0),
               note=f"{s['duration_s']:.0f} s real time: 10 kHz force, 1 kHz stage and voltage, 640x480 at 100 fps",
               messages_written=s["messages_written"], file_MB=s["file_MB"], **load),
        record("acquisition.recorder_cpu_share", 100 * s["recorder_cpu_share_of_one_core"], "% of one core",
               100 * raw["cpu_share_of_one_core"], "a synchronous raw mcap Writer sink under the same load",
               s["recorder_cpu_share_of_one_core"] / raw["cpu_share_of_one_core"], "recorder / raw writer",
               goal("value", "<", 25.0), note="process CPU minus the producer loop's own (null sink), per wall s",
               writer_thread_share_pct=100 * s["writer_thread_cpu_share"],
               producer_null_sink_share_pct=100 * s["producer_null_sink_cpu_share"], **load),
        record("acquisition.throughput", t["recorder_msg_per_s"], "messages/s", t["raw_writer_msg_per_s"],
               "raw mcap Writer, same messages pre-encoded, same chunking/compression/CRCs",
               t["throughput_ratio"], "recorder / raw writer", goal("ratio", ">=", 0.8),
               note="as fast as possible, best of 3 alternating passes", cpu_ratio=t["cpu_ratio"],
               messages=t["messages"], **load),
    ]


def bench_live(ctx: Context) -> list[dict]:
    from benchmarks import bench_live

    r = bench_live.run(duration_s=10.0 if ctx.quick else 30.0, quick=ctx.quick)
    live = r["live"]
    load = {"load_average_before": r["load_average_before"], "load_average_after": r["load_average_after"]}
    load_note = f"{live['duration_s']:.0f} s real time at full load: 10 kHz force, 1 kHz stage and voltages, " \
                "640x480 at 100 fps; a websockets client in another process subscribed to every topic"
    records = [
        record("live.sample_latency_median", live["samples_median_ms"], "ms", live["samples_p95_ms"],
               "95th percentile", None, "", goal("value", "<=", 100.0),
               note=f"{load_note}; worst topic's median, from the sample's own time to its arrival",
               topics=live["client_topics"], server_publish_age_median_ms=live["server_publish_age_median_ms"],
               client_errors=live["client_errors"], **load),
        record("live.frame_latency_median", live["frames_median_ms"], "ms", live["frames_p95_ms"],
               "95th percentile", None, "", goal("value", "<=", 200.0), note=load_note, **load),
        record("live.recorder_and_server_cpu_share", 100 * live["cpu_share_recorder_and_live"], "% of one core",
               100 * live["cpu_share_recorder_alone"], "the recorder alone, same load, same run",
               live["cpu_share_recorder_and_live"] / live["cpu_share_recorder_alone"], "with live / alone",
               goal("value", "<", 30.0), note="process CPU minus the producer loop's own (null sink), per wall s",
               published_to_server=live["published_to_server"], dropped_by_live_tap=live["dropped_by_live_tap"],
               **load),
        record("live.dropped_samples_in_file", live["dropped_in_file"], "samples", None, "", None, "",
               goal("value", "==", 0), note=f"{live['samples_written']} of {live['samples_expected']} written",
               **load),
    ]
    for protocol, row in r["bytes_per_recorded_s"].items():
        records.append(record(
            f"bytes_per_recorded_s.{protocol}", row["roi_bytes_per_s"], "B/s", row["full_bytes_per_s"],
            "every frame kept raw (--camera-storage full, format 1's storage)", row["ratio"], "roi / full",
            note=f"simulated bench, {row['recorded_s']:.0f} s recorded" + (" (shortened)" if ctx.quick else ""),
            **load))
    return records


def bench_campaign(ctx: Context) -> list[dict]:
    ctx.ensure_campaign()
    c = ctx.campaign_result
    assert c is not None
    scope = "reduced campaign (design 4, 2 layers)" if ctx.quick else "whole campaign"
    details = {k: c[k] for k in ("runs", "failed", "jobs", "cpu_s", "speedup_per_cpu_s")}
    return [
        record("campaign.speedup", c["speedup"], "x real time", 1.0, "real time", c["speedup"],
               "simulated s / wall s", goal("value", ">=", 100.0),
               note=f"{scope}: {c['simulated_s']:.0f} s simulated in {c['wall_s']:.1f} s wall "
                    f"({c['jobs']} processes); CPU-time speed-up {c['speedup_per_cpu_s']:.0f}x", **details),
        record("campaign.wall_s", c["wall_s"], "s", c["simulated_s"], "simulated duration (real time on a rig)",
               c["wall_s"] / c["simulated_s"], "wall / simulated", goal("value", "<", 120.0) if not ctx.quick else None,
               note=f"{scope}; issue 4 goal: the whole campaign under 2 minutes", **details),
    ]


def bench_replay(ctx: Context) -> list[dict]:
    from benchmarks import bench_replay

    r = bench_replay.run(quick=ctx.quick, repeats=1 if ctx.quick else 3)
    return [record("replay.speedup", r["overall_replay_speed_x"], "x real time", r["recorded_s"],
                   "the recordings' own duration (s)", r["overall_replay_speed_x"], "recorded s / replay wall s",
                   goal("value", ">=", 50.0),
                   note=f"{r['recorded_s']:.0f} s of recordings replayed in {r['replay_wall_s']:.1f} s",
                   rows=[{k: row[k] for k in ("protocol", "recording_s", "replay_wall_s", "replay_speed_x")}
                         for row in r["rows"]])]


def bench_fit(ctx: Context) -> list[dict]:
    try:
        from analysis.fit import fit_transmission
        from tests.analysis.synth import table_dataset
    except ImportError as exc:
        return [record("fit.four_designs_s", None, "s", note=f"analysis.fit not available yet ({exc})")]
    designs = (1, 2, 3, 4)
    data = {d: table_dataset(d, seed=1) for d in designs}

    def timed(fn) -> tuple[float, float]:
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        return time.perf_counter() - w0, time.process_time() - c0

    point_wall, point_cpu = timed(
        lambda: [fit_transmission(data[d], d, "least-squares", intervals=False) for d in designs])
    ci_wall, ci_cpu = timed(lambda: [fit_transmission(data[d], d, "least-squares") for d in designs])
    if ctx.quick:
        nm_wall = nm_cpu = None
        nm_label = "Nelder-Mead baseline skipped in --quick (it takes about a minute)"
    else:
        nm_wall, nm_cpu = timed(
            lambda: [fit_transmission(data[d], d, "nelder-mead", intervals=False) for d in designs])
        nm_label = "the paper's method: Nelder-Mead on the RMS cost, point estimates"
    data_note = "designs 1-4, synthetic per-step observations of the three leg protocols (tests/analysis/synth.py)"
    return [
        record("fit.four_designs_s", point_wall, "s", nm_wall, nm_label,
               point_wall / nm_wall if nm_wall else None, "least squares / Nelder-Mead", goal("value", "<", 2.0),
               note=f"least-squares point estimates; {data_note}", cpu_s=point_cpu, baseline_cpu_s=nm_cpu),
        record("fit.four_designs_with_intervals_s", ci_wall, "s", point_wall, "the same fits, point estimates only",
               ci_wall / point_wall, "with intervals / points", goal("value", "<", 2.0),
               note=f"with 95 % profile intervals (the default of hamr-bench fit); {data_note}", cpu_s=ci_cpu),
    ]


def bench_gap(ctx: Context) -> list[dict]:
    try:
        from analysis.gap.diagnose import diagnose
        from analysis.gap.features import load_gap_data
    except ImportError as exc:
        return [record("gap.diagnose_campaign_s", None, "s", note=f"analysis.gap not available yet ({exc})")]
    directory = ctx.ensure_campaign()
    t0, c0 = time.perf_counter(), time.process_time()
    data = load_gap_data([directory])
    t1 = time.perf_counter()
    diagnose(data)
    t2, c2 = time.perf_counter(), time.process_time()
    scope = "reduced campaign (design 4, 2 layers)" if ctx.quick else "whole campaign"
    return [record("gap.diagnose_campaign_s", t2 - t0, "s", t1 - t0, "reading the campaign's recordings alone",
                   (t2 - t0) / (t1 - t0), "diagnosis / reading", goal("value", "<", 60.0),
                   note=f"{scope}, {len(data.runs)} recordings: load + diagnose (every candidate effect)",
                   cpu_s=c2 - c0)]


def bench_scaleout(ctx: Context) -> list[dict]:
    from benchmarks import bench_scaleout

    directory = ctx.ensure_campaign()
    recordings = sorted(directory.glob("*.mcap"))
    # "Many recordings": the campaign's, repeated until there are at least 16 items (a reduced campaign has 5).
    items = recordings * max(1, math.ceil(16 / max(len(recordings), 1)))
    r = bench_scaleout.run(items, repeat=1 if ctx.quick else 2)
    out = [record("scaleout.local_pool_speedup", r["local_s"], "s", r["serial_s"],
                  "the same batch in one process", r["serial_s"] / r["local_s"], "speed-up (serial / pool)",
                  None, note=f"{r['items']} recordings read into fit observations, {r['workers']} local workers on "
                             f"{os.cpu_count()} CPUs", items=r["items"], workers=r["workers"])]
    if r.get("dask_s") is not None:
        out.append(record("scaleout.dask_speedup", r["dask_s"], "s", r["serial_s"], "the same batch in one process",
                          r["serial_s"] / r["dask_s"], "speed-up (serial / Dask)", None,
                          note=f"LocalCluster of {r['workers']} worker processes on loopback, started beforehand",
                          cluster_start_s=r["dask_start_s"]))
    else:
        out.append(record("scaleout.dask_speedup", None, "s", r["serial_s"], "the same batch in one process",
                          note=r.get("dask_note", "Dask not installed (optional extra 'dask')")))
    return out


BENCHMARKS: dict[str, Callable[[Context], list[dict]]] = {
    "model": bench_model, "tracking": bench_tracking, "serial": bench_serial, "acquisition": bench_acquisition,
    "live": bench_live,
    "campaign": bench_campaign, "replay": bench_replay, "fit": bench_fit, "gap": bench_gap,
    "scaleout": bench_scaleout,
}


def run_all(names: list[str], quick: bool, log: Callable[[str], None]) -> dict[str, Any]:
    machine = {"cpus": os.cpu_count(), "python": platform.python_version(), "platform": platform.platform(),
               "load_average_before": list(os.getloadavg())}
    records: list[dict] = []
    errors: dict[str, str] = {}
    timings: dict[str, float] = {}
    root = Path(tempfile.mkdtemp(prefix="hamr-bench-"))
    try:
        ctx = Context(quick, root)
        for name in names:
            log(f"benchmark {name} ...")
            t0 = time.perf_counter()
            try:
                records += BENCHMARKS[name](ctx)
            except Exception as exc:  # one failing benchmark must not hide the others' figures
                errors[name] = f"{type(exc).__name__}: {exc}"
                log(traceback.format_exc())
            timings[name] = time.perf_counter() - t0
    finally:
        shutil.rmtree(root, ignore_errors=True)
    machine["load_average_after"] = list(os.getloadavg())
    return {"machine": machine, "quick": quick, "records": records, "errors": errors, "seconds_per_benchmark": timings}


def _fmt(x: Any) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few minutes in all (shorter runs, smaller campaign)")
    parser.add_argument("--only", default="", metavar="NAME[,NAME...]", help=f"among: {', '.join(ORDER)}")
    parser.add_argument("--json", action="store_true", help="print one JSON object (progress goes to stderr)")
    args = parser.parse_args(argv)
    names = [n.strip() for n in args.only.split(",") if n.strip()] or list(ORDER)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        print(f"python -m benchmarks: unknown benchmark {unknown[0]!r} (known: {', '.join(ORDER)})", file=sys.stderr)
        return 2
    result = run_all(names, args.quick, lambda text: print(text, file=sys.stderr, flush=True))
    if args.json:
        print(json.dumps(result, indent=1, default=float))
        return 0
    m = result["machine"]
    print(f"{m['cpus']} CPUs, load average {m['load_average_before'][0]:.1f} before, "
          f"{m['load_average_after'][0]:.1f} after{' (quick)' if args.quick else ''}")
    print(f"{'benchmark':40s} {'value':>12s} {'unit':16s} {'baseline':>11s} {'ratio':>9s}  {'goal':14s} met")
    for r in result["records"]:
        g = r["goal"]
        goal_text = f"{g['on']} {g['op']} {g['target']:g}" if g else "-"
        print(f"{r['name']:40s} {_fmt(r['value']):>12s} {r['unit']:16s} {_fmt(r['baseline']):>11s} "
              f"{_fmt(r['ratio']):>9s}  {goal_text:14s} {_fmt(r['met'])}")
    for name, err in result["errors"].items():
        print(f"{name}: FAILED: {err}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
