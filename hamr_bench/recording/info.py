"""The summary behind `hamr-bench info`: topics with counts, rates and time span, the metadata that matters at a
glance (how the run ended, rig, design, protocol, software), the specimens its steps name, and the result of the
CRC check.

`summarise` returns plain JSON-able data (`--json` prints it as is); `format_summary` turns it into text.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path
from typing import Any

from hamr_bench.errors import RecordingError
from hamr_bench.recording.contract import EventKind, MetadataName
from hamr_bench.recording.reader import RecordingReader, RecordingWarning

# Metadata keys shown in the text summary, per record; anything else is in --json.
_HIGHLIGHTS = {
    MetadataName.RUN_END: ("exit_status", "reason", "dropped_total", "end_time_utc", "recovered"),
    MetadataName.RUN: ("seed", "clock", "started_utc", "source"),
    MetadataName.RIG: ("name", "kind", "path"),
    MetadataName.DESIGN: ("design", "layers", "fixture", "params_set"),
    MetadataName.PROTOCOL: ("name", "protocol_file"),
    MetadataName.SOFTWARE: ("hamr_bench", "python", "numpy", "mcap"),
}


def summarise(path: Path | str) -> dict[str, Any]:
    """Everything `info` shows. Reads with CRC validation; if that fails, reads again without it so the summary
    still appears, and says so under `crc`."""
    path = Path(path)
    crc_error = None
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RecordingWarning)
        try:
            reader = RecordingReader(path, validate_crcs=True)
        except RecordingError as exc:
            crc_error = str(exc)
            reader = RecordingReader(path, validate_crcs=False)
    status = reader.status
    crc: dict[str, Any]
    if crc_error is not None:
        crc = {"result": "failed", "error": crc_error}
    else:
        crc = {
            "result": "ok",
            "chunks_checked": status.chunks_crc_checked,
            "data_section": status.data_crc,
            "summary_section": status.summary_crc,
        }
    topics = []
    first_times: list[float] = []
    last_times: list[float] = []
    for info in reader.topics().values():
        topics.append(
            {
                "topic": info.topic,
                "schema": info.schema_name,
                "messages": info.message_count,
                "rate_Hz": info.rate_Hz,
                "first_time_s": info.first_time_s,
                "last_time_s": info.last_time_s,
            }
        )
        if info.first_time_s is not None and info.last_time_s is not None:
            first_times.append(info.first_time_s)
            last_times.append(info.last_time_s)
    metadata = reader.metadata()
    specimens = sorted({str(e.data["specimen"]) for e in reader.events()
                        if e.kind in (EventKind.STEP, EventKind.SPECIMEN) and e.data.get("specimen")})
    return {
        "path": str(path),
        "size_bytes": status.file_size,
        "complete": not reader.partial,
        "partial_reason": status.problem if reader.partial else None,
        "warnings": [str(w.message) for w in caught if issubclass(w.category, RecordingWarning)],
        "crc": crc,
        "exit_status": reader.exit_status,
        "reason": reader.exit_reason,
        "start_time_utc": metadata.get(MetadataName.RECORDING, {}).get("start_time_utc"),
        "time_span_s": [min(first_times), max(last_times)] if first_times else None,
        "specimens": specimens,
        "messages": sum(t["messages"] for t in topics),
        "topics": topics,
        "metadata": metadata,
    }


def format_summary(summary: dict[str, Any]) -> str:
    lines = []
    size_mb = summary["size_bytes"] / 1e6
    state = "complete" if summary["complete"] else f"PARTIAL ({summary['partial_reason']})"
    lines.append(f"{summary['path']}: {size_mb:.2f} MB, {state}")
    crc = summary["crc"]
    if crc["result"] == "ok":
        lines.append(
            f"CRC check: ok ({crc['chunks_checked']} chunks; data section {crc['data_section']}; "
            f"summary {crc['summary_section']})"
        )
    else:
        lines.append(f"CRC check: FAILED: {crc['error']}")
    exit_status = summary["exit_status"] or "unknown (no run_end record: the writer did not finish)"
    reason = f" - {summary['reason']}" if summary.get("reason") else ""
    lines.append(f"exit status: {exit_status}{reason}")
    if summary.get("specimens"):
        lines.append(f"specimens: {', '.join(summary['specimens'])}")
    span = summary["time_span_s"]
    if span:
        lines.append(f"time span: {span[0]:.3f} s to {span[1]:.3f} s ({span[1] - span[0]:.3f} s) from run start "
                     f"{summary['start_time_utc'] or '(unknown)'}")
    lines.append(f"topics ({len(summary['topics'])}, {summary['messages']} messages):")
    width = max((len(t["topic"]) for t in summary["topics"]), default=5)
    for t in summary["topics"]:
        rate = f"{t['rate_Hz']:10.1f} Hz" if t["rate_Hz"] is not None else " " * 13
        span_text = "no messages"
        if t["first_time_s"] is not None:
            span_text = f"{t['first_time_s']:9.3f} - {t['last_time_s']:9.3f} s"
        lines.append(f"  {t['topic']:<{width}}  {t['messages']:>9}  {rate}  {span_text}  {t['schema']}")
    lines.append("metadata:")
    for name, values in summary["metadata"].items():
        keys = _HIGHLIGHTS.get(name)
        if keys is None:
            shown = f"{len(values)} keys"
        else:
            parts = [f"{k}={_short(values[k])}" for k in keys if k in values]
            others = len(values) - len(parts)
            shown = ", ".join(parts) + (f" (+{others} more)" if others else "")
        lines.append(f"  {name}: {shown}")
    return "\n".join(lines)


def _short(value: str, limit: int = 60) -> str:
    value = value.replace("\n", " ")
    return json.dumps(value if len(value) <= limit else value[: limit - 3] + "...")
