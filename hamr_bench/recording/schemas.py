"""The message schemas of a hamr-bench recording: which topic carries which protobuf message, and how each is
encoded and decoded.

Every stream is protobuf with its schema stored in the file (a serialised `FileDescriptorSet`, built here at run
time from `descriptor_pb2`, so no `protoc` is needed and any MCAP reader can decode it). Scalar streams are flat
messages of `double` fields whose first field is `time_s`; one message per sample, so Foxglove plots
`/force.force_N` against `log_time` with no configuration. Because a flat message of doubles has a fixed wire
layout (tag byte, 8 little-endian bytes, per field), scalars are encoded and decoded with `struct`/numpy instead of
protobuf objects: the bytes are ordinary protobuf (the tests check them against the real protobuf classes), only
about 25 times cheaper to produce. `docs/log-format.md` is the human-readable form of this module.
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache, lru_cache
from typing import Any

from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

from hamr_bench.errors import RecordingError
from hamr_bench.recording.contract import TRAFFIC_PREFIX, Topic

PACKAGE = "hamr_bench"
IMAGE_SCHEMA = "foxglove.CompressedImage"
RAW_IMAGE_SCHEMA = "foxglove.RawImage"
IMAGE_SCHEMAS = (RAW_IMAGE_SCHEMA, IMAGE_SCHEMA)
EVENT_SCHEMA = f"{PACKAGE}.Event"
TRAFFIC_SCHEMA = f"{PACKAGE}.SerialTraffic"
LOG_SCHEMA = "foxglove.Log"
ANNOTATIONS_SCHEMA = "foxglove.ImageAnnotations"
STEP_SCHEMA = f"{PACKAGE}.StepCondition"
# Topics the recorder writes itself, never as plain scalars (format 2 adds the last five).
RESERVED_TOPICS = (Topic.EVENTS, Topic.CAMERA_IMAGE, Topic.LOG, Topic.STEP, Topic.CAMERA_ROI, Topic.CAMERA_ANNOTATIONS)

_FDP = descriptor_pb2.FieldDescriptorProto
# Only field numbers 1..15 have a one-byte tag; the fixed-layout fast path relies on that.
MAX_SCALAR_FIELDS = 15


@dataclass(frozen=True)
class ScalarSchema:
    """A flat protobuf message: `time_s` then `fields`, all `double`, numbered 1, 2, 3, ..."""

    name: str
    fields: tuple[str, ...]

    @property
    def all_fields(self) -> tuple[str, ...]:
        return ("time_s", *self.fields)

    @property
    def struct(self) -> struct.Struct:
        """Wire layout: for each field a tag byte ((number << 3) | 1 = 64-bit) then the double."""
        return _scalar_struct(len(self.all_fields))

    @property
    def tags(self) -> tuple[int, ...]:
        return tuple(((i + 1) << 3) | 1 for i in range(len(self.all_fields)))

    def descriptor_set(self) -> bytes:
        return _message_descriptor_set(self.name, [(name, _FDP.TYPE_DOUBLE) for name in self.all_fields])

    def packer(self) -> Callable[[float, dict[str, float]], bytes]:
        """A function (time_s, {field: value}) -> protobuf bytes; raises KeyError on a missing or extra field and
        struct.error on a value that is not a number. One- and two-value topics get a specialised function
        because they carry nearly every sample (10 kHz force)."""
        pack = self.struct.pack
        names = self.fields
        n = len(names)
        if n == 1:
            (name,) = names

            def pack1(time_s: float, fields: dict[str, float]) -> bytes:
                if len(fields) != 1:
                    raise KeyError(name)
                return pack(9, time_s, 17, fields[name])

            return pack1
        tags = self.tags[1:]

        def pack_n(time_s: float, fields: dict[str, float]) -> bytes:
            if len(fields) != n:
                raise KeyError(names)
            args: list[float] = [9, time_s]
            for tag, name in zip(tags, names):
                args.append(tag)
                args.append(fields[name])
            return pack(*args)

        return pack_n


@cache
def _scalar_struct(n_fields: int) -> struct.Struct:
    return struct.Struct("<" + "Bd" * n_fields)


# The documented scalar streams (docs/log-format.md). Topics sharing a field set share a schema.
FORCE = ScalarSchema(f"{PACKAGE}.Force", ("force_N",))
STAGE_POSITION = ScalarSchema(f"{PACKAGE}.StagePosition", ("position_m",))
STAGE_COMMAND = ScalarSchema(f"{PACKAGE}.StageCommand", ("target_m",))
VOLTAGE = ScalarSchema(f"{PACKAGE}.Voltage", ("voltage_V",))
CAMERA_DISPLACEMENT = ScalarSchema(f"{PACKAGE}.CameraDisplacement", ("displacement_m", "x_px", "y_px"))
IMAGE_REGION = ScalarSchema(f"{PACKAGE}.ImageRegion", ("x0_px", "y0_px"))

KNOWN_SCALAR_TOPICS: dict[str, ScalarSchema] = {
    Topic.FORCE: FORCE,
    Topic.STAGE_POSITION: STAGE_POSITION,
    Topic.STAGE_COMMAND: STAGE_COMMAND,
    Topic.BIAS_COMMAND: VOLTAGE,
    Topic.DRIVE_COMMAND: VOLTAGE,
    Topic.BIAS_MONITOR: VOLTAGE,
    Topic.DRIVE_MONITOR: VOLTAGE,
    Topic.CAMERA_DISPLACEMENT: CAMERA_DISPLACEMENT,
    Topic.CAMERA_ROI_ORIGIN: IMAGE_REGION,
}

# Unit suffixes of field names (docs/log-format.md, "Units"): a field `name_<suffix>` is in that unit.
UNIT_SUFFIXES = {"s": "s", "m": "m", "N": "N", "V": "V", "px": "px", "Hz": "Hz", "A": "A", "rad": "rad",
                 "Pa": "Pa", "K": "K", "W": "W", "J": "J", "kg": "kg", "ns": "ns"}


def unit_of(field_name: str) -> str | None:
    """The unit a field name's suffix names (`force_N` -> N), or None when it names none (`step`)."""
    _, sep, suffix = field_name.rpartition("_")
    return UNIT_SUFFIXES.get(suffix) if sep else None


