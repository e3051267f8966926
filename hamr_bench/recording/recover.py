"""`recover`: rebuild a finished, indexed MCAP file from whatever a killed (or crashed) writer left on disk.

Everything the scanner can read is copied in file order with its original times: schemas, channels, metadata and
every message of every complete chunk (a chunk with a bad CRC is skipped and counted, the rest is kept). The new
file gets a `run_end` record: the source's own if it had one, otherwise exit_status 'failed' with reason
'recovered: writer did not finish'. Either way `recovered` = 'true' says the file went through here.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from hamr_bench.errors import RecordingError
from hamr_bench.recording import schemas
from hamr_bench.recording.contract import MetadataName
from hamr_bench.recording.mcap_file import McapFileWriter
from hamr_bench.recording.scan import (
    ChannelRecord,
    MessageRecord,
    MetadataRecord,
    SchemaRecord,
    ScanStatus,
    scan,
)

RECOVERED_REASON = "recovered: writer did not finish"


@dataclass(frozen=True)
class RecoverReport:
    source: Path
    output: Path
    messages_recovered: int
    messages_by_topic: dict[str, int]
    metadata_recovered: tuple[str, ...]
    last_time_s: float | None  # rig time of the newest message recovered (None if there was none)
    exit_status: str  # as written in the output's run_end
    reason: str
    source_complete: bool  # the source already had a valid footer
    bytes_read: int  # how far into the source the records made sense
    source_size: int
    chunks_skipped: int  # chunks dropped for a bad CRC or undecodable data
    problem: str | None  # why reading the source stopped early, if it did


def recover(src: Path | str, dst: Path | str, *, overwrite: bool = False) -> RecoverReport:
    from hamr_bench import __version__

    src, dst = Path(src), Path(dst)
    if dst.exists() and src.exists() and os.path.samefile(src, dst):
        raise RecordingError(f"recover would overwrite its own source {src}; give another output with -o")
    status = ScanStatus()
    records = scan(src, "salvage", status)
    first = next(records, None)  # opens the source and checks its magic before anything is created
    try:
        out = open(dst, "wb" if overwrite else "xb")
    except FileExistsError:
        raise RecordingError(f"{dst} already exists; use --force to overwrite it") from None
    except OSError as exc:
        raise RecordingError(f"cannot create {dst}: {exc.strerror or exc}") from None

    # The recorder's own writer, as the recorder writes: every schema and channel kept (written when registered,
    # even one whose messages were all lost), frames marked for stored chunks, all CRCs; messages in
    # the source's file order (a format-2 source is in log-time order, so its copy is too).
    writer = McapFileWriter(out, chunk_size=256 * 1024, compression="lz4")
    writer.start(profile="", library=f"hamr-bench {__version__} (recover)")
    stored_channels: set[int] = set()  # image channels: their frames go in stored chunks
    schema_ids: dict[int, int] = {}
    schema_keys: dict[tuple[str, str, bytes], int] = {}
    schema_names: dict[int, str] = {}
    channel_ids: dict[int, int] = {}
    channel_keys: dict[tuple[str, str, int], int] = {}
    topics: dict[int, str] = {}
    counts: dict[str, int] = {}
    metadata_names: list[str] = []
    source_run_end: dict[str, str] | None = None
    start_time_ns: int | None = None
    damaged: list[str] = []
    last_log: int | None = None
    first_log: int | None = None
    orphans = 0

    def handle(record: object) -> None:
        nonlocal source_run_end, start_time_ns, last_log, first_log, orphans
        if isinstance(record, MessageRecord):
            new_id = channel_ids.get(record.channel_id)
            if new_id is None:
                orphans += 1
                return
            writer.add_message(new_id, record.log_time, record.data, record.publish_time, record.sequence,
                               stored=new_id in stored_channels)
            topic = topics[new_id]
            counts[topic] = counts.get(topic, 0) + 1
            last_log = record.log_time if last_log is None else max(last_log, record.log_time)
            first_log = record.log_time if first_log is None else min(first_log, record.log_time)
        elif isinstance(record, SchemaRecord):
            schema_key = (record.name, record.encoding, record.data)
            if schema_key not in schema_keys:
                schema_keys[schema_key] = writer.register_schema(record.name, record.encoding, record.data)
                schema_names[schema_keys[schema_key]] = record.name
            schema_ids[record.id] = schema_keys[schema_key]
        elif isinstance(record, ChannelRecord):
            channel_key = (record.topic, record.message_encoding, schema_ids.get(record.schema_id, 0))
            if channel_key not in channel_keys:
                channel_keys[channel_key] = writer.register_channel(
                    record.topic, record.message_encoding, channel_key[2], record.metadata
                )
                topics[channel_keys[channel_key]] = record.topic
                if schema_names.get(channel_key[2]) in schemas.IMAGE_SCHEMAS:
                    stored_channels.add(channel_keys[channel_key])
            channel_ids[record.id] = channel_keys[channel_key]
        elif isinstance(record, MetadataRecord):
            if record.name == MetadataName.RUN_END:
                source_run_end = dict(record.values)
                return
            values = dict(record.values)
            if record.name == MetadataName.RECORDING and "start_time_ns" in values:
                try:
                    start_time_ns = int(values["start_time_ns"])
                except ValueError:
                    # Metadata records carry no CRC: a damaged run-start time must not make the rebuilt file
                    # unreadable. Drop it; readers then count time from the first message.
                    del values["start_time_ns"]
                    damaged.append("recording.start_time_ns")
            writer.add_metadata(record.name, values)
            metadata_names.append(record.name)

    try:
        if first is not None:
            handle(first)
        for record in records:
            handle(record)
        origin = start_time_ns if start_time_ns is not None else first_log
        last_time_s = (last_log - origin) / 1e9 if last_log is not None and origin is not None else None
        total = sum(counts.values())
        if source_run_end is not None:
            run_end = dict(source_run_end)
        else:
            run_end = {
                "exit_status": "failed",
                "reason": RECOVERED_REASON,
                "dropped_total": "unknown",
                "dropped_by_topic": "{}",
                "out_of_order_by_topic": "{}",
            }
        run_end.update(
            {
                "recovered": "true",
                "recovered_from": str(src),
                "messages_recovered": str(total),
                "last_time_s": "" if last_time_s is None else repr(last_time_s),
                "recover_chunks_skipped": str(status.chunks_skipped),
                "recover_orphan_messages": str(orphans),
                "recover_damaged_metadata": ",".join(damaged),
            }
        )
        writer.add_metadata(MetadataName.RUN_END, run_end)
        metadata_names.append(MetadataName.RUN_END)
        writer.finish()
        out.flush()
        os.fsync(out.fileno())
    except BaseException:
        out.close()
        dst.unlink(missing_ok=True)  # never leave a half-written "recovered" file behind
        raise
    out.close()
    return RecoverReport(
        source=src,
        output=dst,
        messages_recovered=total,
        messages_by_topic=counts,
        metadata_recovered=tuple(metadata_names),
        last_time_s=last_time_s,
        exit_status=run_end.get("exit_status", ""),
        reason=run_end.get("reason", ""),
        source_complete=status.complete,
        bytes_read=status.bytes_read,
        source_size=status.file_size,
        chunks_skipped=status.chunks_skipped,
        problem=status.problem,
    )
