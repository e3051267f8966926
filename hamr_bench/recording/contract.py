"""The recording contract: the names every writer and reader of a hamr-bench recording agree on.

Topic names, event kinds and metadata record names are spelled here and nowhere else; writers (the runner, the
importer, replay) and readers (the dataset, the gap diagnosis, `info`) import them. `docs/log-format.md` is the
human-readable form. The enums are `StrEnum`s, so a member compares equal to the string stored in the file and
recordings written before this module existed read unchanged.

The typed parts of the contract live in sibling modules and are re-exported here (imported lazily, since they
import this module's names): `RunMetadata` (the run's metadata records, `run_metadata.py`), `iter_steps`,
`parse_run`, `read_run`, `StepRecord`, `DriveTiming`, `Timelines` (the one step parser, `steps.py`) and `Cycle`,
`infer_cycles` (drive timing from a waveform, `drive_timing.py`).
"""

from __future__ import annotations

from enum import StrEnum


class Topic(StrEnum):
    """Fixed topics of a recording (traffic topics are `TRAFFIC_PREFIX + device`)."""

    FORCE = "/force"
    STAGE_POSITION = "/stage/position"
    STAGE_COMMAND = "/stage/command"
    BIAS_COMMAND = "/amplifier/bias/command"
    DRIVE_COMMAND = "/amplifier/drive/command"
    BIAS_MONITOR = "/amplifier/bias/monitor"
    DRIVE_MONITOR = "/amplifier/drive/monitor"
    CAMERA_DISPLACEMENT = "/camera/displacement"
    CAMERA_IMAGE = "/camera/image"
    CAMERA_ROI = "/camera/roi"  # format 2: the region around the marker, every frame
    CAMERA_ROI_ORIGIN = "/camera/roi/origin"  # format 2: that region's top-left pixel in the full frame
    CAMERA_ANNOTATIONS = "/camera/annotations"  # format 2: the tracked marker drawn on /camera/image
    EVENTS = "/events"
    LOG = "/log"  # format 2: every event as a foxglove.Log (Foxglove's Log panel)
    STEP = "/step"  # format 2: each step's condition as typed fields (plottable by message path)


TRAFFIC_PREFIX = "/traffic/"


def amplifier_topics(channel: str) -> tuple[Topic, Topic]:
    """(command, monitor) topics of one amplifier channel, `bias` or `drive`."""
    if channel == "bias":
        return Topic.BIAS_COMMAND, Topic.BIAS_MONITOR
    if channel == "drive":
        return Topic.DRIVE_COMMAND, Topic.DRIVE_MONITOR
    raise ValueError(f"amplifier channel {channel!r}: expected 'bias' or 'drive'")


class EventKind(StrEnum):
    """What an `/events` message says happened (docs/log-format.md, Events)."""

    RUN_START = "run_start"
    STEP = "step"
    HOME = "home"
    TARE = "tare"
    CONTACT_FOUND = "contact_found"
    SET_VOLTAGES = "set_voltages"
    DRIVE_START = "drive_start"
    DRIVE_END = "drive_end"
    MEASUREMENT = "measurement"
    SPECIMEN = "specimen"
    SAFE_STATE = "safe_state"
    RUN_END = "run_end"


class MetadataName(StrEnum):
    """Names of the MCAP metadata records of a recording."""

    RECORDING = "recording"
    RIG = "rig"
    DESIGN = "design"
    PROTOCOL = "protocol"
    SOFTWARE = "software"
    RUN = "run"
    REPLAY = "replay"
    RUN_END = "run_end"


_LAZY = {
    "RunMetadata": "run_metadata",
    "iter_steps": "steps", "parse_run": "steps", "read_run": "steps", "StepRecord": "steps",
    "DriveTiming": "steps", "Timelines": "steps", "ParsedRun": "steps", "Block": "steps",
    "Cycle": "drive_timing", "infer_cycles": "drive_timing",
}


def __getattr__(name: str) -> object:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    from importlib import import_module

    return getattr(import_module(f"hamr_bench.recording.{module}"), name)
