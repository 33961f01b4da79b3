"""The result fields (synth.result.RESULT_FIELDS) drive both outputs; both still say what docs/formats.md says:
the `r2s synth --format json` keys in their order, the programs Parquet columns with their types."""

from __future__ import annotations

import json
import re

import pyarrow.parquet as pq

from pipeline.programs import failure_row, programs_table, result_row
from synth.config import SynthConfig
from synth.result import RESULT_FIELDS
from synth.scene import scene_from_dict
from synth.synthesize import synthesize
from tests.support import ROOT, run_r2s

FORMATS_MD = ROOT / "docs" / "formats.md"
SCENE = {"frame_id": "fig2", "entities": [
    {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
    {"id": "car1", "type": "Car", "x": 3, "y": 8, "heading": 0},
    {"id": "car2", "type": "Car", "x": 3, "y": 5, "heading": 0},
]}
ARROW_NAMES = {"float64": "double"}  # the docs name Parquet types as pyarrow's constructors do


def _section(heading: str) -> str:
    text = FORMATS_MD.read_text()
    return text.split(heading, 1)[1].split("\n## ", 1)[0]


def documented_json() -> tuple[list[str], list[str]]:
    """(top-level keys, stats keys) of the --format json document, in the documented order."""
    block = _section("## `r2s synth --format json`").split("```")[1]
    top, stats = block.split('"stats": {')
    return re.findall(r'"(\w+)"', top) + ["stats"], re.findall(r'"(\w+)"', stats)


def documented_columns() -> list[tuple[str, str]]:
    """(column, type) of the programs Parquet table, in the documented order."""
    out = []
    for line in _section("## Programs Parquet").splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        names = re.findall(r"`(\w+)`", cells[0]) if len(cells) >= 3 else []
        out += [(name, cells[1]) for name in names]
    return out


def test_the_json_document_has_the_documented_keys_in_order(tmp_path):
    path = tmp_path / "fig2.json"
    path.write_text(json.dumps(SCENE))
    proc = run_r2s("synth", str(path), "--format", "json")
    assert proc.returncode == 0, proc.stderr
    doc = json.loads(proc.stdout)
    top, stats = documented_json()
    assert (list(doc), list(doc["stats"])) == (top, stats)
    assert len(top) == 9 and len(stats) == 6


def test_programs_parquet_has_the_documented_columns_and_types_and_the_json_values(tmp_path):
    config = SynthConfig()
    result = synthesize(scene_from_dict(SCENE), config)
    rows = [result_row(result), failure_row("bad", "error", "why", 2, config)]
    pq.write_table(programs_table(rows), tmp_path / "p.parquet")
    table = pq.read_table(tmp_path / "p.parquet")
    documented = documented_columns()
    assert len(documented) == 21
    assert [(f.name, str(f.type)) for f in table.schema] == [(n, ARROW_NAMES.get(t, t)) for n, t in documented]
    written, failed = table.to_pylist()
    # each column reads back as the Python type the core declares for its field (pipeline gives its Arrow type)
    assert [type(written[f.name]) for f in RESULT_FIELDS if f.name not in ("error", "frame_hash")] == \
        [f.type for f in RESULT_FIELDS if f.name not in ("error", "frame_hash")]
    doc = result.to_json_dict()
    assert {k: written[k] for k in doc if k != "stats"} == {k: v for k, v in doc.items() if k != "stats"}
    assert {k: written[k] for k in doc["stats"]} == doc["stats"]
    assert (written["strategy"], written["oracle"], written["solver"]) == (config.strategy, config.oracle, config.solver)
    assert (written["error"], written["config_hash"], failed["config_hash"]) == (None, config.semantic_hash(),
                                                                                config.semantic_hash())
    assert failed["status"] == "error" and failed["error"] == "why" and failed["program"] is None
    assert failed["certified"] is False and failed["strategy"] == config.strategy and failed["smt_queries"] is None
