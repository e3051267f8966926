"""Reliability campaign (issue 9): the long figures the test suite is too short for. Each part prints its figure.

1. `--kills N` (default 20, at least 4 per protocol): real `hamr-bench run PROTOCOL --sim` processes (the
   protocols' default parameters), each SIGKILLed once a random fraction (0.1-0.95) of the run's messages had been
   handed to the recorder; then `hamr-bench recover`, a CRC-validated read-back, and a sample-by-sample comparison
   with the same seed run to completion. Figure per kill: messages lost (handed over but not recovered), the wall
   time between the newest recovered sample's hand-over and the kill, and whether every sample handed over at
   least one flush interval before the kill is there.
2. `--matrix`: every fault of every emulator (sim_devices/faults.py) in every protocol, at two moments (during the
   contact search or first move, and during the drive / loading), through the real command line. Figure: the
   fault x protocol matrix of time from fault to safe (both DAQ outputs at 0 V and the stage still, read from the
   emulators), exit code, one-line message, and samples lost before the fault.
3. `--soak MINUTES` (default 10): per protocol, simulated runs back to back, each with a random fault at a random
   time (or none, 1 in 4) until MINUTES of virtual-clock time have passed; every run must end safe with a closed,
   CRC-valid recording. Figure: runs, faults, virtual and wall time, RSS and Python-object growth from the end of
   the first run to the end (memory flat = the growth does not scale with the number of runs).

Run: `python -m benchmarks.reliability_campaign [--kills 20] [--matrix] [--soak 10] [--seed S]`; with no part
named it runs all three (about 10-15 minutes on a 2-core machine).
"""

from __future__ import annotations

import argparse
import gc
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from tests.reliability.harness import (
    ALL_FAULTS,
    fault_moments,
    loss_allowed,
    PROTOCOL_NAMES,
    SHORT_SETTINGS,
    UNREACHABLE_BY_SOFTWARE,
    takes_the_daq,
    expected_safe_bound_s,
    kill_and_recover,
    make_reference,
    measure_safe,
    reference_samples,
    run_cli,
    run_fault_case,
    stage_stopped_in_time,
    fault_first_matters_s,
)


class _Tmp:
    """tmp_path_factory stand-in for reference_samples outside pytest."""

    def __init__(self, root: Path) -> None:
        self.root, self.n = root, 0

    def mktemp(self, name: str) -> Path:
        self.n += 1
        path = self.root / f"{name}{self.n}"
        path.mkdir()
        return path


def rss_kB() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return -1


# ---------------------------------------------------------------------------------------------------- kills
def kills(n: int, seed: int, root: Path) -> bool:
    rng = np.random.default_rng(seed)
    per = max(4, math.ceil(n / len(PROTOCOL_NAMES)))
    print(f"\n== SIGKILL campaign: {per} kills x {len(PROTOCOL_NAMES)} protocols (default parameters), recover, "
          "compare with the same seed run to completion")
    print(f"{'protocol':18s} {'kill at':>8s} {'handed':>8s} {'recovered':>9s} {'lost':>6s} {'window_s':>8s} "
          f"{'older than flush all there':>26s} {'prefix of ref':>13s}")
    all_ok, windows, losses = True, [], []
    for protocol in PROTOCOL_NAMES:
        work = root / f"kill-{protocol}"
        work.mkdir()
        t0 = time.perf_counter()
        reference = make_reference(protocol, work / "reference.mcap", seed, settings=[])
        ref_wall = time.perf_counter() - t0
        for i in range(per):
            fraction = float(rng.uniform(0.1, 0.95))
            tmp = work / f"k{i}"
            tmp.mkdir()
            o = kill_and_recover(protocol, tmp, reference, fraction, seed, settings=[])
            all_ok &= o.ok
            if not math.isnan(o.lost_window_s):
                windows.append(o.lost_window_s)
            losses.append(o.lost)
            print(f"{protocol:18s} {fraction:8.0%} {o.handed_at_kill:8d} {o.recovered:9d} {o.lost:6d} "
                  f"{o.lost_window_s:8.3f} {'yes' if not o.must_have_short else o.must_have_short!s:>26s} "
                  f"{'yes' if not o.mismatched else o.mismatched!s:>13s}")
        print(f"   ({protocol}: reference run {ref_wall:.1f} s wall)")
    print(f"kills: {len(losses)}; messages lost per kill: median {np.median(losses):.0f}, max {max(losses)}; "
          f"newest recovered sample handed over before the kill by: median {np.median(windows):.3f} s, "
          f"max {max(windows):.3f} s (flush interval 0.5 s; {len(losses) - len(windows)} kills came before "
          f"anything was flushed); all checks passed: {all_ok}")
    return all_ok


