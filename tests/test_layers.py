"""The package's import graph against the layer table of docs/architecture.md (one-way data flow)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "aacmm_pin"
CORE_LAYERS = 5  # data, model, effects, fit and analyses (layers 1-5) stay free of these
OPTIONAL = ("matplotlib", "meshcat", "serial")


def _layer_table() -> dict[str, int]:
    """Return module (or ``pkg/`` prefix) -> layer from docs/architecture.md's layer table."""
    text = (ROOT / "docs" / "architecture.md").read_text()
    section = text[text.index("# Architecture"):]
    section = section[:section.index("\n## ", 1)]
    table: dict[str, int] = {}
    for layer, cell in re.findall(r"^\| (\d+) [a-z]+ \| (.+) \|$", section, flags=re.M):
        for name in re.findall(r"`([^`]+)`", cell):
            table[name] = int(layer)
    return table


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        out[".".join(parts)] = path
    return out


def _layer(module: str, table: dict[str, int]) -> int:
    if module in table:
        return table[module]
    package = module.split(".")[0] + "/"
    if package in table:
        return table[package]
    raise AssertionError(f"aacmm_pin.{module} is in no layer of docs/architecture.md's table")


def _type_checking_nodes(tree: ast.AST) -> set[int]:
    """Return ids of import nodes under ``if TYPE_CHECKING:`` (types only, not run)."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return out


def _imports(path: Path, module: str, types: bool = True) -> list[str]:
    """Return the modules (package-relative, or third-party top names) ``path`` imports.

    ``types``: also the imports under ``if TYPE_CHECKING:`` (a type names a dependency too: a
    module that needs another's types to be read sits above it).
    """
    tree = ast.parse(path.read_text())
    skip = set() if types else _type_checking_nodes(tree)
    package = module.rsplit(".", 1)[0] if "." in module or path.name == "__init__.py" else ""
    if path.name == "__init__.py":
        package = module.removesuffix(".__init__") if module != "__init__" else ""
    out = []
    for node in ast.walk(tree):
        if id(node) in skip:
            continue
        if isinstance(node, ast.ImportFrom):
            if node.level:  # relative import: resolved against the module's package
                parts = package.split(".") if package else []
                base = parts[:len(parts) - node.level + 1]
                name = ".".join(["aacmm_pin", *base, node.module or ""]).strip(".")
            else:
                name = node.module or ""
            if name == "aacmm_pin":
                out += [f"aacmm_pin.{a.name}" for a in node.names]
            else:
                out.append(name)
        elif isinstance(node, ast.Import):
            out += [a.name for a in node.names]
    return out


def _internal(name: str, modules: dict[str, Path]) -> str | None:
    if not name.startswith("aacmm_pin"):
        return None
    rest = name.removeprefix("aacmm_pin").lstrip(".")
    while rest and rest not in modules and f"{rest}.__init__" not in modules:
        rest = rest.rpartition(".")[0]
    if not rest:
        return "__init__"
    return rest if rest in modules else f"{rest}.__init__"


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        targets = {_internal(n, modules) for n in _imports(path, module)}
        graph[module] = {t for t in targets if t is not None and t != module}
    return graph


def test_every_module_is_in_a_layer() -> None:
    """Every module of the package is named (or its subpackage is) in docs/architecture.md's table."""
    table = _layer_table()
    assert table, "docs/architecture.md has no layer table"
    for module in _modules():
        _layer(module.removesuffix(".__init__") if module.endswith(".__init__") else module, table)


def test_no_module_imports_a_higher_layer() -> None:
    """Every import, function-level and type-only ones included, goes to the same or a lower layer."""
    table = _layer_table()

    def layer(m: str) -> int:
        return _layer(m.removesuffix(".__init__") if m.endswith(".__init__") else m, table)

    wrong = [f"aacmm_pin.{a} (layer {layer(a)}) imports aacmm_pin.{b} (layer {layer(b)})"
             for a, targets in _graph().items() for b in sorted(targets) if layer(b) > layer(a)]
    assert not wrong, "\n".join(wrong)


def test_import_graph_has_no_cycle() -> None:
    """No chain of imports (type-only ones included) leads from a module back to itself."""
    graph = _graph()
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        stack.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                pytest.fail("import cycle: " + " -> ".join(stack[stack.index(n):] + [n]))
            if n not in state:
                visit(n)
        stack.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_core_layers_import_no_optional_dependency() -> None:
    """Model, solver and analyses import neither matplotlib, meshcat nor pyserial."""
    table = _layer_table()
    modules = _modules()
    wrong = []
    for module, path in modules.items():
        name = module.removesuffix(".__init__") if module.endswith(".__init__") else module
        if _layer(name, table) > CORE_LAYERS:
            continue
        wrong += [f"aacmm_pin.{module} imports {n}" for n in _imports(path, module, types=False)
                  if n.split(".")[0] in OPTIONAL]
    assert not wrong, "\n".join(wrong)


def test_the_checker_sees_a_violation(tmp_path: Path) -> None:
    """The import reader finds function-level imports, and TYPE_CHECKING ones when asked."""
    path = tmp_path / "probe.py"
    path.write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import aacmm_pin.cli\n"
                    "def f():\n    from aacmm_pin.outputs.viewer import view\n")
    found = _imports(path, "probe", types=False)
    assert "aacmm_pin.outputs.viewer" in found and "aacmm_pin.cli" not in found
    assert "aacmm_pin.cli" in _imports(path, "probe")
    inner = tmp_path / "inner.py"
    inner.write_text("from ..outputs import viewer\nfrom .base import Term\n")
    assert _imports(inner, "effects.inner") == ["aacmm_pin.outputs", "aacmm_pin.effects.base"]
