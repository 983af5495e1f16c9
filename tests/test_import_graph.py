"""No import cycles inside the boucwen package.

The graph is read from the source with ``ast``: one node per module of
``python/boucwen`` (``.py`` files, plus the compiled core by its ``.pyi`` stub), one
edge per ``import`` / ``from … import`` of another boucwen module anywhere in a file
(inside functions too: a deferred import hides a cycle, it does not remove it), but
not an import under ``if TYPE_CHECKING:``, which never runs.
``from package import name`` points at the submodule ``package.name`` when there is
one, else at the package. The implicit import of a parent package when a submodule
is loaded is not an edge (every package would be a cycle with its own modules).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE_ROOT = Path(__file__).resolve().parent.parent / "python" / "boucwen"


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _modules(root: Path) -> dict[str, Path]:
    """Module name → file, for every .py (and .pyi without a .py) under ``root``."""
    found = {_module_name(p, root): p for p in root.rglob("*.py")}
    for stub in root.rglob("*.pyi"):
        found.setdefault(_module_name(stub, root), stub)
    return found


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The boucwen modules that module ``name`` imports."""
    is_package = path.name == "__init__.py"
    package = name if is_package else name.rpartition(".")[0]
    out: set[str] = set()
    tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
    type_only = {
        id(inner)
        for node in ast.walk(tree)
        if isinstance(node, ast.If) and ast.unparse(node.test) in ("TYPE_CHECKING", "typing.TYPE_CHECKING")
        for stmt in node.body
        for inner in ast.walk(stmt)
    }
    for node in ast.walk(tree):
        if id(node) in type_only:
            continue
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names if alias.name in modules)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base_parts = package.split(".")
                base_parts = base_parts[: len(base_parts) - (node.level - 1)]
                base = ".".join(base_parts + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            for alias in node.names:
                sub = f"{base}.{alias.name}"
                if sub in modules:
                    out.add(sub)
                elif base in modules:
                    out.add(base)
    out.discard(name)
    return out


def import_graph(root: Path = PACKAGE_ROOT) -> dict[str, set[str]]:
    """Module → the boucwen modules it imports."""
    modules = _modules(root)
    return {name: _imports(name, path, modules) for name, path in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle as [a, b, …, a], or None if the graph is acyclic (depth-first search)."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return [*path[path.index(nxt) :], nxt]
            if nxt not in state:
                cycle = visit(nxt)
                if cycle is not None:
                    return cycle
        path.pop()
        state[node] = 2
        return None

    for start in sorted(graph):
        if start not in state:
            cycle = visit(start)
            if cycle is not None:
                return cycle
    return None


def test_the_graph_sees_the_imports_it_should():
    # Guards the reader: an empty or partial graph would make the next test pass
    # for the wrong reason.
    graph = import_graph()
    assert "boucwen.diagnosis.search" in graph["boucwen.diagnosis"]  # from .search import …
    assert "boucwen.fit" in graph["boucwen.diagnosis"]  # from ..fit import …
    assert "boucwen.diagnosis.fits" in graph["boucwen.diagnosis.search"]  # from .fits import …
    assert "boucwen._core" in graph["boucwen.plant"]  # the compiled core, by its stub
    assert "boucwen.plant" in graph["boucwen.experiments.reproduce"]  # from .. import plant
    assert "boucwen.experiments.reproduce" in graph["boucwen.cli"]  # imported inside a function


@pytest.mark.parametrize(
    "graph, acyclic",
    [
        ({"a": {"b"}, "b": {"c"}, "c": set()}, True),
        ({"a": {"b", "c"}, "b": {"c"}, "c": set()}, True),
        ({"a": {"b"}, "b": {"a"}}, False),
        ({"a": {"b"}, "b": {"c"}, "c": {"a"}}, False),
    ],
)
def test_find_cycle_on_small_graphs(graph, acyclic):
    cycle = find_cycle(graph)
    assert (cycle is None) == acyclic
    if cycle is not None:
        assert cycle[0] == cycle[-1]
        assert all(b in graph[a] for a, b in zip(cycle, cycle[1:]))


def test_no_import_cycles_inside_boucwen():
    cycle = find_cycle(import_graph())
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_the_effects_do_not_reach_the_diagnosis():
    # The diagnosis builds on the effects, never the other way round.
    graph = import_graph()
    effects = {name for name in graph if name == "boucwen.effects" or name.startswith("boucwen.effects.")}
    assert "boucwen.effects.fit" in effects
    reached, todo = set(), list(effects)
    while todo:
        for nxt in graph[todo.pop()] - reached:
            reached.add(nxt)
            todo.append(nxt)
    assert not {name for name in reached if name.startswith("boucwen.diagnosis")}