# ---------------------------------------------------------------------------------------------------- matrix
def matrix(root: Path) -> bool:
    tmp = _Tmp(root)
    bound = expected_safe_bound_s()
    print(f"\n== Fault x protocol matrix: time from fault to safe (0 V on both DAQ outputs, stage still), rig clock; "
          f"bound {bound:.2f} s")
    print("   cell: seconds | '-' the fault never touched the run (device unused or idle) | "
          "'NO DAQ' the DAQ is gone: 0 V cannot be commanded (reported in the reason) | "
          "'n/m' not modelled by that emulator (refused in one line)")
    ok = True
    lost_link: list[tuple[int, float]] = []
    worst = 0.0
    moments = {p: fault_moments(p, tmp) for p in PROTOCOL_NAMES}
    for moment in ("search", "drive"):
        table = {p: moments[p][moment] for p in PROTOCOL_NAMES}
        print(f"\n-- fault during the {'contact search / first moves' if moment == 'search' else 'drive / loading'}"
              f" (t = {', '.join(f'{p} {t:g} s' for p, t in table.items())})")
        print(f"{'fault':28s}" + "".join(f"{p:>19s}" for p in PROTOCOL_NAMES))
        for fault in ALL_FAULTS:
            row = []
            for protocol in PROTOCOL_NAMES:
                at_s = table[protocol]
                reference = reference_samples(protocol, at_s, tmp)
                out = tmp.mktemp("m") / "run.mcap"
                o = run_fault_case(protocol, f"{fault}@{at_s}", out, reference)
                if not o.modelled:
                    cell = "n/m"
                    ok &= o.code == 2 and len(o.stderr_lines) == 1 and "unknown fault" in o.stderr_lines[0]
                elif not o.triggered:
                    cell = "-"
                    ok &= o.code == 0
                elif o.safe is None:
                    raise RuntimeError(f"{protocol} {fault}: a modelled fault's run has no safe-state measure")
                else:
                    t0 = o.first_use_s
                    cell_ok = (o.code != 0 and len(o.stderr_lines) == 1 and o.exit_status == "failed"
                               and o.safe.stage_still_at_s - t0 <= bound)
                    cell_ok &= loss_allowed(protocol, fault, o)
                    if o.lost:
                        lost_link.append((sum(o.lost.values()), o.fault_s - o.oldest_lost_s))
                    zeroed = all(z <= o.safe.end_s for z in o.safe.zero_V_at_s.values())
                    if takes_the_daq(protocol, fault) and not zeroed:
                        cell = "NO DAQ"
                        cell_ok &= "while making safe" in (o.reason or "")
                    else:
                        cell = f"{o.time_to_safe_s:.3f}"
                        if o.latent_s > 1e-9:
                            cell += f" (+{o.latent_s:.1f})"
                        cell_ok &= o.time_to_safe_s <= bound
                        worst = max(worst, o.time_to_safe_s)
                    if not cell_ok:
                        cell += " FAIL"
                    ok &= cell_ok
                row.append(cell)
            print(f"{fault:28s}" + "".join(f"{c:>19s}" for c in row), flush=True)
    print(f"\nmatrix: every cell safe within {bound:.2f} s of the fault becoming noticeable (or reported unreachable):"
          f" {ok}; worst time to safe {worst:.3f} s")
    print("'(+L)': the fault sat L s on an idle device (DAQ before the first drive, camera outside tracked drives) "
          "before the run used it; the time is counted from that use")
    if lost_link:
        print(f"samples taken before a fault but never received (exchange straddling the fault, or unread lines in "
              f"a port that went away): {sum(n for n, _ in lost_link)} in {len(lost_link)} runs, none older than "
              f"{max(w for _, w in lost_link):.3f} s before the fault")
    return ok


