"""Imports are at the top of a module (docs/layout.md), but at the documented lazy boundaries: the verb table (a
verb's module loads when it runs, and its `run` imports its stage), `import synth` staying light, and optional or
heavy libraries imported where they are used. Every import inside a function of the code (synth, storage, frames,
extractors, pipeline) is either of a library in HEAVY or an entry of LAZY, each with its reason; an entry whose
import is gone fails too, so the list stays true. A local import of what the module's top already imports is
never needed."""

from __future__ import annotations

import ast
from collections.abc import Iterator
from dataclasses import dataclass

from tests.support import ROOT as REPO

ROOMS = ("synth", "storage", "frames", "extractors", "pipeline")

# Optional or heavy libraries (a package or module, and what is in it -> why): imported in the function that uses
# them, anywhere, so that a module that `r2s --help`, `r2s VERB --help`, `import synth` or another verb loads does not pay for them.
HEAVY = {
    "matplotlib": "heavy (~0.3 s): only drawing a plot or picture pays for it",
    "scipy": "heavy: only matching detections pays for it",
    "shapely": "~11 ms on top of numpy: the road modules load for `r2s extract --help`, which draws no polygon",
    "pandas": "heavy (~0.2 s): light modules read by `r2s VERB --help` import it where rows are read",
    "pyarrow.parquet": "its Parquet reader and writer: storage.atomic, which --help loads, writes no Parquet",
    "pyarrow.dataset": "its datasets (~40 ms): loaded where a dataset is read",
    "scenic": "optional and heavy: Scenic loads only to compile or sample a program",
    "z3": "heavy: the solver loads when a formula is first decided",
    "nuscenes": "optional: nuscenes-devkit loads when a nuScenes dataset is read",
    "mcap": "optional: mcap loads when an MCAP log is read",
    "mcap_protobuf": "optional: decoders of MCAP messages, loaded when an MCAP log is read",
    "mcap_ros2": "optional: decoders of MCAP messages, loaded when an MCAP log is read",
    "rosbags": "optional: rosbags loads when a ROS bag is read",
    "zstandard": "optional: a compression of MCAP chunks, loaded when a chunk uses it",
    "lz4": "optional: a compression of MCAP chunks and ROS bags, loaded when one uses it",
    "distributed": "heavy (dask): only --backend dask pays for it",
    "joblib": "the loky pool: only a run with workers pays for it",
    "fsspec": "heavy: remote filesystems, only a path with a protocol pays for it",
    "scenariogeneration": "optional and heavy: OpenSCENARIO / OpenDRIVE export only",
}

VERB = "the verb table: a verb's module is light for `r2s VERB --help`; its `run` imports its stage"
SYNTH_LIGHT = "`import synth` stays light: the DSL, the oracles, the search and the road load on first use"
HELP = "`r2s --help` does not load it"
QUERY = "only r2s report --query loads the miner, the pattern parser and the frames reader (~0.1 s)"
EXPORT_TARGET = "a target's writer loads when it is chosen: --to scenarionet loads no XML nor road network"
WINDOW = "only `r2s run --window` loads the window synthesis (the DSL, the driver: ~70 ms of a run's start-up)"

