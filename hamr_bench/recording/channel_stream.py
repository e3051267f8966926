"""One channel's messages as a recording is read: the per-channel store of `RecordingReader`.

Messages arrive in file order either one record at a time (the plain scan) or as numpy blocks of a whole chunk
(`index_scan.py`); the store keeps both kinds of block in order and joins them when asked, so the reader gives the
same answers either way.
"""

from __future__ import annotations

import numpy as np


class ChannelStream:
    """One channel's messages in file order, as blocks: Python lists filled record by record, or the numpy arrays of
    an indexed chunk (log times int64; payloads an (n, size) uint8 array when all have one size). Lazy (image)
    streams keep no payloads, only the offsets of the chunks that hold them."""

    __slots__ = ("lazy", "time_blocks", "payload_blocks", "chunk_offsets", "count", "_times", "_payloads")

    def __init__(self, lazy: bool = False) -> None:
        self.lazy = lazy
        self.time_blocks: list[list[int] | np.ndarray] = []
        self.payload_blocks: list[list[bytes] | np.ndarray] = []
        self.chunk_offsets: list[int] = []
        self.count = 0
        self._times: list[int] | None = None  # the list block being filled record by record, if the last is one
        self._payloads: list[bytes] | None = None

    def add_record(self, log_time: int, payload: bytes) -> None:
        if self._times is None:
            self._times = []
            self.time_blocks.append(self._times)
            if not self.lazy:
                self._payloads = []
                self.payload_blocks.append(self._payloads)
        self._times.append(log_time)
        if self._payloads is not None:
            self._payloads.append(payload)
        self.count += 1

    def add_block(self, log_times: np.ndarray, payloads: np.ndarray | list[bytes] | None) -> None:
        self._times = self._payloads = None
        self.time_blocks.append(log_times)
        if payloads is not None:
            self.payload_blocks.append(payloads)
        self.count += len(log_times)

    def add_chunk_offset(self, chunk_offset: int) -> None:
        if not self.chunk_offsets or self.chunk_offsets[-1] != chunk_offset:
            self.chunk_offsets.append(chunk_offset)

    def first_last_ns(self) -> tuple[int, int] | None:
        """Smallest and largest log time (Python ints, as the record path always gave), None if no message."""
        lows = [int(b.min()) if isinstance(b, np.ndarray) else min(b) for b in self.time_blocks if len(b)]
        highs = [int(b.max()) if isinstance(b, np.ndarray) else max(b) for b in self.time_blocks if len(b)]
        return (min(lows), max(highs)) if lows else None

    def log_times(self) -> np.ndarray:
        # np.asarray on a list block raises OverflowError past int64 as before; indexed blocks never hold such times.
        if not self.time_blocks:
            return np.asarray([], dtype=np.int64)
        return np.concatenate([np.asarray(b, dtype=np.int64) for b in self.time_blocks])

    def payloads(self) -> list[bytes]:
        out: list[bytes] = []
        for block in self.payload_blocks:
            if isinstance(block, np.ndarray):
                out.extend(row.tobytes() for row in block)
            else:
                out.extend(block)
        return out

    def payload_matrix(self, size: int) -> np.ndarray | None:
        """All payloads as one (n, size) uint8 array if every one is `size` bytes long, else None."""
        parts = []
        for block in self.payload_blocks:
            if isinstance(block, np.ndarray):
                if block.shape[1] != size:
                    return None
                parts.append(block)
            else:
                if not all(len(p) == size for p in block):
                    return None
                parts.append(np.frombuffer(b"".join(block), dtype=np.uint8).reshape(-1, size))
        if not parts:
            return np.empty((0, size), dtype=np.uint8)
        return np.ascontiguousarray(np.concatenate(parts) if len(parts) > 1 else parts[0])