# ---------------------------------------------------------------------------------------------------- soak
def soak(minutes: float, seed: int, root: Path) -> bool:
    from hamr_bench.recording import RecordingReader

    rng = np.random.default_rng(seed)
    print(f"\n== Soak: >= {minutes:g} min of virtual time per protocol, random faults, every run checked safe")
    print(f"{'protocol':18s} {'runs':>5s} {'faulted':>7s} {'virtual_s':>9s} {'wall_s':>7s} {'RSS after 1st kB':>16s} "
          f"{'RSS growth kB':>13s} {'per run kB':>10s} {'objects growth':>14s} {'all safe':>8s}")
    ok = True
    for protocol in PROTOCOL_NAMES:
        work = root / f"soak-{protocol}"
        work.mkdir()
        virtual_s, runs, faulted, safe_all, attempts, refused_n = 0.0, 0, 0, True, 0, 0
        t0 = time.perf_counter()
        rss0: int | None = None
        objs0 = 0
        span = {"actuator": 90.0, "blocked-force": 17.0, "sag-sweep": 19.5, "free-displacement": 2.4,
                "static": 21.4}[protocol]  # virtual length of the short run (for a fault time inside it)
        while virtual_s < minutes * 60:
            out = work / f"run{runs}-{attempts}.mcap"
            attempts += 1
            faults: tuple[str, ...] = ()
            if rng.random() >= 0.25:
                faults = (f"{ALL_FAULTS[rng.integers(len(ALL_FAULTS))]}@{rng.uniform(0.0, span):.3f}",)
            run = run_cli(protocol, out, faults=faults, seed=int(rng.integers(1 << 31)))
            if run.bench is None:  # a fault that emulator does not model: refused in one line, nothing ran
                # a fault the emulator does not model, or one that breaks a device while the rig is being built
                # (fault time ~0): one line, exit 2, the recording closed with "rig could not be built"
                refused = run.code == 2 and len(run.stderr_lines) == 1 and (
                    "unknown fault" in run.stderr_lines[0]
                    or (RecordingReader(out).exit_reason or "").startswith("rig could not be built"))
                if not refused:
                    print(f"   NOT REFUSED CLEANLY: {protocol} {faults} {run.stderr_lines}")
                safe_all &= refused
                refused_n += 1
                continue
            reader = RecordingReader(out, validate_crcs=True)
            fault_s = float(faults[0].rsplit("@", 1)[1]) if faults else run.end_s
            measure = measure_safe(run.bench, min(fault_s, run.end_s), run.end_s)
            safe = (reader.exit_status in ("success", "failed") and
                    stage_stopped_in_time(run.bench, faults[0] if faults else None,
                                          min(fault_first_matters_s(faults[0], run), run.end_s) if faults else 0.0,
                                          run.end_s) and (
                        (faults and faults[0].split("@")[0] in UNREACHABLE_BY_SOFTWARE
                         and reader.exit_status == "failed")
                        or all(z <= run.end_s for z in measure.zero_V_at_s.values())))
            if not safe:
                print(f"   NOT SAFE: {protocol} {faults} {reader.exit_status} {reader.exit_reason}")
            safe_all &= bool(safe)
            faulted += reader.exit_status != "success"
            virtual_s += run.end_s
            runs += 1
            del run, reader, measure
            out.unlink()
            gc.collect()
            if rss0 is None:
                rss0, objs0 = rss_kB(), len(gc.get_objects())
        if rss0 is None:
            raise RuntimeError(f"{protocol}: no run completed in {attempts} attempts")
        rss1, objs1 = rss_kB(), len(gc.get_objects())
        wall = time.perf_counter() - t0
        growth = rss1 - rss0
        print(f"{protocol:18s} {runs:5d} {faulted:7d} {virtual_s:9.0f} {wall:7.1f} {rss0:16d} {growth:13d} "
              f"{growth / max(runs - 1, 1):10.1f} {objs1 - objs0:14d} {str(safe_all):>8s}"
              + (f"  ({refused_n} refused before the run: fault not modelled, or device broken at start)"
                 if refused_n else ""), flush=True)
        ok &= safe_all
        shutil.rmtree(work)
    return ok


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kills", type=int, default=None)
    parser.add_argument("--matrix", action="store_true")
    parser.add_argument("--soak", type=float, default=None, metavar="MINUTES")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    everything = args.kills is None and not args.matrix and args.soak is None
    assert SHORT_SETTINGS  # the matrix and soak use the short protocols; kills use the defaults
    ok = True
    with tempfile.TemporaryDirectory(prefix="hamr-reliability-") as tmp:
        root = Path(tmp)
        if everything or args.kills is not None:
            ok &= kills(args.kills or 20, args.seed, root)
        if everything or args.matrix:
            ok &= matrix(root)
        if everything or args.soak is not None:
            ok &= soak(args.soak or 10.0, args.seed, root)
    print(f"\nreliability campaign: {'all checks passed' if ok else 'SOME CHECKS FAILED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