# (module, imported module) -> why it is imported inside a function.
LAZY: dict[tuple[str, str], str] = {
    # synth: `import synth` loads the scene and the configuration only (synth/__init__.py)
    ("synth.synthesize", "synth.driver"): SYNTH_LIGHT,
    ("synth.scene", "synth.road.lane_relations"): SYNTH_LIGHT + " (numpy): only a scene with a road loads it",
    ("synth.scene", "synth.road.roadmap"): SYNTH_LIGHT + " (numpy): only a scene with a road loads it",
    ("synth.scene", "synth.world"): SYNTH_LIGHT + " (numpy, through synth.pose): only a scene with a world loads it",
    ("synth.scene", "synth.geometry"): SYNTH_LIGHT + " (fractions, decimal)",
    ("synth.scene", "difflib"): SYNTH_LIGHT + ": only a misspelt key loads it",
    ("synth.config", "difflib"): SYNTH_LIGHT + ": only a misspelt key loads it",
    ("synth.config", "hashlib"): SYNTH_LIGHT + " (OpenSSL): only a configuration's hash loads it",
    # pipeline.batch
    ("pipeline.batch.options", "pipeline.batch.windows"): "options.py stays light for --help (docs/layout.md); the "
                                                          "window planner loads numpy, pyarrow and the window synthesis",
    ("pipeline.batch.stage", "synth.window.program"): WINDOW,
    ("pipeline.batch.stage", "pipeline.batch.windows"): WINDOW,
    ("pipeline.batch.stage", "pipeline.batch.window_task"): WINDOW,
    ("pipeline.batch.options", "pipeline.batch.clips"): "options.py stays light for --help (docs/layout.md); the "
                                                        "clip planner loads numpy, pyarrow and the behaviour synthesis",
    ("pipeline.batch.stage", "pipeline.batch.clips"): "only `r2s run --clip` loads the behaviour synthesis",
    # pipeline.cli: each verb's module is light for `r2s VERB --help`; its run imports what it runs
    ('pipeline.cli.check', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.check', 'synth.behaviour.program'): VERB,
    ('pipeline.cli.check', 'synth.dsl'): VERB,
    ('pipeline.cli.check', 'synth.semantics'): VERB,
    ('pipeline.cli.check', 'synth.syntax'): VERB,
    ('pipeline.cli.check', 'synth.behaviour.check'): VERB,
    ('pipeline.cli.eval_frontend', 'frames.rows'): VERB,
    ('pipeline.cli.eval_frontend', 'pipeline.evaluation.frontend'): VERB,
    ('pipeline.cli.eval_frontend', 'pipeline.evaluation.plot'): VERB,
    ('pipeline.cli.eval_frontend', 'pipeline.outputs'): VERB,
    ('pipeline.cli.eval_frontend', 'storage.atomic'): VERB,
    ('pipeline.cli.export', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.export', 'pipeline.export.stage'): VERB,
    ('pipeline.cli.export', 'pipeline.export.opendrive'): VERB,
    ('pipeline.cli.export', 'pipeline.export.behaviour_motion'): VERB,
    ('pipeline.cli.export', 'pipeline.export.clip'): VERB,
    ('pipeline.cli.extract', 'pipeline.batch.extract'): VERB,
    ('pipeline.cli.query', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.query', 'pipeline.query.mining'): VERB,
    ('pipeline.cli.query', 'pipeline.query.stop'): VERB,
    ('pipeline.cli.render', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.render', 'pipeline.variants.picture'): VERB,
    ('pipeline.cli.render', 'pipeline.variants.clip_picture'): VERB,
    ('pipeline.cli.report', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.report', 'pipeline.report.output'): VERB,
    ('pipeline.cli.run', 'pipeline.batch.stage'): VERB,
    ('pipeline.cli.sample', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.sample', 'pipeline.variants.sample'): VERB,
    ('pipeline.cli.scene', 'pipeline.scenes'): VERB,
    ('pipeline.cli.simulate', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.simulate', 'pipeline.simulation'): VERB,
    ('pipeline.cli.simulate', 'pipeline.batch.simulations'): VERB,
    ('pipeline.cli.synth', 'pipeline.cli.inputs'): VERB,
    ('pipeline.cli.synth', 'synth.behaviour.synthesize'): VERB,
    ('pipeline.cli.synth', 'synth.window.program'): VERB,
    ('pipeline.cli.synth', 'synth.behaviour.scenic'): VERB,
    ("pipeline.cli", "textwrap"): HELP + " (only a verb's help text is wrapped)",
    ("pipeline.cli.options", "pipeline.cli.inputs"): "options.py is loaded for `r2s VERB --help`; the config "
                                                      "reader (the DSL) loads when a verb runs",
    ("pipeline.cli.options", "pipeline.variants.sample"): "options.py is loaded for `r2s VERB --help`; the "
                                                           "sampler loads when a verb samples",
    ("pipeline.cli.inputs", "synth.dsl"): "r2s export reads scene JSON only: the DSL (python-flint) loads for a "
                                           "program or a pattern",
    ("pipeline.cli.inputs", "synth.patterns.temporal"): "only r2s query and r2s report read a pattern; the "
                                                         "other verbs that read their inputs here do not pay for it",
    ("pipeline.cli.inputs", "importlib.resources"): "only a preset's name loads it (r2s check does not)",
    ("pipeline.cli.inputs", "difflib"): "only a misspelt preset loads it",
    # the Python API of a room loads on first use, as pipeline/__init__.py's: r2s render reads
    # pipeline.query.matches without DuckDB, the report's modules load without the report
    ("pipeline.query", "pipeline.query.mining"): "pipeline.query.query loads the miner (DuckDB) on first use",
    ("pipeline.report", "pipeline.report.output"): "pipeline.report.report loads the report on first use",
    # stages that read Parquet only for one option: r2s sample and r2s render of a scene JSON load no pyarrow, pandas
    ("pipeline.variants.sample", "pipeline.programs"): "only `programs=` (--programs) reads a programs dataset",
    ("pipeline.variants.picture", "pipeline.programs"): "only `programs=` (--programs) reads a programs dataset",
    ("pipeline.variants.picture", "pipeline.query.matches"): "only `matches=` (--matches) reads a matches file",
    ("pipeline.export.opendrive", "frames.maps"): "only a maps dataset is Parquet: r2s export of a scene JSON "
                                                  "loads no pyarrow",
    ("pipeline.report.output", "frames.dataset"): QUERY,
    ("pipeline.report.output", "pipeline.report.query_section"): QUERY,
    ("pipeline.report.output", "synth.patterns.temporal"): QUERY,
    ("pipeline.report.data", "frames.dataset"): "only r2s report --frames reads the frames",
    ("pipeline.report.window_section", "frames.dataset"): "only r2s report --frames reads the frames",
    ("pipeline.export.stage", "pipeline.export.scenarionet"): EXPORT_TARGET,
    ("pipeline.export.stage", "pipeline.export.openscenario"): EXPORT_TARGET,
    ("pipeline.scenes", "difflib"): "only a frame that is not there loads it (the hint of its nearest names)",
}


@dataclass(frozen=True)
class LocalImport:
    """One import statement inside a function: where, and the module it imports."""

    module: str
    path: str
    line: int
    function: str
    imported: str
    text: str


def _absolute(module: str, is_package: bool, node: ast.ImportFrom) -> str:
    if not node.level:
        return node.module or ""
    package = module.split(".") if is_package else module.split(".")[:-1]
    base = package[:len(package) - node.level + 1]
    return ".".join([*base, *([node.module] if node.module else [])])


def _imported(module: str, is_package: bool, node: ast.Import | ast.ImportFrom) -> list[str]:
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    return [_absolute(module, is_package, node)]


def _is_type_checking(node: ast.AST) -> bool:
    test = node.test if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def local_imports(module: str, path: str, source: str) -> tuple[list[LocalImport], set[str]]:
    """The function-local imports of a module's source, and the modules its top imports when it runs (under an `if`
    or `try` at module level too, but not under `if TYPE_CHECKING:`, which never runs)."""
    tree = ast.parse(source)
    is_package = path.endswith("__init__.py")
    local: list[LocalImport] = []
    top: set[str] = set()

    def visit(node: ast.AST, function: str | None, runs: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                for name in _imported(module, is_package, child):
                    if function is not None:
                        local.append(LocalImport(module, path, child.lineno, function, name, ast.unparse(child)))
                    elif runs:
                        top.add(name)
            inner = child.name if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)) else None
            visit(child, function or inner, runs and not _is_type_checking(child))

    visit(tree, None, True)
    return local, top


def _sources() -> Iterator[tuple[str, str, str]]:
    for room in ROOMS:
        for path in sorted((REPO / room).rglob("*.py")):
            parts = path.relative_to(REPO).with_suffix("").parts
            module = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            yield module, str(path.relative_to(REPO)), path.read_text()


def problems(sources: list[tuple[str, str, str]], lazy: dict[tuple[str, str], str],
             heavy: dict[str, str]) -> list[str]:
    """What breaks the rule in these (module, path, source): stray local imports, then stale allow-list entries."""
    found: list[str] = []
    used_lazy: set[tuple[str, str]] = set()
    used_heavy: set[str] = set()
    for module, path, source in sources:
        local, top = local_imports(module, path, source)
        for imp in local:
            where = f"{imp.path}:{imp.line}: `{imp.text}` inside {imp.function}()"
            if imp.imported in top:
                found.append(f"{where}: the module's top already imports {imp.imported}; delete this one")
                continue
            library = next((name for name in heavy if imp.imported == name or imp.imported.startswith(name + ".")),
                           None)
            if library is not None:
                used_heavy.add(library)
            elif (imp.module, imp.imported) in lazy:
                used_lazy.add((imp.module, imp.imported))
            else:
                found.append(f"{where}: move it to the top of the module (docs/layout.md); if it is a documented "
                             f"lazy boundary, add ({imp.module!r}, {imp.imported!r}): <why> to LAZY in "
                             "tests/test_imports.py")
    for key in sorted(set(lazy) - used_lazy):
        found.append(f"LAZY entry {key} in tests/test_imports.py: no such import inside a function any more; "
                     "delete the entry")
    for library in sorted(set(heavy) - used_heavy):
        found.append(f"HEAVY entry {library!r} in tests/test_imports.py: no function imports it any more; delete "
                     "the entry")
    return found


def test_imports_are_at_the_top_but_the_documented_lazy_ones():
    found = problems(list(_sources()), LAZY, HEAVY)
    assert not found, "\n".join(found)


def test_a_stray_import_a_repeated_import_and_a_stale_entry_fail():
    source = ("import json\n\nfrom synth.scene import Scene\n\n\ndef f():\n    from synth.dsl import parse_program\n"
              "    import shapely\n    from . import helpers\n    import json\n    return Scene\n\n\n"
              "class C:\n    def g(self):\n        from synth.geometry import normalize\n")
    sources = [("pipeline.toy", "pipeline/toy.py", source)]
    lazy = {("pipeline.toy", "synth.geometry"): "why", ("pipeline.toy", "synth.gone"): "why"}
    found = problems(sources, lazy, {"shapely": "heavy", "z3": "heavy"})
    assert found == [
        "pipeline/toy.py:7: `from synth.dsl import parse_program` inside f(): move it to the top of the module "
        "(docs/layout.md); if it is a documented lazy boundary, add ('pipeline.toy', 'synth.dsl'): <why> to LAZY in "
        "tests/test_imports.py",
        "pipeline/toy.py:9: `from . import helpers` inside f(): move it to the top of the module (docs/layout.md); "
        "if it is a documented lazy boundary, add ('pipeline.toy', 'pipeline'): <why> to LAZY in "
        "tests/test_imports.py",
        "pipeline/toy.py:10: `import json` inside f(): the module's top already imports json; delete this one",
        "LAZY entry ('pipeline.toy', 'synth.gone') in tests/test_imports.py: no such import inside a function any "
        "more; delete the entry",
        "HEAVY entry 'z3' in tests/test_imports.py: no function imports it any more; delete the entry",
    ]


def test_the_real_tree_has_function_local_imports_to_check():
    # the walk sees into methods and nested functions: the tree's lazy boundaries are found where they are
    local = [imp for module, path, source in _sources() for imp in local_imports(module, path, source)[0]]
    assert {imp.imported.split(".")[0] for imp in local} >= {"matplotlib", "scenic", "z3"}
