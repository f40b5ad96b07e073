"""The layout the project keeps (docs/architecture.md): no module over 500 lines, no function
over 80, no import cycle, and the pipeline (``compensation/``, ``cli/``) importing no
language folder of ``programs/`` (it asks the registry, ``programs/languages.py``)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "olp_compensate"
MODULES = sorted(PACKAGE.rglob("*.py"))
LANGUAGES = sorted(p.parent.name for p in PACKAGE.glob("programs/*/language.py"))


def _name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _package_of(path: Path) -> list[str]:
    parts = _name(path).split(".")
    return parts if path.name == "__init__.py" else parts[:-1]


def _imports(path: Path) -> set[str]:
    """The modules of the package ``path`` imports, anywhere in it (lazy imports too), but
    not under ``if TYPE_CHECKING:``."""
    tree = ast.parse(path.read_text())
    typing_only = {id(node) for block in ast.walk(tree) if isinstance(block, ast.If)
                   and "TYPE_CHECKING" in ast.unparse(block.test)
                   for stmt in block.body for node in ast.walk(stmt)}
    known = {_name(p) for p in MODULES}
    found = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.ImportFrom):
            package = _package_of(path)
            base = (".".join(package[:len(package) - node.level + 1]
                             + ([node.module] if node.module else []))
                    if node.level else (node.module or ""))
            for alias in node.names:
                full = f"{base}.{alias.name}"
                found.add(full if full in known else base)
        elif isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
    return {m for m in found if m in known} - {_name(path)}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return out


def test_no_module_over_500_lines():
    long = {_name(p): n for p in MODULES if (n := len(p.read_text().splitlines())) > 500}
    assert not long, long


def test_no_function_over_80_lines():
    long = [f"{_name(p)}.{node.name}: {node.end_lineno - node.lineno + 1}"
            for p in MODULES for node in ast.walk(ast.parse(p.read_text()))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > 80]
    assert not long, long


def test_no_import_cycle():
    graph = {_name(p): _imports(p) for p in MODULES}
    assert not _cycles(graph)


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.parametrize("folder", ["compensation", "cli"])
def test_the_pipeline_imports_no_language(folder):
    assert LANGUAGES == ["fanuc", "krl", "rapid", "urscript", "val3", "vplus"]
    named = {f"olp_compensate.programs.{lang}" for lang in LANGUAGES}
    found = {(_name(p), m) for p in sorted((PACKAGE / folder).rglob("*.py"))
             for m in _imports(p) if any(m == n or m.startswith(n + ".") for n in named)}
    assert not found, found
