"""The run metadata of a recording as one typed record: the `rig`, `design`, `protocol` and `run` metadata records
(docs/log-format.md, Metadata records) read into a `RunMetadata` and written from one. Readers (the dataset, the
gap diagnosis, replay) and writers (the importer) use it instead of spelling record keys.

`read` is lenient where old recordings differ (`params` may be `parameters`, `model_params` may be `params`) and
strict where a value cannot be used (JSON that is not JSON, a design or layer count that is not an integer): the
error names the file, the record and the key.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from typing import Any

from hamr_bench.errors import RecordingError
from hamr_bench.recording.contract import MetadataName

# keys of the `run` record this class knows; any other key is kept in `run_extra`
_RUN_KEYS = ("seed", "clock", "effects", "faults", "started_utc", "source", "imported_from", "session")


@dataclass(frozen=True)
class RunMetadata:
    """What a recording says about its run. Strings as stored where the value is free text; parsed JSON where it
    is a JSON object; `design` None for a bare-actuator run (or several designs)."""

    protocol: str
    protocol_params: dict[str, Any] = field(default_factory=dict)
    protocol_file: str = ""
    design: int | None = None
    layers: int = 2
    fixture: str = ""              # leg | actuator | mixed (empty: derive from the protocol)
    params_set: str = "effective"
    model_params: dict[str, Any] = field(default_factory=dict)
    rig_name: str = ""
    rig_path: str = ""
    rig_text: str = ""
    rig_kind: str = ""             # sim | real | imported
    seed: str = ""
    clock: str = ""
    effects: dict[str, Any] = field(default_factory=dict)
    faults: tuple[str, ...] | None = None  # the faults injected (a run records them, even none); None: not said
    started_utc: str = ""
    source: str = "recorded"       # recorded | import-trace | import-points | synthetic ...
    imported_from: str = ""
    session: str = ""              # the session label given at import ("" = none given)
    run_extra: dict[str, str] = field(default_factory=dict)
    software: dict[str, str] = field(default_factory=dict)  # package -> version (the `software` record)

    @property
    def fixture_kind(self) -> str:
        """The fixture, derived from the protocol when the record does not say."""
        if self.fixture:
            return self.fixture
        return "actuator" if self.protocol == "actuator" else "leg"

    @property
    def imported(self) -> bool:
        return self.source.startswith("import")

    # ------------------------------------------------------------------------------------------- writing
    def records(self) -> list[tuple[str, dict[str, str]]]:
        """The metadata records, in the order a run writes them (rig, design, protocol, software, run); optional
        keys and the software record are written only when they say something ("recorded" is the source a record
        without one reads as)."""
        run = {"seed": self.seed, "clock": self.clock, "effects": json.dumps(self.effects)}
        if self.faults is not None:
            run["faults"] = json.dumps(list(self.faults))
        if self.source != "recorded":
            run["source"] = self.source
        if self.started_utc:
            run["started_utc"] = self.started_utc
        if self.imported_from:
            run["imported_from"] = self.imported_from
        if self.session:
            run["session"] = self.session
        run.update({k: str(v) for k, v in self.run_extra.items()})
        records: list[tuple[str, dict[str, str]]] = [
            (MetadataName.RIG, {"name": self.rig_name, "path": self.rig_path, "text": self.rig_text,
                                "kind": self.rig_kind}),
            (MetadataName.DESIGN, {"design": "" if self.design is None else str(self.design),
                                   "layers": str(self.layers), "fixture": self.fixture_kind,
                                   "params_set": self.params_set, "model_params": json.dumps(self.model_params)}),
            (MetadataName.PROTOCOL, {"name": self.protocol, "params": json.dumps(self.protocol_params),
                                     "protocol_file": self.protocol_file}),
        ]
        if self.software:
            records.append((MetadataName.SOFTWARE, dict(self.software)))
        return [*records, (MetadataName.RUN, run)]

    def write(self, recorder: Any) -> None:
        """Add the records to an open `Recorder`."""
        for name, values in self.records():
            recorder.add_metadata(name, values)

    # ------------------------------------------------------------------------------------------- reading
    @classmethod
    def read(cls, metadata: dict[str, dict[str, str]], where: str) -> RunMetadata:
        """From `RecordingReader.metadata()`; `where` (the file) prefixes every error."""
        design_md = metadata.get(MetadataName.DESIGN, {})
        protocol_md = metadata.get(MetadataName.PROTOCOL, {})
        run_md = metadata.get(MetadataName.RUN, {})
        rig_md = metadata.get(MetadataName.RIG, {})
        protocol = protocol_md.get("name", "")
        if not protocol:
            raise RecordingError(f"{where}: metadata 'protocol' has no 'name' (not a hamr-bench run recording?)")
        design_text = (design_md.get("design") or "").strip()
        layers_text = (design_md.get("layers") or "2").strip()
        try:
            design = int(design_text) if design_text not in ("", "mixed") else None
            layers = int(layers_text or 2)
        except ValueError:
            raise RecordingError(f"{where}: metadata design/layers are not integers ({design_text!r}, "
                                 f"{layers_text!r})") from None
        return cls(
            protocol=protocol,
            protocol_params=_json(protocol_md.get("params") or protocol_md.get("parameters"),
                                  f"{where}: metadata protocol.params"),
            protocol_file=protocol_md.get("protocol_file", ""),
            design=design, layers=layers, fixture=design_md.get("fixture", ""),
            params_set=design_md.get("params_set", "effective") or "effective",
            model_params=_json(design_md.get("model_params") or design_md.get("params"),
                               f"{where}: metadata design.model_params"),
            rig_name=rig_md.get("name", ""), rig_path=rig_md.get("path", ""), rig_text=rig_md.get("text", ""),
            rig_kind=rig_md.get("kind", ""),
            seed=run_md.get("seed", ""), clock=run_md.get("clock", ""),
            effects=_json(run_md.get("effects"), f"{where}: metadata run.effects"),
            faults=_faults(run_md.get("faults"), f"{where}: metadata run.faults"),
            started_utc=run_md.get("started_utc", ""), source=run_md.get("source", "recorded") or "recorded",
            imported_from=run_md.get("imported_from", ""), session=run_md.get("session", ""),
            run_extra={k: v for k, v in run_md.items() if k not in _RUN_KEYS},
            software=dict(metadata.get(MetadataName.SOFTWARE, {})))


def _faults(value: str | None, where: str) -> tuple[str, ...] | None:
    if value is None:
        return None
    try:
        out = json.loads(value)
    except ValueError:
        raise RecordingError(f"{where} is not JSON") from None
    if not isinstance(out, list) or not all(isinstance(f, str) for f in out):
        raise RecordingError(f"{where} is not a JSON list of fault names")
    return tuple(out)


def _json(value: str | None, where: str) -> dict[str, Any]:
    if not value:
        return {}
    try:
        out = json.loads(value)
    except ValueError:
        raise RecordingError(f"{where} is not JSON") from None
    if not isinstance(out, dict):
        raise RecordingError(f"{where} is not a JSON object")
    return out
