"""The shipped Foxglove layout (docs/foxglove/hamr-bench.json) names only topics, fields and services a recording
and the live server have: every message path is checked against the schema the recorder writes for that topic."""

from __future__ import annotations

import json
from pathlib import Path

from hamr_bench.live.control import ABORT_SERVICE
from hamr_bench.recording import schemas

LAYOUT = Path(__file__).resolve().parents[2] / "docs" / "foxglove" / "hamr-bench.json"


def _fields(topic: str) -> set[str]:
    if topic in schemas.KNOWN_SCALAR_TOPICS:
        return set(schemas.KNOWN_SCALAR_TOPICS[topic].all_fields)
    if topic == "/step":
        return {name for name, _ in schemas.STEP_FIELDS}
    raise AssertionError(f"the layout plots {topic}, which has no known fields")


def test_every_path_in_the_layout_exists():
    layout = json.loads(LAYOUT.read_text())
    configs = layout["configById"]
    paths = [p["value"] for c in configs.values() for p in c.get("paths", [])]
    assert paths
    for path in paths:
        topic, _, field = path.rpartition(".")
        assert field in _fields(topic), path
    images = {c["imageMode"]["imageTopic"] for c in configs.values() if "imageMode" in c}
    assert images == {"/camera/image", "/camera/roi"}
    annotations = [t for c in configs.values() for t in c.get("imageMode", {}).get("annotations", {})]
    assert annotations == ["/camera/annotations"]
    assert [c["topicToRender"] for c in configs.values() if "topicToRender" in c] == ["/log"]
    assert [c["serviceName"] for c in configs.values() if "serviceName" in c] == [ABORT_SERVICE]

    def panels(node):
        return [node] if isinstance(node, str) else panels(node["first"]) + panels(node["second"])

    assert sorted(panels(layout["layout"])) == sorted(configs)
