"""The rooms import one way (docs/layout.md): synth and storage at the bottom, each importing neither the other
nor anything above; extractors above them; pipeline on top. Inside each room no module imports itself back
through others (no circle), counting imports inside functions too: a circle hidden in a
function is still a circle, it only fails later. Imports under `if TYPE_CHECKING:` are for the type checker
and never run, so they are left out, except in synth, whose modules do not import each other in a circle even
for the type checker (the solver protocol knows no part, the parts build on it)."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

from tests.support import ROOT as REPO

ROOMS = ("synth", "storage", "extractors", "pipeline")
# room -> the rooms it may import (besides itself)
MAY_IMPORT = {"synth": set(), "storage": set(), "extractors": {"synth", "storage"},
              "pipeline": {"synth", "storage", "extractors"}}
NO_CIRCLES = ("synth", "storage", "extractors", "pipeline")


def _modules() -> dict[str, Path]:
    found = {}
    for room in ROOMS:
        for path in sorted((REPO / room).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            found[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return found


def _is_type_checking(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _imported(tree: ast.AST, module: str, is_package: bool, known: set[str], type_checking: bool = False) -> set[str]:
    """The modules of ours a module imports, anywhere in it but under `if TYPE_CHECKING:` (there too with
    type_checking)."""
    out: set[str] = set()

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _is_type_checking(node) and not type_checking:
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = module.split(".") if is_package else module.split(".")[:-1]
                anchor = anchor[: len(anchor) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            for alias in node.names:  # `from pkg import mod` imports the module pkg.mod
                out.add(f"{base}.{alias.name}" if f"{base}.{alias.name}" in known else base)
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(tree)
    return {m for m in out if m in known and m != module}


def import_graph(type_checking: bool = False) -> nx.DiGraph:
    modules = _modules()
    graph = nx.DiGraph()
    for name, path in modules.items():
        graph.add_node(name)
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for target in _imported(tree, name, path.name == "__init__.py", set(modules), type_checking):
            graph.add_edge(name, target)
    return graph


def room(module: str) -> str:
    return module.split(".")[0]


def test_the_graph_sees_the_imports_it_must():
    # the test's own reading of imports, checked on edges that exist: a module-level, a function-local and a
    # `from package import module` import
    graph = import_graph()
    assert graph.has_edge("extractors.frames", "extractors.frames_dataset")
    assert graph.has_edge("pipeline.cli.extract", "pipeline.batch.extract")
    assert graph.has_edge("extractors.mcap", "extractors.messages")
    assert graph.has_edge("pipeline.batch.store", "storage.atomic")


@pytest.mark.parametrize("low", ROOMS)
def test_rooms_import_one_way(low):
    wrong = sorted((a, b) for a, b in import_graph().edges
                   if room(a) == low and room(b) != low and room(b) not in MAY_IMPORT[low])
    assert not wrong, f"{low} may import only {sorted(MAY_IMPORT[low]) or 'nothing of ours'}: {wrong}"


@pytest.mark.parametrize("name,type_checking", [(name, False) for name in NO_CIRCLES] + [("synth", True)])
def test_no_import_circle_inside(name, type_checking):
    graph = import_graph(type_checking).subgraph(m for m in _modules() if room(m) == name)
    circles = [c for c in nx.strongly_connected_components(graph) if len(c) > 1]
    assert not circles, f"modules of {name} that import each other (in a circle): {[sorted(c) for c in circles]}"


def test_the_type_checkers_graph_has_its_imports_too():
    # synth.parts.base names synth.draws.Draws for the type checker only
    assert not import_graph().has_edge("synth.parts.base", "synth.draws")
    assert import_graph(type_checking=True).has_edge("synth.parts.base", "synth.draws")


def test_a_circle_is_found():
    # the check itself on a graph with a circle through a function-local import and one under TYPE_CHECKING
    known = {"a", "b"}
    local = ast.parse("def f():\n    import b\n")
    typing_only = ast.parse("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import a\n")
    assert _imported(local, "a", False, known) == {"b"}
    assert _imported(typing_only, "b", False, known) == set()
    assert _imported(typing_only, "b", False, known, type_checking=True) == {"a"}
    graph = nx.DiGraph([("a", "b"), ("b", "a")])
    assert [c for c in nx.strongly_connected_components(graph) if len(c) > 1] == [{"a", "b"}]
