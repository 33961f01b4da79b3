"""The rooms import one way (docs/layout.md): synth and storage at the bottom, each importing neither the other
nor anything above; frames (the frames format) above them; extractors above frames; pipeline on top. Inside
synth the sub-rooms are in order too: the road below the scene (a scene holds a road, a road knows no scene), the
scene's values below the statement parts, the parts below what builds on them (variants, Scenic text, patterns,
search, windows). No module imports itself back through others (no circle) in any room, counting imports inside
functions too (a circle hidden in a function is still a circle, it only fails later) and imports under
`if TYPE_CHECKING:` (they never run, but a circle the type checker sees is a circle of meaning all the same)."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx
import pytest

from tests.support import ROOT as REPO

ROOMS = ("synth", "storage", "frames", "extractors", "pipeline")
# room -> the rooms it may import (besides itself)
MAY_IMPORT = {"synth": set(), "storage": set(), "frames": {"synth", "storage"},
              "extractors": {"synth", "storage", "frames"}, "pipeline": {"synth", "storage", "frames", "extractors"}}

# synth's sub-rooms (its sub-packages; "core" is the modules in synth/ itself) -> the sub-rooms each may import
# besides itself and the core: the road at the bottom, the parts on the road and the solvers' protocol, and above
# them what builds on the parts. smt reads the parts to certify a program (smt.certify), while its protocol
# (smt.backend) knows no part; the core's driver (synthesize) runs a search, certifies and emits Scenic text.
SYNTH_MAY_IMPORT = {
    "road": set(),
    "parts": {"road", "smt"},
    "smt": {"parts"},
    "search": {"smt"},
    "variants": {"road"},
    "scenic": {"road", "parts", "variants"},
    "patterns": {"parts"},
    "window": {"road", "parts", "smt", "search", "scenic"},
    "behaviour": {"road", "patterns", "window"},  # behaviour programs over a clip (issue 38), in the making
    "core": {"road", "parts", "smt", "search", "scenic"},
}
# The road imports of the core only these (a road knows no scene); the core's values (the scene and what describes
# it, below the parts) import no sub-room but the road.
ROAD_MAY_IMPORT = {"synth.errors", "synth.geometry", "synth.pose"}
CORE_VALUES = {"synth.scene", "synth.world", "synth.geometry", "synth.pose", "synth.errors", "synth.config", "synth.syntax",
               "synth.tables", "synth.perturbation", "synth.intervals", "synth.ranges", "synth.draws", "synth.version"}


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


def synth_room(module: str) -> str:
    """The sub-room of a module of synth: its sub-package, or "core" for the modules in synth/ itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 2 or (len(parts) == 2 and (REPO / "synth" / parts[1]).is_dir()) else "core"


def test_the_graph_sees_the_imports_it_must():
    # the test's own reading of imports, checked on edges that exist: a module-level, a function-local and a
    # `from package import module` import
    graph = import_graph()
    assert graph.has_edge("frames.rows", "frames.dataset")
    assert graph.has_edge("pipeline.cli.extract", "pipeline.batch.extract")
    assert graph.has_edge("extractors.mcap", "extractors.messages")
    assert graph.has_edge("pipeline.batch.store", "storage.atomic")


@pytest.mark.parametrize("low", ROOMS)
def test_rooms_import_one_way(low):
    wrong = sorted((a, b) for a, b in import_graph(type_checking=True).edges
                   if room(a) == low and room(b) != low and room(b) not in MAY_IMPORT[low])
    assert not wrong, f"{low} may import only {sorted(MAY_IMPORT[low]) or 'nothing of ours'}: {wrong}"


def test_every_room_of_synth_has_its_place_in_the_order():
    found = {synth_room(m) for m in _modules() if room(m) == "synth"}
    assert found <= set(SYNTH_MAY_IMPORT), f"a new sub-room of synth: say in SYNTH_MAY_IMPORT what it may import: " \
                                           f"{sorted(found - set(SYNTH_MAY_IMPORT))}"


@pytest.mark.parametrize("low", sorted(SYNTH_MAY_IMPORT))
def test_synths_rooms_import_in_order(low):
    # what runs: a type-only import of a room above (a part's requirement names the sampler's SceneRoad) is a
    # name for the type checker, not a dependency; its circles are checked below all the same
    allowed = SYNTH_MAY_IMPORT[low]
    wrong = sorted((a, b) for a, b in import_graph().edges
                   if room(a) == room(b) == "synth" and synth_room(a) == low and synth_room(b) != low
                   and synth_room(b) != "core" and synth_room(b) not in allowed)
    assert not wrong, f"synth/{low} may import only {sorted(allowed) or 'the core'} of synth's rooms: {wrong}"


def test_the_road_is_below_the_scene():
    graph = import_graph()
    wrong = sorted((a, b) for a, b in graph.edges if synth_room(a) == "road" and room(b) == "synth"
                   and synth_room(b) == "core" and b not in ROAD_MAY_IMPORT)
    assert not wrong, f"synth/road may import of synth's core only {sorted(ROAD_MAY_IMPORT)}: {wrong}"
    above = sorted((a, b) for a, b in graph.edges if a in CORE_VALUES and room(b) == "synth"
                   and synth_room(b) not in ("core", "road"))
    assert not above, f"the scene's values import no room of synth but the road: {above}"
    core = sorted((a, b) for a, b in graph.edges if a in CORE_VALUES and room(b) == "synth"
                  and synth_room(b) == "core" and b not in CORE_VALUES)
    assert not core, f"the scene's values import none of the core's other modules: {core}"


@pytest.mark.parametrize("name,type_checking", [(name, tc) for name in ROOMS for tc in (False, True)])
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


def test_the_sub_rooms_are_read_from_the_tree():
    # the sub-room of a module, as the order checks read it: a sub-package's modules and the package itself
    assert [synth_room(m) for m in ("synth.road.roadmap", "synth.parts", "synth.scene", "synth", "synth.smt.certify")] \
        == ["road", "parts", "core", "core", "smt"]
    assert import_graph().has_edge("synth.scene", "synth.road.roadmap")  # a scene holds a road: core -> road
