"""The protobuf wire bytes of the two Foxglove image messages, built by hand around the pixels.

`foxglove.RawImage` and `foxglove.CompressedImage` through protobuf copy a frame twice (into the message, then out
of it); here each is one join around the pixel bytes. Byte-identical to protobuf's serialiser (property tests in
`tests/benchmarks/test_fast_paths.py`); the recorder's `write_image` uses them.
"""

from __future__ import annotations

import struct
from functools import lru_cache


def _varint(value: int) -> bytes:
    """Protobuf base-128 varint; negative int64 values as their 64-bit two's complement (10 bytes)."""
    if value < 0:
        value += 1 << 64
    out = bytearray()
    while value > 0x7F:
        out.append((value & 0x7F) | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _timestamp(timestamp_ns: int) -> bytes:
    """The body of a `google.protobuf.Timestamp` (seconds 1, nanos 2; zeros left out) for `timestamp_ns`."""
    seconds, nanos = divmod(int(timestamp_ns), 1_000_000_000)
    if not -(1 << 63) <= seconds < (1 << 63):
        raise OverflowError(f"timestamp {timestamp_ns} ns out of range")
    return (b"\x08" + _varint(seconds) if seconds else b"") + (b"\x10" + _varint(nanos) if nanos else b"")


def compressed_image_payload(timestamp_ns: int, frame_id: str, image_format: str, data: bytes) -> bytes:
    """The bytes `foxglove.CompressedImage(timestamp, frame_id, data, format).SerializeToString()` gives, built with
    one copy of `data` (protobuf copies a frame twice: into the message, then out of it; at 100 fps of 640x480 that
    was about 1 % of a core). Fields in number order, defaults (0, empty) left out, as protobuf writes them; the
    timestamp sub-message is always present (the recorder always sets it)."""
    stamp = _timestamp(timestamp_ns)
    values = {"timestamp": stamp, "frame_id": frame_id.encode("utf-8"), "data": data,
              "format": image_format.encode("utf-8")}
    parts = []
    for name, tag in _image_field_tags():
        value = values[name]
        if value or name == "timestamp":  # a timestamp that was set is written even when it is zero
            parts += [tag, _varint(len(value)), value]
    return b"".join(parts)


def raw_image_payload(timestamp_ns: int, frame_id: str, width: int, height: int, encoding: str, step: int,
                      data: bytes) -> bytes:
    """The bytes `foxglove.RawImage(timestamp, frame_id, width, height, encoding, step, data).SerializeToString()`
    gives, with one copy of `data` (as `compressed_image_payload`; checked against protobuf in the tests). Fields
    in number order: timestamp 1, width 2, height 3 (fixed32), encoding 4, step 5 (fixed32), data 6, frame_id 7."""
    stamp = _timestamp(timestamp_ns)
    name = encoding.encode("utf-8")
    frame = frame_id.encode("utf-8")
    parts = [b"\x0a", _varint(len(stamp)), stamp]
    for tag, value in ((b"\x15", width), (b"\x1d", height)):
        if value:
            parts += [tag, struct.pack("<I", value)]
    if name:
        parts += [b"\x22", _varint(len(name)), name]
    if step:
        parts += [b"\x2d", struct.pack("<I", step)]
    if data:
        parts += [b"\x32", _varint(len(data)), data]
    if frame:
        parts += [b"\x3a", _varint(len(frame)), frame]
    return b"".join(parts)


@lru_cache(maxsize=1)
def _image_field_tags() -> tuple[tuple[str, bytes], ...]:
    """(field name, length-delimited tag byte) of foxglove.CompressedImage in field-number order, from its
    descriptor (the schema's numbering is not its declaration order)."""
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage

    fields = sorted(CompressedImage.DESCRIPTOR.fields, key=lambda f: f.number)
    assert {f.name for f in fields} == {"timestamp", "frame_id", "data", "format"} and fields[-1].number < 16
    return tuple((f.name, bytes([(f.number << 3) | 2])) for f in fields)
