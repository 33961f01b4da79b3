"""The verbs are thin and independent: a verb module imports no other verb (shared options live in
pipeline.cli.options, shared readers in pipeline.cli.inputs), and the verbs that synthesize read their shared
options into the same configuration."""

from __future__ import annotations

import ast

import pytest

from pipeline.cli import VERBS, build_parser
from pipeline.cli.options import synthesis_config
from tests.support import ROOT


@pytest.mark.parametrize("verb", sorted(VERBS))
def test_a_verb_imports_no_other_verb(verb):
    module = VERBS[verb][0]
    path = ROOT / (module.replace(".", "/") + ".py")
    imported = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            imported.add(node.module)
            imported.update(f"{node.module}.{a.name}" for a in node.names)
        elif isinstance(node, ast.Import):
            imported.update(a.name for a in node.names)
    others = [m for m in imported if m.startswith("pipeline.cli.")
              and not any(m == s or m.startswith(s + ".") for s in ("pipeline.cli.inputs", "pipeline.cli.options"))]
    assert not others, (verb, others)


@pytest.mark.parametrize("options", [
    [],
    ["--strategy", "dfs-bnb", "--oracle", "smt", "--time-limit", "2.5", "--memory-limit", "900"],
    ["--config", "paper", "--motion", "--uncertainty", "0.5,2,0.25"],
])
def test_synth_and_run_read_the_shared_options_alike(options):
    synth = build_parser("synth").parse_args(["scene.json", *options])
    run = build_parser("run").parse_args(["frames.parquet", "--out", "programs", *options])
    assert synthesis_config(synth) == synthesis_config(run)
