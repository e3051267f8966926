"""Lint (ruff) and type (mypy) findings compared with checked-in baselines that may only shrink.

A finding is keyed by file, rule and message, and counted: line numbers are left out (and so are the numbers in a
message such as "too complex (12 > 10)"), so code moving inside a file, or a branch merged beside it, does not
disturb the baseline. `tests/house/test_lint.py` and `test_types.py` fail when a finding is not in the baseline
(fix it; a finding that must stay is added to the baseline by hand, with its reason) and when a baselined finding
is gone (remove it: `python3 -m tests.house.baselines prune`, which never adds anything). Every baseline entry
carries the reason it is still there.

    python3 -m tests.house.baselines check    # print new and fixed findings, as the tests see them
    python3 -m tests.house.baselines prune    # drop fixed findings from the baselines
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
import tomllib
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
HERE = Path(__file__).resolve().parent
RUFF_PATHS = ("hamr_bench", "drivers", "sim_devices", "analysis", "benchmarks", "tests")
MYPY_PATHS = ("hamr_bench", "drivers", "sim_devices", "analysis", "benchmarks")

Key = tuple[str, str, str]  # (file, rule, message)


@dataclass(frozen=True)
class Tool:
    name: str
    baseline: Path

    def findings(self) -> Counter[Key]:
        return _ruff() if self.name == "ruff" else _mypy()


RUFF = Tool("ruff", HERE / "ruff_baseline.toml")
MYPY = Tool("mypy", HERE / "mypy_baseline.toml")


def pinned_version(package: str) -> str:
    """The version the `test` extra of pyproject.toml pins for `package` (the baselines were made with it)."""
    extra = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]["test"]
    (pin,) = [p for p in extra if p.startswith(f"{package}==")]
    return pin.split("==")[1]


def installed_version(package: str) -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return None


def _normalise(message: str) -> str:
    message = re.sub(r"\(\d+ > \d+\)", "", message)  # complexity, line length: the function or line is the key
    message = re.sub(r"\bline \d+\b", "line N", message)
    return " ".join(message.split())


def _run(args: list[str]) -> str:
    done = subprocess.run([sys.executable, "-m", *args], cwd=REPO, capture_output=True, text=True, check=False)
    if done.returncode not in (0, 1):  # 1: findings; anything else: the tool itself failed
        raise RuntimeError(f"{' '.join(args[:2])} failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return done.stdout


def _ruff() -> Counter[Key]:
    out = _run(["ruff", "check", "--output-format", "json", "--no-cache", *RUFF_PATHS])
    counts: Counter[Key] = Counter()
    for item in json.loads(out or "[]"):
        path = Path(item["filename"]).resolve().relative_to(REPO).as_posix()
        counts[(path, item["code"] or "syntax", _normalise(item["message"]))] += 1
    return counts


def _mypy() -> Counter[Key]:
    out = _run(["mypy", "--output", "json", "--no-error-summary", *MYPY_PATHS])
    counts: Counter[Key] = Counter()
    for line in out.splitlines():
        if not line.startswith("{"):
            continue
        item = json.loads(line)
        if item.get("severity") != "error":
            continue
        path = Path(item["file"]).as_posix()
        counts[(path, item.get("code") or "error", _normalise(item["message"]))] += 1
    return counts


@dataclass
class Entry:
    file: str
    code: str
    message: str
    count: int
    reason: str

    @property
    def key(self) -> Key:
        return (self.file, self.code, self.message)


def read_baseline(path: Path) -> list[Entry]:
    if not path.exists():
        return []
    doc = tomllib.loads(path.read_text(encoding="utf-8"))
    return [Entry(e["file"], e["code"], e["message"], int(e["count"]), e.get("reason", "")) for e in
            doc.get("finding", [])]


def write_baseline(path: Path, header: str, entries: list[Entry]) -> None:
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    for e in sorted(entries, key=lambda e: e.key):
        lines += ["", "[[finding]]", f"file = {json.dumps(e.file)}", f"code = {json.dumps(e.code)}",
                  f"message = {json.dumps(e.message, ensure_ascii=False)}", f"count = {e.count}",
                  f"reason = {json.dumps(e.reason, ensure_ascii=False)}"]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def header_of(path: Path) -> str:
    if not path.exists():
        return ""
    head = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        head.append(line[2:] if line.startswith("# ") else line[1:])
    return "\n".join(head)


@dataclass
class Comparison:
    new: list[tuple[Key, int]]  # (key, how many more than the baseline allows)
    fixed: list[tuple[Key, int]]  # (key, how many fewer than the baseline lists)
    unexplained: list[Key]  # baseline entries without a reason

    def report(self, tool: Tool) -> str:
        out = []
        if self.new:
            out.append(f"{tool.name}: {sum(n for _, n in self.new)} finding(s) not in {tool.baseline.name} (fix "
                       "them; one that must stay goes into the baseline by hand, with its reason):")
            out += [f"  {f}: {c} {m}" + (f" (x{n})" if n > 1 else "") for (f, c, m), n in self.new]
        if self.fixed:
            out.append(f"{tool.name}: {sum(n for _, n in self.fixed)} baselined finding(s) are fixed: remove them "
                       "with `python3 -m tests.house.baselines prune`:")
            out += [f"  {f}: {c} {m}" + (f" (x{n})" if n > 1 else "") for (f, c, m), n in self.fixed]
        if self.unexplained:
            out.append(f"{tool.name}: baseline entries without a reason:")
            out += [f"  {f}: {c} {m}" for f, c, m in self.unexplained]
        return "\n".join(out)

    @property
    def clean(self) -> bool:
        return not (self.new or self.fixed or self.unexplained)


def compare(tool: Tool, found: Counter[Key] | None = None) -> Comparison:
    found = tool.findings() if found is None else found
    allowed: Counter[Key] = Counter()
    unexplained = []
    for e in read_baseline(tool.baseline):
        allowed[e.key] += e.count
        if not e.reason.strip():
            unexplained.append(e.key)
    new = sorted((k, n - allowed[k]) for k, n in found.items() if n > allowed[k])
    fixed = sorted((k, n - found[k]) for k, n in allowed.items() if n > found[k])
    return Comparison(new, fixed, unexplained)


def prune(tool: Tool) -> int:
    """Lower each baseline count to what is found (dropping entries found no more); returns how many went."""
    found = tool.findings()
    entries = read_baseline(tool.baseline)
    kept, removed = [], 0
    for e in entries:
        now = min(e.count, found[e.key])
        removed += e.count - now
        if now:
            kept.append(Entry(e.file, e.code, e.message, now, e.reason))
    write_baseline(tool.baseline, header_of(tool.baseline), kept)
    return removed


def main(argv: list[str]) -> int:
    command = argv[0] if argv else "check"
    status = 0
    for tool in (RUFF, MYPY):
        if command == "prune":
            print(f"{tool.name}: {prune(tool)} fixed finding(s) removed from {tool.baseline.name}")
        else:
            comparison = compare(tool)
            print(comparison.report(tool) or f"{tool.name}: as the baseline says")
            status |= not comparison.clean
    return status


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
