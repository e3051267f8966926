"""The recorder's side door: what a `RecorderTap` (the live view) is told, beside the writer's queue.

A tap sees every channel as it is registered and every message as it is handed to the recorder, on the producer's
thread, before the writer thread has it. It must return at once and never raise: the recorder calls it with the
message already queued for the file, and a tap that fails is dropped (the recording goes on). Nothing a tap does
can slow, block or drop what goes to the file; see hamr_bench/live/ for the one there is.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


@dataclass(frozen=True)
class TapChannel:
    """A channel as the file declares it."""

    index: int
    topic: str
    schema_name: str
    schema_data: bytes  # serialised protobuf FileDescriptorSet
    metadata: dict[str, str]
    is_image: bool


class RecorderTap(Protocol):
    def channel(self, channel: TapChannel) -> None:
        """A channel was registered (called once per channel, before its first message)."""

    def message(self, index: int, time_s: float, payload: bytes) -> None:
        """A message of channel `index` was queued for the file."""

    def wants_frame(self, time_s: float) -> bool:
        """Whether a full camera frame at `time_s` that the file does not keep should be offered (`frame`)."""

    def frame(self, time_s: float, payload: bytes) -> None:
        """A full camera frame (`foxglove.RawImage` bytes of `/camera/image`) the file does not keep."""
