"""Reading chunks through their MessageIndex records, many chunks at a time, for the reader's fast open.

Why: the per-record scanner (`scan.py`) builds a Python object per message, about 2 us each: most of the time to
open a 160k-message recording. Our writer (and the `mcap` package's) follows every chunk with one MessageIndex per
channel giving each message's offset in the decompressed chunk, so message headers can be gathered and checked with
numpy, and fixed-size payloads (the scalar streams) copied out as (n, size) arrays. Numpy costs ~1 us a call, so
checking chunk by chunk (a dozen calls each, thousands of chunks) would cost as much as it saves: chunks wait in an
`IndexBatch` and are checked and split together.

An index is only a hint: nothing is taken from it but where to look. Each message's opcode, length, channel id and
log time are read from the chunk itself and must agree with the index, and the messages must tile the chunk exactly
(no byte left over, so no record the index left out). A chunk that passes yields exactly the messages
`scan._inner_records` would, in the same order. One that does not (no index, a disagreeing index, schema or channel
records among the messages, log times past int64) is handed back to the reader to take in file order, through
`split_chunk` (which also accepts schema/channel records around the messages) or record by record.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from hamr_bench.recording.scan import (
    OP_MESSAGE,
    MessageRecord,
    Policy,
    Record,
    ScanStatus,
    _Corrupt,
    _inner_records,
    _scan,
)

# opcode, record length, then the message's fixed fields: the first 31 bytes of every message record.
_HEAD = np.dtype([("opcode", "u1"), ("length", "<u8"), ("channel_id", "<u2"), ("sequence", "<u4"),
                  ("log_time", "<u8"), ("publish_time", "<u8")])
_HEAD_SIZE = _HEAD.itemsize  # 31
_HEAD_STRUCT = struct.Struct("<BQHIQ")  # the same fields up to the log time, for a chunk checked in Python
_MESSAGE_FIXED = 22  # channel id, sequence, log time, publish time
_INDEX_HEAD = struct.Struct("<HI")  # channel id, byte length of the (log time, offset) entries
_INT64_MAX = (1 << 63) - 1
# Chunks with at most this many messages, all on lazy (image) channels, are checked in Python at once and their
# bytes dropped: a camera frame alone in its chunk should not be held until the batch is checked.
SMALL_CHUNK = 4
# Decompressed bytes held by a batch before it is checked (bounds the reader's extra memory).
BATCH_BYTES = 32 << 20


class ChunkCandidate:
    """A chunk handed on whole by `scan_indexed`, with its message index entries (not yet checked)."""

    __slots__ = ("chunk_offset", "data", "index_channels", "index_counts", "entries")

    def __init__(self, chunk_offset: int, data: bytes, index_channels: list[int], index_counts: list[int],
                 entries: bytes) -> None:
        self.chunk_offset = chunk_offset
        self.data = data
        self.index_channels = index_channels  # channel claimed by each (non-empty) MessageIndex record
        self.index_counts = index_counts  # its number of entries
        self.entries = entries  # the entries, (log time, offset) little-endian u64 pairs

    @property
    def count(self) -> int:
        return len(self.entries) // 16

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(claimed channel, log time, offset) per entry."""
        pairs = np.frombuffer(self.entries, dtype="<u8").reshape(-1, 2)
        claimed = np.repeat(np.asarray(self.index_channels, dtype=np.uint16), self.index_counts)
        return claimed, pairs[:, 0], pairs[:, 1]


def scan_indexed(path: Path, policy: Policy, status: ScanStatus) -> Iterator[Record | ChunkCandidate]:
    """`scan`, except that a chunk followed by well-formed message indexes comes as one `ChunkCandidate` instead of
    its records. Only the reader's policies: `salvage` keeps the plain scan (recover copies record by record)."""
    if policy not in ("strict", "lenient"):
        raise ValueError(f"scan_indexed: policy {policy!r} (expected 'strict' or 'lenient')")
    return _scan(path, policy, status, _candidate)