def units_metadata(field_names: tuple[str, ...] | list[str]) -> dict[str, str]:
    """Channel metadata giving each field's unit: {"unit.force_N": "N", ...} (fields without a unit left out)."""
    return {f"unit.{name}": unit for name in field_names if (unit := unit_of(name)) is not None}

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_TOPIC = re.compile(r"^/[A-Za-z0-9_]+(/[A-Za-z0-9_]+)*$")


def check_topic(topic: str) -> None:
    if not isinstance(topic, str) or not _TOPIC.match(topic):
        raise RecordingError(
            f"topic {topic!r} is not a valid topic (expected '/name' or '/a/b', letters, digits, _)"
        )


def scalar_schema_for(topic: str, field_names: tuple[str, ...]) -> ScalarSchema:
    """The schema a scalar topic uses: the documented one for a known topic (its fields must match), or one made
    from the field names for any other topic (`hamr_bench.Scalar_<fields>`)."""
    check_topic(topic)
    known = KNOWN_SCALAR_TOPICS.get(topic)
    if known is not None:
        if set(field_names) != set(known.fields):
            raise RecordingError(
                f"topic {topic} takes fields {', '.join(known.fields)}; got {', '.join(field_names) or 'none'}"
            )
        return known
    if topic in RESERVED_TOPICS or topic.startswith(TRAFFIC_PREFIX) or topic.startswith(Topic.CAMERA_IMAGE):
        raise RecordingError(f"topic {topic} is reserved for events, logs, steps, traffic or images, not scalars")
    if not field_names:
        raise RecordingError(f"topic {topic}: a scalar sample needs at least one field (e.g. force_N=0.1)")
    if len(field_names) + 1 > MAX_SCALAR_FIELDS:
        raise RecordingError(f"topic {topic}: at most {MAX_SCALAR_FIELDS - 1} fields per scalar topic")
    for name in field_names:
        if not _IDENT.match(name) or name == "time_s":
            raise RecordingError(f"topic {topic}: field name {name!r} is not allowed")
    return ScalarSchema(f"{PACKAGE}.Scalar_{'_'.join(field_names)}", tuple(field_names))


def _message_descriptor_set(full_name: str, fields: list[tuple[str, int]]) -> bytes:
    package, _, message_name = full_name.rpartition(".")
    file_proto = descriptor_pb2.FileDescriptorProto(
        name=f"{package.replace('.', '/')}/{message_name}.proto", package=package, syntax="proto3"
    )
    message = file_proto.message_type.add(name=message_name)
    for number, (name, field_type) in enumerate(fields, start=1):
        message.field.add(name=name, number=number, type=field_type, label=_FDP.LABEL_OPTIONAL)
    return descriptor_pb2.FileDescriptorSet(file=[file_proto]).SerializeToString()


