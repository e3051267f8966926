"""The recording's names are spelled in one place, `hamr_bench/recording/contract.py` (`Topic`, `TRAFFIC_PREFIX`,
`EventKind`, `MetadataName`): every other module of the packages names them through it. Checked on the syntax tree
of every module (docstrings are documentation and may show a topic):

- topics: any string literal (or literal part of an f-string) holding a topic name (one that starts with a
  topic's first segment: `/force`, `/stage`, `/amplifier`, `/camera`, `/events`, `/log`, `/step`, `/traffic`);
- metadata names: the first argument of `add_metadata(...)`, and a literal record name looked up in a mapping
  whose expression says `meta` (`metadata.get("run_end")`, `meta["design"]`);
- event kinds: the kind given to `record_event`, `RecordEvent`, `Note`, `write_event` (second argument), and a
  literal kind compared with `.kind` of an event (a name bound by a loop over something that says `event`) or with
  a variable named `kind`;
- metadata names, also: a literal compared with a record's `.name` (`record.name == "run_end"`) and a mapping
  literal keyed by record names only (a table per record).

The tests (`tests/`) spell the names on purpose: a test that reads a topic through the contract would pass if the
contract itself changed a name, so they stay an independent check of the file format.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from hamr_bench.recording.contract import TRAFFIC_PREFIX, EventKind, MetadataName, Topic

REPO = Path(__file__).resolve().parents[2]
PACKAGES = ("hamr_bench", "drivers", "sim_devices", "analysis", "benchmarks")
CONTRACT = "hamr_bench/recording/contract.py"
# a topic's first path segment (`/force`, `/stage/...`, `/traffic/...`), not inside a longer path or word
_FIRST_SEGMENTS = sorted({t.split("/")[1] for t in [*Topic, TRAFFIC_PREFIX]})
TOPIC = re.compile(rf"(?<![\w./-])/({'|'.join(_FIRST_SEGMENTS)})\b")
EVENT_CALLS = {"record_event": 0, "RecordEvent": 0, "Note": 0, "write_event": 1}  # name -> position of the kind
METADATA_NAMES = frozenset(MetadataName)
EVENT_KINDS = frozenset(EventKind)


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                ids.add(id(first.value))
    return ids


def _literal(node: ast.AST | None) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _call_name(call: ast.Call) -> str:
    func = call.func
    return func.attr if isinstance(func, ast.Attribute) else func.id if isinstance(func, ast.Name) else ""


def _event_names(tree: ast.AST) -> set[str]:
    """Names bound by a loop or comprehension over an expression that says `event`."""
    names: set[str] = set()
    loops = [(n.target, n.iter) for n in ast.walk(tree) if isinstance(n, ast.For | ast.comprehension)]
    for target, iterable in loops:
        if "event" in ast.unparse(iterable).lower():
            names |= {n.id for n in ast.walk(target) if isinstance(n, ast.Name)}
    return names


def spellings(source: str, rel: str) -> list[tuple[int, str, str]]:
    """(line, what, name) of every recording name `source` spells instead of naming it through the contract."""
    tree = ast.parse(source, rel)
    docstrings = _docstrings(tree)
    events = _event_names(tree)
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            found += [(node.lineno, "topic", node.value[m.start():].split()[0]) for m in TOPIC.finditer(node.value)]
        elif isinstance(node, ast.Call):
            found += [(node.lineno, what, name) for what, name in _call_spellings(node)]
        elif isinstance(node, ast.Subscript) and _says_meta(node.value) and _literal(node.slice) in METADATA_NAMES:
            found.append((node.lineno, "metadata", _literal(node.slice) or ""))
        elif isinstance(node, ast.Compare):
            found += [(node.lineno, what, name) for what, name in _compare_spellings(node, events)]
        elif isinstance(node, ast.Dict) and len(node.keys) >= 2 \
                and all(_literal(k) in METADATA_NAMES for k in node.keys):
            found += [(node.lineno, "metadata", _literal(k) or "") for k in node.keys]
    return found


def _compare_spellings(node: ast.Compare, events: set[str]) -> list[tuple[str, str]]:
    """`event.kind == "step"` (an event bound by a loop over events), `kind == "run_end"` (a variable holding an
    event's kind), `record.name == "run_end"` (a metadata record's name)."""
    left = node.left
    if isinstance(left, ast.Name) and left.id == "kind" or isinstance(left, ast.Attribute) and left.attr == "kind" \
            and isinstance(left.value, ast.Name) and left.value.id in events:
        what, names = "event", EVENT_KINDS
    elif isinstance(left, ast.Attribute) and left.attr == "name" and any(
            w in ast.unparse(left.value).lower() for w in ("meta", "record")):
        what, names = "metadata", METADATA_NAMES
    else:
        return []
    found = []
    for right in node.comparators:
        values = right.elts if isinstance(right, ast.Tuple | ast.List | ast.Set) else [right]
        found += [(what, v) for v in map(_literal, values) if v in names]
    return found


def _says_meta(node: ast.expr) -> bool:
    return "meta" in ast.unparse(node).lower()


def _call_spellings(call: ast.Call) -> list[tuple[str, str]]:
    name = _call_name(call)
    first = _literal(call.args[0]) if call.args else None
    if name == "add_metadata" and first is not None:
        return [("metadata", first)]
    if name == "get" and isinstance(call.func, ast.Attribute) and _says_meta(call.func.value) \
            and first in METADATA_NAMES:
        return [("metadata", first or "")]
    if name in EVENT_CALLS:
        pos = EVENT_CALLS[name]
        kind = call.args[pos] if len(call.args) > pos else next(
            (k.value for k in call.keywords if k.arg == "kind"), None)
        literal = _literal(kind)
        return [] if literal is None else [("event", literal)]
    return []


def all_spellings() -> list[tuple[str, int, str, str]]:
    found = []
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            if rel != CONTRACT:
                found += [(rel, line, what, name) for line, what, name in spellings(path.read_text("utf-8"), rel)]
    return found


def test_recording_names_are_spelled_only_in_the_contract():
    stray = [f"{rel}:{line}: {what} name {name!r}: use hamr_bench.recording.contract"
             for rel, line, what, name in all_spellings()]
    assert not stray, "\n".join(stray)


def test_the_check_sees_each_form():
    source = '''
"""A docstring may show "/force"."""
def f(rec, reader, runner, events):
    rec.write_scalar("/force", 0.0, force_N=1.0)
    topic = f"/traffic/{device}"
    rec.add_metadata("rig", {})
    reader.metadata.get("run_end", {})
    meta["design"]
    runner.record_event("tare")
    rec.write_event(0.0, "step", 1)
    steps = [e for e in events if e.kind == "step"]
    for ev in reader.events():
        if ev.kind in ("run_end", "safe_state"):
            pass
    motion.kind == "home"                      # not an event: the loop variable above is not it
    if kind == "run_end": pass
    if record.name == "run_end": pass
    highlights = {"run_end": ("reason",), "rig": ("name",)}
    condition = {"protocol": "static", "voltage_V": 0.0}  # a step's condition, not a table of records
    path = "tests/force/x"                     # not a topic
    rec.write_scalar(Topic.FORCE, 0.0, force_N=1.0)
'''
    found = [(what, name) for _, what, name in spellings(source, "example.py")]
    assert sorted(found) == sorted([
        ("topic", "/force"), ("topic", "/traffic/"), ("metadata", "rig"), ("metadata", "run_end"),
        ("metadata", "design"), ("event", "tare"), ("event", "step"), ("event", "step"), ("event", "run_end"),
        ("event", "safe_state"), ("event", "run_end"), ("metadata", "run_end"), ("metadata", "run_end"),
        ("metadata", "rig")])