def _candidate(data: bytes, chunk_offset: int, index_bodies: list[bytes]) -> list[Any] | None:
    channels: list[int] = []
    counts: list[int] = []
    parts: list[bytes] = []
    for body in index_bodies:
        if len(body) < _INDEX_HEAD.size:
            return None
        channel_id, entries_size = _INDEX_HEAD.unpack_from(body)
        if entries_size % 16 or len(body) != _INDEX_HEAD.size + entries_size:
            return None
        if entries_size:
            channels.append(channel_id)
            counts.append(entries_size // 16)
            parts.append(body[_INDEX_HEAD.size :])
    if not parts:
        return None
    return [ChunkCandidate(chunk_offset, data, channels, counts, parts[0] if len(parts) == 1 else b"".join(parts))]


def check_small(cand: ChunkCandidate) -> list[tuple[int, int]] | None:
    """(channel id, log time) of each message of a chunk with few entries, in file order, if they tile the chunk
    and agree with the index; else None. The same checks as `IndexBatch`, in Python."""
    data, n = cand.data, len(cand.data)
    entries = struct.unpack(f"<{2 * cand.count}Q", cand.entries)
    claimed = [c for c, k in zip(cand.index_channels, cand.index_counts) for _ in range(k)]
    rows = sorted(zip(entries[1::2], entries[0::2], claimed))
    out = []
    expected = 0
    for offset, log_time, channel in rows:
        if offset != expected or offset + _HEAD_SIZE > n:
            return None
        opcode, length, channel_id, _sequence, head_time = _HEAD_STRUCT.unpack_from(data, offset)
        if (opcode != OP_MESSAGE or length < _MESSAGE_FIXED or channel_id != channel or head_time != log_time
                or log_time > _INT64_MAX):
            return None
        expected = offset + 9 + length
        out.append((channel_id, log_time))
    return out if expected == n else None


class ChannelRun:
    """Messages of one channel from consecutive checked chunks, in file order."""

    __slots__ = ("channel_id", "log_times", "chunk_offsets", "_buf", "_starts", "_ends")

    def __init__(self, channel_id: int, log_times: np.ndarray, chunk_offsets: np.ndarray, buf: np.ndarray,
                 starts: np.ndarray, ends: np.ndarray) -> None:
        self.channel_id = channel_id
        self.log_times = log_times  # int64 ns
        self.chunk_offsets = chunk_offsets  # of the chunk holding each message
        self._buf, self._starts, self._ends = buf, starts, ends  # payload [start, end) in buf

    def payloads(self) -> np.ndarray | list[bytes]:
        return _payloads(self._buf, self._starts, self._ends)


def _payloads(buf: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | list[bytes]:
    """An (n, size) uint8 copy if every payload has one size (the scalar streams), else the payloads as bytes."""
    sizes = ends - starts
    if len(sizes) == 0:
        return []
    size = int(sizes[0])
    if (sizes == size).all():
        if size == 0:
            return np.zeros((len(sizes), 0), dtype=np.uint8)
        return sliding_window_view(buf, size)[starts]
    return [buf[a:b].tobytes() for a, b in zip(starts.tolist(), ends.tolist(), strict=True)]


class IndexBatch:
    """Chunks waiting to be checked together. Items are added in file order; `take` checks them all and returns, in
    file order, ("runs", [ChannelRun, ...]) for each stretch of chunks that passed and ("chunk", candidate) for each
    that did not (to be read on its own, in its place)."""

    def __init__(self) -> None:
        self._items: list[tuple[int, list[tuple[int, int]]] | ChunkCandidate] = []
        self.held_bytes = 0

    def __len__(self) -> int:
        return len(self._items)

    def add(self, cand: ChunkCandidate) -> None:
        self._items.append(cand)
        self.held_bytes += len(cand.data)

    def add_checked(self, chunk_offset: int, messages: list[tuple[int, int]]) -> None:
        """A small chunk already checked by `check_small` (its bytes are not kept)."""
        self._items.append((chunk_offset, messages))

    def all_pass(self) -> bool:
        """Whether every chunk held would pass (used when the scan failed before the batch was taken)."""
        return not self._check(self._candidates())[1].any()

    def _candidates(self) -> list[ChunkCandidate]:
        return [item for item in self._items if isinstance(item, ChunkCandidate)]

    def take(self) -> list[tuple[str, Any]]:
        items, self._items, self.held_bytes = self._items, [], 0
        cands = [item for item in items if isinstance(item, ChunkCandidate)]
        arrays, bad = self._check(cands)
        # Per message, in file order: item number, channel, log time, chunk offset, payload start/end in `buf`.
        seq_of_cand = [k for k, item in enumerate(items) if isinstance(item, ChunkCandidate)]
        columns = []
        if cands:
            cand_id, channel, log_time, start, end, buf = arrays
            keep = ~bad[cand_id]
            cid = cand_id[keep]
            offsets_of_cand = np.asarray([c.chunk_offset for c in cands], dtype=np.int64)
            columns.append((np.asarray(seq_of_cand, dtype=np.int64)[cid], channel[keep], log_time[keep],
                            offsets_of_cand[cid], start[keep] + _HEAD_SIZE, end[keep]))
        else:
            buf = np.zeros(0, dtype=np.uint8)
        small = [(k, c, t, item[0]) for k, item in enumerate(items) if not isinstance(item, ChunkCandidate)
                 for c, t in item[1]]
        if small:
            s = np.asarray(small, dtype=np.int64).reshape(-1, 4)
            minus = np.full(len(s), -1, dtype=np.int64)
            columns.append((s[:, 0], s[:, 1], s[:, 2], s[:, 3], minus, minus))
        eager = [seq_of_cand[k] for k in np.flatnonzero(bad).tolist()]
        # Chunks that passed, per stretch between those that did not.
        edges = [-1, *eager, len(items)]
        chunks_by_segment = {k: edges[k + 1] - edges[k] - 1 for k in range(len(eager) + 1)}
        steps: list[tuple[str, Any]] = []
        if columns and sum(len(col[0]) for col in columns):
            seq, channel, log_time, chunk_off, start, end = (np.concatenate(col) for col in zip(*columns))
            segment = np.searchsorted(np.asarray(eager, dtype=np.int64), seq)  # stretch between unchecked chunks
            order = np.lexsort((seq, channel, segment))  # stable: file order within each (segment, channel)
            segment, channel = segment[order], channel[order]
            cuts = np.flatnonzero((segment[1:] != segment[:-1]) | (channel[1:] != channel[:-1])) + 1
            bounds = [0, *cuts.tolist(), len(order)]
            runs_by_segment: dict[int, list[ChannelRun]] = {}
            for a, b in zip(bounds[:-1], bounds[1:], strict=True):
                rows = order[a:b]
                runs_by_segment.setdefault(int(segment[a]), []).append(ChannelRun(
                    int(channel[a]), log_time[rows], chunk_off[rows], buf, start[rows], end[rows]))
        else:
            runs_by_segment = {}
        for k in range(len(eager) + 1):
            if k in runs_by_segment:
                steps.append(("runs", (runs_by_segment[k], chunks_by_segment[k])))
            if k < len(eager):
                steps.append(("chunk", items[eager[k]]))
        return steps

    @staticmethod
    def _check(cands: list[ChunkCandidate]) -> tuple[tuple, np.ndarray]:
        """Message columns in file order (candidate, channel, log time, start, end in the joined bytes, the joined
        bytes) and, per candidate, whether it failed a check."""
        if not cands:
            empty = np.zeros(0, dtype=np.int64)
            return (empty, empty, empty, empty, empty, np.zeros(0, dtype=np.uint8)), np.zeros(0, dtype=bool)
        sizes = np.asarray([len(c.data) for c in cands], dtype=np.int64)
        bases = np.concatenate(([0], np.cumsum(sizes)[:-1]))
        buf = np.frombuffer(b"".join(c.data for c in cands), dtype=np.uint8)
        counts = np.asarray([c.count for c in cands], dtype=np.int64)
        cand_id = np.repeat(np.arange(len(cands)), counts)
        pairs = np.frombuffer(b"".join(c.entries for c in cands), dtype="<u8").reshape(-1, 2)
        claimed = np.repeat(np.asarray([ch for c in cands for ch in c.index_channels], dtype=np.int64),
                            [k for c in cands for k in c.index_counts])
        n = sizes[cand_id]
        offset = pairs[:, 1]
        in_range = (n >= _HEAD_SIZE) & (offset <= np.maximum(n - _HEAD_SIZE, 0).astype(np.uint64))
        # An offset out of range is looked up at its chunk's start instead, and its chunk failed anyway.
        start = bases[cand_id] + np.where(in_range, offset, 0).astype(np.int64)
        order = np.argsort(start, kind="stable")
        cand_id, start, in_range, n = cand_id[order], start[order], in_range[order], n[order]
        claimed, index_time = claimed[order], pairs[order, 0]
        if len(buf) >= _HEAD_SIZE:
            # An out-of-range entry looks at its chunk's start, which for a chunk shorter than a header at the end
            # of the batch is past the last full header: clip (that entry is bad already).
            at = np.minimum(start, len(buf) - _HEAD_SIZE)
            heads = sliding_window_view(buf, _HEAD_SIZE)[at].view(_HEAD)[:, 0]
        else:
            heads = np.zeros(len(start), dtype=_HEAD)
        length = heads["length"]
        room = (bases[cand_id] + n - 9 - start).astype(np.uint64)
        bad = ~in_range | (heads["opcode"] != OP_MESSAGE) | (length < _MESSAGE_FIXED) | (length > room)
        bad |= (heads["channel_id"] != claimed) | (heads["log_time"] != index_time)
        bad |= heads["log_time"] > np.uint64(_INT64_MAX)
        end = start + np.where(bad, 0, length).astype(np.int64) + 9
        # Tiling: each message starts where the one before it in its chunk ends (the first at the chunk's start),
        # and the last ends where the chunk ends.
        first = np.ones(len(start), dtype=bool)
        first[1:] = cand_id[1:] != cand_id[:-1]
        last = np.ones(len(start), dtype=bool)
        last[:-1] = first[1:]
        expected = np.where(first, bases[cand_id], np.concatenate(([0], end[:-1])))
        bad |= start != expected
        bad |= last & (end != bases[cand_id] + n)
        bad_cand = np.bincount(cand_id[bad], minlength=len(cands)) > 0
        channel = heads["channel_id"].astype(np.int64)
        log_time = heads["log_time"].astype(np.int64)
        return (cand_id, channel, log_time, start, end, buf), bad_cand


class ChunkMessages:
    """The messages of one chunk checked on its own by `split_chunk`, by channel."""

    __slots__ = ("chunk_offset", "buf", "channels")

    def __init__(self, chunk_offset: int, buf: np.ndarray, channels: list[tuple[int, np.ndarray, np.ndarray,
                 np.ndarray]]) -> None:
        self.chunk_offset = chunk_offset
        self.buf = buf
        self.channels = channels  # (channel id, log times int64, payload starts, payload ends)

    def payloads(self, starts: np.ndarray, ends: np.ndarray) -> np.ndarray | list[bytes]:
        return _payloads(self.buf, starts, ends)


def split_chunk(cand: ChunkCandidate) -> list[Any] | None:
    """The records of one chunk as [schema/channel records before its first message, ChunkMessages, those after its
    last], or None if its indexes cannot be trusted to give exactly what a per-record walk gives. Unlike the batch,
    this accepts records around the messages (a chunk in which a channel is registered)."""
    data, chunk_offset = cand.data, cand.chunk_offset
    claimed, index_times, offsets = cand.arrays()
    n = len(data)
    if n < _HEAD_SIZE or int(offsets.max()) > n - _HEAD_SIZE:
        return None
    order = np.argsort(offsets, kind="stable")  # file order (an index may be sorted by log time instead)
    starts = offsets[order].astype(np.int64)
    buf = np.frombuffer(data, dtype=np.uint8)
    heads = sliding_window_view(buf, _HEAD_SIZE)[starts].view(_HEAD)[:, 0]
    lengths = heads["length"]
    log_times = heads["log_time"]
    channel_ids = heads["channel_id"]
    if not (
        (heads["opcode"] == OP_MESSAGE).all()
        and (lengths >= _MESSAGE_FIXED).all()
        and (lengths <= (n - 9 - starts).astype(np.uint64)).all()
        and (channel_ids == claimed[order]).all()
        and (log_times == index_times[order]).all()
        and (log_times <= np.uint64(_INT64_MAX)).all()
    ):
        return None
    ends = starts + 9 + lengths.astype(np.int64)
    if not (ends[:-1] <= starts[1:]).all():  # overlapping or repeated entries
        return None
    before: list[Any] = []
    after: list[Any] = []
    # Whatever lies between messages must be whole records and no message (else the index left one out).
    gap_starts = np.concatenate(([0], ends))
    gap_ends = np.concatenate((starts, [n]))
    last = len(gap_starts) - 1
    for k in np.flatnonzero(gap_starts < gap_ends).tolist():
        try:
            records = list(_inner_records(data, chunk_offset, int(gap_starts[k]), int(gap_ends[k])))
        except _Corrupt:
            return None
        if any(isinstance(r, MessageRecord) for r in records):
            return None
        if k == 0:
            before = records
        elif k == last:
            after = records
        elif records:
            # A schema or channel between two messages: its order against them matters (a message before its
            # channel record is an orphan), so this chunk is left to the per-record walk.
            return None
    times = log_times.astype(np.int64)
    payload_starts = starts + _HEAD_SIZE
    channels = []
    for channel_id in np.unique(channel_ids).tolist():
        mask = channel_ids == channel_id
        channels.append((channel_id, times[mask], payload_starts[mask], ends[mask]))
    return [*before, ChunkMessages(chunk_offset, buf, channels), *after]


def walk_chunk(cand: ChunkCandidate) -> list[Any] | None:
    """The chunk's records one by one, as `scan` gives them, or None if they do not parse (the reader then reads
    the file again the plain way, so the error is the one `scan` raises, from the same place)."""
    try:
        return list(_inner_records(cand.data, cand.chunk_offset))
    except _Corrupt:
        return None