EVENT_FIELDS = [
    ("time_s", _FDP.TYPE_DOUBLE),
    ("step", _FDP.TYPE_INT64),
    ("kind", _FDP.TYPE_STRING),
    ("message", _FDP.TYPE_STRING),
    ("data", _FDP.TYPE_STRING),
]
TRAFFIC_FIELDS = [
    ("time_s", _FDP.TYPE_DOUBLE),
    ("direction", _FDP.TYPE_STRING),
    ("data", _FDP.TYPE_BYTES),
]


# A step's condition as typed fields, so Foxglove plots e.g. `/step.voltage_V` (numbers absent from a condition are
# NaN; `design` and `layers` 0 when the condition names none; strings empty).
STEP_FIELDS = [
    ("time_s", _FDP.TYPE_DOUBLE),
    ("step", _FDP.TYPE_INT32),
    ("voltage_V", _FDP.TYPE_DOUBLE),
    ("sag_m", _FDP.TYPE_DOUBLE),
    ("repetition", _FDP.TYPE_INT32),
    ("direction", _FDP.TYPE_STRING),
    ("mode", _FDP.TYPE_STRING),
    ("design", _FDP.TYPE_INT32),
    ("layers", _FDP.TYPE_INT32),
    ("specimen", _FDP.TYPE_STRING),
    ("label", _FDP.TYPE_STRING),
]


@cache
def step_descriptor_set() -> bytes:
    return _message_descriptor_set(STEP_SCHEMA, STEP_FIELDS)


@cache
def log_descriptor_set() -> bytes:
    from foxglove_schemas_protobuf.Log_pb2 import Log
    from mcap_protobuf.schema import build_file_descriptor_set

    return build_file_descriptor_set(Log).SerializeToString()


@cache
def annotations_descriptor_set() -> bytes:
    from foxglove_schemas_protobuf.ImageAnnotations_pb2 import ImageAnnotations
    from mcap_protobuf.schema import build_file_descriptor_set

    return build_file_descriptor_set(ImageAnnotations).SerializeToString()


@cache
def event_descriptor_set() -> bytes:
    return _message_descriptor_set(EVENT_SCHEMA, EVENT_FIELDS)


@cache
def traffic_descriptor_set() -> bytes:
    return _message_descriptor_set(TRAFFIC_SCHEMA, TRAFFIC_FIELDS)


@cache
def image_descriptor_set() -> bytes:
    from foxglove_schemas_protobuf.CompressedImage_pb2 import CompressedImage
    from mcap_protobuf.schema import build_file_descriptor_set

    return build_file_descriptor_set(CompressedImage).SerializeToString()


@cache
def raw_image_descriptor_set() -> bytes:
    from foxglove_schemas_protobuf.RawImage_pb2 import RawImage
    from mcap_protobuf.schema import build_file_descriptor_set

    return build_file_descriptor_set(RawImage).SerializeToString()


@lru_cache(maxsize=64)
def message_class(schema_name: str, descriptor_set: bytes) -> Any:
    """A protobuf message class for `schema_name`, built from the FileDescriptorSet stored in a file (so files from
    another version of this code, or another writer, still decode). Raises RecordingError if it cannot be built."""
    try:
        fds = descriptor_pb2.FileDescriptorSet.FromString(descriptor_set)
        pool = descriptor_pool.DescriptorPool()
        for file_proto in fds.file:
            pool.Add(file_proto)
        return message_factory.GetMessageClass(pool.FindMessageTypeByName(schema_name))
    except Exception as exc:  # protobuf raises several unrelated types for a bad descriptor
        raise RecordingError(f"schema {schema_name}: stored protobuf descriptor is unreadable ({exc})") from None


def scalar_fields_from_descriptor(schema_name: str, descriptor_set: bytes) -> tuple[str, ...] | None:
    """The field names of a flat all-double message whose first field is `time_s` (numbered 1..n), or None if the
    stored schema is not of that form."""
    cls = message_class(schema_name, descriptor_set)
    fields = cls.DESCRIPTOR.fields
    if not fields or len(fields) > MAX_SCALAR_FIELDS:
        return None
    for i, f in enumerate(fields):
        if f.number != i + 1 or f.type != f.TYPE_DOUBLE or f.is_repeated:
            return None
    names = tuple(f.name for f in fields)
    return names[1:] if names[0] == "time_s" else None
