"""`r2s report` on programs with lane clauses (issue 24 item 8): the relation counts include every lane kind,
counted from the text as the DSL's parser counts them, position's left / right not inflated by `in lane left of`;
and the share of entities in a lane, in no lane and either."""

from __future__ import annotations

import random
from collections import Counter

from pipeline.programs import programs_table, result_row
from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.parts import LANE
from synth.synthesize import synthesize
from tests.support import run_r2s
from tests.support.lanes import random_lane_scene


def _relations(md: str) -> dict[str, str]:
    """The Relation usage table's Total column, by relation."""
    section = md.split("## Relation usage\n", 1)[1].split("\n## ", 1)[0]
    cells = [[c.strip() for c in ln.strip("|").split("|")] for ln in section.splitlines() if ln.startswith("| ")]
    return {row[0]: row[-1] for row in cells[1:]}


def test_lane_kinds_and_the_share_on_lanes_are_counted_as_the_parser_counts_them(tmp_path):
    import pyarrow.parquet as pq

    rows = [result_row(synthesize(random_lane_scene(random.Random(300 + k), 8), SynthConfig(lanes=True)))
            for k in range(12)]
    pq.write_table(programs_table(rows), tmp_path / "programs.parquet")
    out = tmp_path / "report"
    proc = run_r2s("report", str(tmp_path / "programs.parquet"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    md = (out / "report.md").read_text()
    table = _relations(md)
    parsed = Counter(clause.kind for r in rows for st in parse_program(r["program"]).statements
                     for _, clause in st.clauses())
    for kind in ("ahead", "behind", "left", "right", "toward", "away", *LANE.kinds):
        assert int(table[kind]) == parsed[kind], kind
    assert parsed["lane left"] + parsed["lane right"] > 0 and parsed["same lane"] > 0  # the test can fail
    # the share of entities on / off lanes, from the same counts
    total = sum(parsed[k] for k in LANE.kinds)
    on = sum(parsed[k] for k in ("same lane", "lane left", "lane right", "oncoming lane", "lane by id"))
    off = parsed["off lane"] + parsed["off road"]
    shares = md.split("Where the entities are", 1)[1]
    line = next(ln for ln in shares.splitlines() if ln.startswith("| auto"))
    assert [c.strip() for c in line.strip("|").split("|")][1:] == [
        f"{100 * on / total:.1f}%", f"{100 * off / total:.1f}%", f"{100 * (total - on - off) / total:.1f}%"]


def test_reports_without_lanes_have_no_lane_rows(tmp_path):
    import pyarrow.parquet as pq

    rows = [result_row(synthesize(random_lane_scene(random.Random(k), 5), SynthConfig())) for k in range(3)]
    pq.write_table(programs_table(rows), tmp_path / "programs.parquet")
    out = tmp_path / "report"
    assert run_r2s("report", str(tmp_path / "programs.parquet"), "--out", str(out)).returncode == 0
    md = (out / "report.md").read_text()
    assert "same lane" not in _relations(md) and "ahead" in _relations(md) and "Where the entities are" not in md
