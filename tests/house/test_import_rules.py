"""The dependency rules of docs/architecture.md, checked on every import statement (module level and inside
functions) and every `importlib.import_module("...")` / `__import__("...")` with a literal name:

- `hamr_bench` imports none of `drivers`, `sim_devices`, `analysis` (backends are found by name through
  `hamr_bench.backends`, command modules through the entry-point group `hamr_bench.commands`);
- `analysis` never imports `drivers`;
- `sim_devices` never imports `drivers` (the emulators implement what the drivers expect; a driver test against an
  emulator is then a test of the real code path).
"""

from __future__ import annotations

import ast
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
FORBIDDEN: dict[str, frozenset[str]] = {
    "hamr_bench": frozenset({"drivers", "sim_devices", "analysis"}),
    "analysis": frozenset({"drivers"}),
    "sim_devices": frozenset({"drivers"}),
}


def imported_modules(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, module) of every import in `tree`, at any depth; relative imports are not used in this project."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            found.append((node.lineno, node.module))
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) \
                and isinstance(node.args[0].value, str) and _is_import_call(node.func):
            found.append((node.lineno, node.args[0].value))
    return found


def _is_import_call(func: ast.expr) -> bool:
    if isinstance(func, ast.Attribute):
        return func.attr == "import_module"
    return isinstance(func, ast.Name) and func.id in ("__import__", "import_module")


def violations() -> list[str]:
    found = []
    for package, forbidden in FORBIDDEN.items():
        for path in sorted((REPO / package).rglob("*.py")):
            rel = path.relative_to(REPO).as_posix()
            for line, module in imported_modules(ast.parse(path.read_text(encoding="utf-8"), rel)):
                if module.split(".")[0] in forbidden:
                    found.append(f"{rel}:{line}: {package} must not import {module}")
    return found


def test_dependencies_point_one_way():
    found = violations()
    assert not found, "\n".join(found)


def test_the_check_sees_function_level_and_by_name_imports():
    tree = ast.parse("def f():\n    from drivers import x\n    import importlib\n"
                     "    importlib.import_module('sim_devices.bench')\n")
    assert [m for _, m in imported_modules(tree)] == ["drivers", "importlib", "sim_devices.bench"]
