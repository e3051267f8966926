"""`hamr-bench recover RUN.mcap -o OUT.mcap [--force]`: rebuild a finished, readable recording from one whose
writer was killed (or that is damaged), keeping everything that can still be read."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser("recover", help="rebuild a valid recording from a killed run's file")
    parser.add_argument("recording", type=Path, help="the unfinished or damaged MCAP file")
    parser.add_argument("-o", "--out", type=Path, required=True, help="where to write the recovered file")
    parser.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from hamr_bench.recording.recover import recover

    report = recover(args.recording, args.out, overwrite=args.force)
    last = f"{report.last_time_s:.3f} s" if report.last_time_s is not None else "none"
    print(f"recovered {report.messages_recovered} messages (newest at {last}) and "
          f"{len(report.metadata_recovered)} metadata records into {report.output}")
    print(f"source: read {report.bytes_read} of {report.source_size} bytes"
          + ("" if report.problem is None else f"; stopped: {report.problem}")
          + ("" if not report.chunks_skipped else f"; {report.chunks_skipped} damaged chunks skipped"))
    print(f"run_end: exit_status={report.exit_status} reason={report.reason!r}")
    return 0
