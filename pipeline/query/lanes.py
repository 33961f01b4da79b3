"""Lane clauses in queries (docs/dsl.md, "Patterns"): exact SQL over the frames' lane columns and a table of the
lanes each lane relates to, computed once per map from the maps beside the frames.

A query's frame is a scene whose road is its whole map (not the crop `r2s scene` writes): the LANE clauses read
each entity's lane facts (the frames' columns lane, lanes, in_intersection, on_crosswalk, off_road) and, for the
four relations, the lanes related to the reference's lane by synth.road.lane_relations on that map. Those sets are
rows of a small table, `r2s_lane_sets` (map_id, lane, and one list of lane ids per relation), joined to every
frames row by (map_id, lane); a relation is then `list_contains(ref.rel_same, e.lane)`, the checker's own
lookup. Every lane condition is exact (its candidate and sure conditions are one), so the Python re-check of the
other clauses leaves the lane clauses out (`without_lanes`).
"""

from __future__ import annotations

from collections.abc import Iterable

import pyarrow as pa

from synth.config import SynthConfig
from synth.dsl import Statement
from synth.parts.lane import Anywhere, InLane, LaneFact, LaneRelation
from synth.patterns.one_frame import Pattern
from synth.road.lane_relations import SIDES, LaneGraph
from synth.road.roadmap import RoadMap

LANE_SETS = "r2s_lane_sets"
# (map_id, from_lane, to_lane): to_lane is in the lane left or right of from_lane (rel_left, rel_right): what
# `changing lanes` looks up (pipeline.query.temporal), one row per pair, so a row's test is a join on its own lane.
SIDE_PAIRS = "r2s_side_pairs"
# The frames' road columns a lane pattern reads (frames.schema.ROAD_COLUMNS), and the relation lists.
FACT_COLUMNS = ("map_id", "lane", "lanes", "in_intersection", "on_crosswalk", "off_road")
RELATION_COLUMNS = tuple(f"rel_{side}" for side in SIDES)
LANE_PART = "lane"


def without_lanes(pattern: Pattern) -> Pattern:
    """The pattern with its lane clauses left out: what the Python re-check decides (SQL decides those exactly)."""
    def strip(st: Statement) -> Statement:
        return Statement(st.id, st.type, parts=tuple((n, c) for n, c in st.parts if n != LANE_PART))

    ego = strip(pattern.ego) if pattern.ego is not None else None  # its motion clauses stay for the re-check
    return Pattern(tuple(strip(st) for st in pattern.statements), ego if ego is not None and ego.parts else None)


def lane_sets(roads: Iterable[RoadMap]) -> pa.Table:
    """One row per lane of each map: the lanes a target's lane must be in for each relation with a reference in
    this lane (synth.road.lane_relations.LaneGraph.related), sorted."""
    cols: dict[str, list] = {"map_id": [], "lane": [], **{c: [] for c in RELATION_COLUMNS}}
    for road in roads:
        graph = LaneGraph(road)
        for f in road.lanes:
            cols["map_id"].append(road.map_id)
            cols["lane"].append(f.feature_id)
            for side, col in zip(SIDES, RELATION_COLUMNS):
                cols[col].append(sorted(graph.related(f.feature_id, side)))
    ids = pa.list_(pa.string())
    return pa.table({"map_id": pa.array(cols["map_id"], pa.string()), "lane": pa.array(cols["lane"], pa.string()),
                     **{c: pa.array(cols[c], ids) for c in RELATION_COLUMNS}})


def side_pairs_sql() -> str:
    """The statement that makes SIDE_PAIRS from LANE_SETS."""
    return (f"CREATE TEMP TABLE {SIDE_PAIRS} AS SELECT DISTINCT map_id, lane AS from_lane, "
            f"unnest(list_concat(coalesce(rel_left, []), coalesce(rel_right, []))) AS to_lane FROM {LANE_SETS}")


def _text(value: str) -> str:
    return "'" + value.replace("'", "''") + "'"


# The exact SQL of each lane clause kind for the entity's alias e and its reference's r (NULL is false):
# pipeline.query.sql.BUILDERS takes them as conditions that are both candidate and sure.

def relation(clause: LaneRelation, e: str, r: str | None, config: SynthConfig) -> str:
    return f"coalesce(list_contains({r}.rel_{clause.side}, {e}.lane), FALSE)"


def fact(clause: LaneFact, e: str, r: str | None, config: SynthConfig) -> str:
    return {"intersection": f"coalesce({e}.in_intersection, FALSE)",
            "crosswalk": f"coalesce({e}.on_crosswalk, FALSE)",
            "off road": f"coalesce({e}.off_road, FALSE)",
            "off lane": f"coalesce(len({e}.lanes) = 0 AND NOT {e}.off_road, FALSE)"}[clause.fact]


def lane_by_id(clause: InLane, e: str, r: str | None, config: SynthConfig) -> str:
    return f"coalesce({e}.lane = {_text(clause.lane)}, FALSE)"


def anywhere(clause: Anywhere, e: str, r: str | None, config: SynthConfig) -> str:
    return "TRUE"


SQL = {LaneRelation: relation, LaneFact: fact, InLane: lane_by_id, Anywhere: anywhere}
