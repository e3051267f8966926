"""Recording a run to one self-describing MCAP file, reading it back, summarising and recovering it.

`Recorder` writes (a single writer thread fed by a queue), `RecordingReader` reads, `recover` rebuilds a finished
file from a killed writer's output, `summarise` feeds `hamr-bench info`. The format is specified in
docs/log-format.md; `schemas` is its code form.
"""

from hamr_bench.recording.reader import Event, Image, RecordingReader, RecordingWarning, TopicInfo, Traffic
from hamr_bench.recording.writer import EXIT_STATUSES, Recorder, RecorderStats

__all__ = [
    "EXIT_STATUSES",
    "Event",
    "Image",
    "Recorder",
    "RecorderStats",
    "RecordingReader",
    "RecordingWarning",
    "TopicInfo",
    "Traffic",
    "recover",
    "RecoverReport",
    "summarise",
]


def __getattr__(name: str):  # recover/info import lazily: most callers only write or read
    if name in ("recover", "RecoverReport"):
        from hamr_bench.recording import recover as module

        return getattr(module, name)
    if name == "summarise":
        from hamr_bench.recording.info import summarise

        return summarise
    raise AttributeError(name)
