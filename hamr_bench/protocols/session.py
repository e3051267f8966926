"""One run from start to finish: build the rig, open the recording, write the metadata that makes the file
self-describing, hand the plan to the runner, and report how it ended. `run`, `campaign`, `demo` and replay all
start runs through `run_protocol`."""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from hamr_bench import __version__
from hamr_bench.protocols import get_protocol
from hamr_bench.protocols.params import as_dict, load_params
from hamr_bench.protocols.runner import RunResult, Runner
from hamr_bench.recording.run_metadata import RunMetadata
from hamr_bench.rig import load_rig, sim_rig_path


@dataclass
class RunRequest:
    """Everything that defines a run; `rig_path` None means the simulated rig."""

    protocol: str
    out: Path
    rig_path: Path | None = None
    design: int = 4
    layers: int = 2
    effects: dict[str, float] = field(default_factory=dict)
    seed: int = 0
    protocol_file: Path | None = None
    set_options: list[str] = field(default_factory=list)
    overwrite: bool = False
    quiet: bool = True
    record_traffic: bool = False
    faults: list[str] = field(default_factory=list)
    extra_metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    params: Any = None  # already-built parameters (replay); overrides protocol_file/set_options
    camera_storage: Any = None  # a hamr_bench.recording.camera_storage.CameraStorage; None: the default (roi)
    live: Any = None  # a hamr_bench.live.session.LiveView that serves this run while it is recorded
    specimen: str = ""  # the mounted specimen's label ('' names none)


class TqdmProgress:
    """A progress bar over the protocol's steps, with the present step's label and an ETA."""

    def __init__(self, total: int, description: str) -> None:
        from tqdm import tqdm

        # disable=None: no bar when stderr is not a terminal (a log file or CI gets the result lines, not redraws)
        self.bar = tqdm(total=total, desc=description, unit="step", leave=False, dynamic_ncols=True, disable=None)
        self.total = total
        self.last = -1

    def step(self, index: int, label: str) -> None:
        if index > self.last:
            self.bar.update(index - max(self.last, 0) if self.last >= 0 else 0)
            self.last = index
        self.bar.set_postfix_str(label)

    def close(self, completed: bool = True) -> None:
        if completed:  # a failed run keeps the bar where it stopped
            self.bar.update(self.total - self.bar.n)
        self.bar.close()


def software_versions() -> dict[str, str]:
    import mcap
    import numpy
    import scipy

    return {
        "hamr_bench": __version__,
        "python": platform.python_version(),
        "numpy": numpy.__version__,
        "scipy": scipy.__version__,
        "mcap": getattr(mcap, "__version__", "unknown"),
        "platform": platform.platform(),
    }


def run_protocol(req: RunRequest) -> RunResult:
    from hamr_bench.recording import Recorder

    protocol = get_protocol(req.protocol)
    params = req.params if req.params is not None else load_params(
        protocol.Params(), req.protocol_file, req.set_options)
    rig_path = req.rig_path or sim_rig_path()
    recorder = Recorder(Path(req.out), overwrite=req.overwrite, camera=req.camera_storage)
    try:
        traffic = recorder.write_bytes if req.record_traffic else None
        rig = load_rig(rig_path, design=req.design, layers=req.layers, effects=req.effects, seed=req.seed,
                       fixture=protocol.FIXTURE, record_traffic=traffic, faults=req.faults)
    except BaseException as exc:
        recorder.close("failed", f"rig could not be built: {exc}")
        raise
    try:
        _write_metadata(recorder, req, protocol, params, rig)
        progress = None if req.quiet else TqdmProgress(protocol.step_count(params), protocol.NAME)
        runner = Runner(rig, recorder, progress, specimen=req.specimen)
        if req.live is not None:
            req.live.follow(recorder, runner.request_abort)
        return runner.run(protocol, params)
    finally:
        if req.live is not None:
            req.live.unfollow()
        rig.close()


def _write_metadata(recorder: Any, req: RunRequest, protocol: Any, params: Any, rig: Any) -> None:
    RunMetadata(
        rig_name=rig.name, rig_path=rig.source_path, rig_text=rig.source_text,
        rig_kind="sim" if rig.is_simulated else "real",
        design=req.design if protocol.FIXTURE == "leg" else None, layers=req.layers, fixture=protocol.FIXTURE,
        params_set=rig.settings.get("params_set", "effective"), model_params=rig.settings.get("model_params", {}),
        protocol=protocol.NAME, protocol_params=as_dict(params), protocol_file=str(req.protocol_file or ""),
        software=software_versions(),
        seed=str(req.seed), clock="virtual" if rig.clock.is_virtual else "real", effects=dict(req.effects),
        faults=tuple(req.faults), started_utc=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        run_extra={k: str(v) for k, v in rig.settings.get("run_metadata", {}).items()},
    ).write(recorder)
    for name, values in req.extra_metadata.items():
        recorder.add_metadata(name, values)


def params_from_recording(protocol_name: str, params_json: str) -> Any:
    """Rebuild a protocol's parameter dataclass from the JSON a recording stores (replay uses it)."""
    protocol = get_protocol(protocol_name)
    values = json.loads(params_json)
    from hamr_bench.protocols.params import override

    return override(protocol.Params(), values, "recorded protocol parameters")

