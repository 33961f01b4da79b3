"""A pattern compiled into one DuckDB query over the frames rows: self-joins per pattern name, one predicate builder
per clause kind, and a split of every candidate binding into *sure* and *to check*.

Exactness. synth.semantics decides with float atan2 bearings, fmod normalisation and hypot distances. Each builder
returns two SQL conditions:
- `candidate`, true for every binding the semantics accept (a superset: every bound widened by SLACK), used to join;
- `sure`, true only for bindings the semantics accept (every bound narrowed by SLACK).
A candidate that is not sure is re-checked by the semantics' own functions (a Python UDF, evaluated only on those
rows), so the matches are exactly the checker's. Why the two conditions are a superset and a subset:
- Local coordinates and heading Ranges are the semantics' formulas, operation for operation (DuckDB's `%` on doubles
  is C fmod, exact as Python's; sin, cos and radians are libm's), so they differ from Python's by an ulp or so.
- Distances: sqrt(dx*dx + dy*dy) against hypot, a few ulps apart, compared with bounds widened or narrowed by SLACK
  metres per metre of bound (at least 1 m).
- "Within delta of a direction" (ahead of, left of, ..., facing toward / away from) is decided without atan2, as
  v.u >= |v| cos(delta): the angle of v to u is at most delta. Python's atan2 bearing is within ~1e-12 degrees of
  the true angle, so widening delta by SLACK degrees and the cosine by COS_MARGIN (far above the ~1e-15 |v| rounding
  of v.u and |v|) gives a superset, narrowing both a subset. A vector shorter than TINY (where squares underflow) is
  never sure.
All these rounding bounds hold for coordinates up to WILD_XY metres and headings up to WILD_HEADING degrees; an entity
beyond them is *wild*: every clause it takes part in is a candidate and never sure, so Python decides it.

Speed: every angle is a dot product with the per-row sin / cos of the heading (columns s and c of the rows view),
so the pairwise conditions are a few multiplications. Clauses that refer only to ego or to nothing filter each
name's rows before any join (ego joined in per frame). A name related to an earlier one is joined to one of them,
its anchor, through an equality key that every candidate pair shares (a grid cell of the reach of a distance, or a
lane of a lane relation: see "Pruning the joins" below), so the join meets the pairs near each other and not every
pair of the frame; the other clauses between names filter the join. Join order and memory are DuckDB's, and it
spills to its temporary directory under its memory limit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from pipeline.query import lanes
from synth.config import SynthConfig
from synth.dsl import (
    DIRECTIONS,
    AbsoluteHeading,
    AbsoluteSpeed,
    AbsoluteXYPos,
    DirectionPos,
    FacingRelation,
    LocalXYPos,
    MovingLike,
    RelativeHeading,
    RelativeSpeed,
    Statement,
    Stationary,
)
from synth.parts.motion import SPEED_EPS
from synth.patterns.one_frame import Pattern, WithinDistance, matched_types
from synth.scene import EGO_ID
from synth.semantics import ANGLE_EPS, LENGTH_EPS

SLACK = 1e-6  # degrees; metres per metre of bound (at least 1 m)
COS_MARGIN = 1e-9  # on cosines, relative to |v|
TINY = 1e-100  # metres: shorter vectors are never sure
WILD_XY = 1e6
WILD_HEADING = 1e4
ROWS = "r2s_rows"  # the view of the frames rows the query reads (pipeline.query.mining creates it)
EXACT_UDF = "r2s_exact"

# synth.geometry.normalize, operation for operation (the heading Ranges use it).
MACROS = (
    "CREATE OR REPLACE TEMP MACRO r2s_norm(a) AS (CASE WHEN (a) % 360.0 >= 0.0 THEN (a) % 360.0 "
    "WHEN (a) % 360.0 + 360.0 >= 360.0 THEN 0.0 ELSE (a) % 360.0 + 360.0 END)",
)
# The per-row columns the builders read besides x, y, heading: c = cos, s = sin of the heading in radians.
ROW_COLUMNS = "cos(radians(heading)) AS c, sin(radians(heading)) AS s"


def lit(v: float) -> str:
    """A double literal that DuckDB reads back to exactly v (a bare decimal would be typed DECIMAL)."""
    return f"'{float(v)!r}'::DOUBLE"


@dataclass(frozen=True)
class Condition:
    candidate: str  # true for every binding the semantics accept
    sure: str  # true only for bindings the semantics accept

    @staticmethod
    def all(conds: list[Condition]) -> Condition:
        if not conds:  # nothing to hold (a name whose clauses all left out, or all on other names): surely true
            return Condition("TRUE", "TRUE")
        return Condition(" AND ".join(f"({c.candidate})" for c in conds), " AND ".join(f"({c.sure})" for c in conds))


def _slack_len(bound: float) -> float:
    return SLACK * max(1.0, abs(bound))


def _within(expr: str, lo: float, hi: float) -> Condition:
    """lo <= expr <= hi for bounds already carrying the semantics' own epsilon (lengths, speeds); an infinite bound
    is no bound. A NULL expr is neither candidate nor sure."""
    cand = [f"{expr} >= {lit(lo - _slack_len(lo))}"] if math.isfinite(lo) else [f"{expr} IS NOT NULL"]
    sure = [f"{expr} >= {lit(lo + _slack_len(lo))}"] if math.isfinite(lo) else [f"{expr} IS NOT NULL"]
    if math.isfinite(hi):
        cand.append(f"{expr} <= {lit(hi + _slack_len(hi))}")
        sure.append(f"{expr} <= {lit(hi - _slack_len(hi))}")
    return Condition(" AND ".join(cand), " AND ".join(sure))


def _distinct_points(e: str, r: str) -> str:
    # Exact in both evaluations: a bearing between coincident points is undefined, no relation holds there.
    return f"NOT ({e}.x = {r}.x AND {e}.y = {r}.y)"


def _and_exact(exact: str, cond: Condition) -> Condition:
    return Condition(f"{exact} AND {cond.candidate}", f"{exact} AND {cond.sure}")


def _toward(vx: str, vy: str, ux: str, uy: str, delta: float) -> Condition:
    """The angle between vector (vx, vy) and unit vector (ux, uy) is at most delta (+ the semantics' ANGLE_EPS)."""
    dot, norm = f"({vx} * {ux} + {vy} * {uy})", f"sqrt({vx} * {vx} + {vy} * {vy})"
    wide = math.cos(math.radians(min(delta + ANGLE_EPS + SLACK, 180.0))) - COS_MARGIN
    candidate = f"({dot} >= {norm} * {lit(wide)} OR {norm} < {lit(TINY)})"
    narrow = delta + ANGLE_EPS - SLACK
    if narrow < 0.0:
        return Condition(candidate, "FALSE")
    sure = f"{norm} >= {lit(TINY)} AND {dot} >= {norm} * {lit(math.cos(math.radians(min(narrow, 180.0))) + COS_MARGIN)}"
    return Condition(candidate, sure)


def _axis(r: str, phi: float) -> tuple[str, str]:
    """The unit vector of heading(r) + phi for phi a multiple of 90: a heading's (-sin, cos), turned exactly."""
    return {0.0: (f"(-{r}.s)", f"{r}.c"), 90.0: (f"(-{r}.c)", f"(-{r}.s)"),
            180.0: (f"{r}.s", f"(-{r}.c)"), 270.0: (f"{r}.c", f"{r}.s")}[phi]


# ----------------------------------------------------------------------------- one builder per clause kind
# Each takes the clause, the SQL alias of the entity and of its reference (None when absolute), and the config.

def direction_pos(pos: DirectionPos, e: str, r: str | None, config: SynthConfig) -> Condition:
    dx, dy = f"({e}.x - {r}.x)", f"({e}.y - {r}.y)"
    dist = _within(f"sqrt({dx} * {dx} + {dy} * {dy})", pos.distance.lo - LENGTH_EPS, pos.distance.hi + LENGTH_EPS)
    angle = _toward(dx, dy, *_axis(r, DIRECTIONS[pos.direction][1]), config.delta1)
    return _and_exact(_distinct_points(e, r), Condition.all([dist, angle]))


def within_distance(pos: WithinDistance, e: str, r: str | None, config: SynthConfig) -> Condition:
    # Distance alone: direction_pos's distance test, with no cone and coincident points allowed.
    dx, dy = f"({e}.x - {r}.x)", f"({e}.y - {r}.y)"
    return _within(f"sqrt({dx} * {dx} + {dy} * {dy})", pos.distance.lo - LENGTH_EPS, pos.distance.hi + LENGTH_EPS)


def local_xy_pos(pos: LocalXYPos, e: str, r: str | None, config: SynthConfig) -> Condition:
    dx, dy = f"({e}.x - {r}.x)", f"({e}.y - {r}.y)"
    # synth.geometry.to_local: lx = dx cos t + dy sin t, ly = dy cos t - dx sin t.
    lx, ly = f"({dx} * {r}.c + {dy} * {r}.s)", f"({dy} * {r}.c - {dx} * {r}.s)"
    return Condition.all([_within(lx, pos.lateral.lo - LENGTH_EPS, pos.lateral.hi + LENGTH_EPS),
                          _within(ly, pos.forward.lo - LENGTH_EPS, pos.forward.hi + LENGTH_EPS)])


def absolute_xy_pos(pos: AbsoluteXYPos, e: str, r: str | None, config: SynthConfig) -> Condition:
    return Condition.all([_within(f"{e}.x", pos.x.lo - LENGTH_EPS, pos.x.hi + LENGTH_EPS),
                          _within(f"{e}.y", pos.y.lo - LENGTH_EPS, pos.y.hi + LENGTH_EPS)])


def facing_relation(head: FacingRelation, e: str, r: str | None, config: SynthConfig) -> Condition:
    # toward: e's heading within delta2 of the bearing from e to r; away: of the bearing from r to e.
    sign = "-" if head.mode == "toward" else ""
    vx, vy = f"{sign}({e}.x - {r}.x)", f"{sign}({e}.y - {r}.y)"
    return _and_exact(_distinct_points(e, r), _toward(vx, vy, f"(-{e}.s)", f"{e}.c", config.delta2))


def _angle_range(heading: str, base: str | None, lo: float, hi: float) -> Condition:
    """synth.semantics._in_angle_range: heading = N(base + alpha) for some alpha in [lo, hi]."""
    if hi - lo >= 360.0:  # every heading, as in the semantics: surely true (a wild entity is still re-checked)
        return Condition("TRUE", "TRUE")
    offset = f"({heading} - {base})" if base is not None else heading
    past = f"r2s_norm({offset} - {lit(lo)})"
    width, wrap = (hi - lo) + ANGLE_EPS, 360.0 - ANGLE_EPS
    return Condition(f"({past} <= {lit(width + SLACK)} OR {past} >= {lit(wrap - SLACK)})",
                     f"({past} <= {lit(width - SLACK)} OR {past} >= {lit(wrap + SLACK)})")


def relative_heading(head: RelativeHeading, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _angle_range(f"{e}.heading", f"{r}.heading", head.angle.lo, head.angle.hi)


def absolute_heading(head: AbsoluteHeading, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _angle_range(f"{e}.heading", None, head.angle.lo, head.angle.hi)


# Speeds: plain differences and comparisons, the semantics' own operations, with the same slack as lengths. An
# entity without a speed (NULL) makes every motion clause false, as in the semantics (NULL is never true in SQL).

def stationary(clause: Stationary, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _within(f"{e}.speed", -math.inf, config.v_stop + SPEED_EPS)


def moving_like(clause: MovingLike, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _within(f"abs({e}.speed - {r}.speed)", -math.inf, config.dv + SPEED_EPS)


def relative_speed(clause: RelativeSpeed, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _within(f"({e}.speed - {r}.speed)", clause.speed.lo - SPEED_EPS, clause.speed.hi + SPEED_EPS)


def absolute_speed(clause: AbsoluteSpeed, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _within(f"{e}.speed", clause.speed.lo - SPEED_EPS, clause.speed.hi + SPEED_EPS)


Builder = Callable[[object, str, "str | None", SynthConfig], Condition]


def _undecided(clause, e: str, r: str | None, config: SynthConfig) -> Condition:
    return Condition("TRUE", "FALSE")


BUILDERS: dict[type, Builder] = {
    DirectionPos: direction_pos,
    WithinDistance: within_distance,
    LocalXYPos: local_xy_pos,
    AbsoluteXYPos: absolute_xy_pos,
    FacingRelation: facing_relation,
    RelativeHeading: relative_heading,
    AbsoluteHeading: absolute_heading,
    Stationary: stationary,
    MovingLike: moving_like,
    RelativeSpeed: relative_speed,
    AbsoluteSpeed: absolute_speed,
}


def clause_condition(clause, e: str, r: str | None, config: SynthConfig) -> Condition:
    """A clause's condition, with wild entities always to check (see the module docstring). A clause kind without
    a builder here (a part registered in synth.parts) is never sure and always a candidate: the exact check
    (Clause.holds) decides it. A lane clause is exact SQL (pipeline.query.lanes), wild or not: its candidate and
    sure conditions are one, and the exact check leaves it out."""
    if (exact := lanes.SQL.get(type(clause))) is not None:
        sql = exact(clause, e, r, config)
        return Condition(sql, sql)
    cond = BUILDERS.get(type(clause), _undecided)(clause, e, r, config)
    wild = f"{e}.wild" + (f" OR {r}.wild" if r is not None else "")
    return Condition(f"({cond.candidate}) OR {wild}", f"({cond.sure}) AND NOT ({wild})")


# ------------------------------------------------------------------------------------------- pruning the joins
# A name related to earlier names is paired with one of them, its *anchor*, in a relation of its own (pairs_cte,
# materialized): the pairs of rows of a frame for which the statement's clauses on the anchor are candidates. The
# bindings then join each name's pairs on the anchor's row (r2s_ref = its ord), so each join meets the candidate
# pairs and not every pair of the frame again: before this (issue 39), DuckDB joined the third car of
# queue-of-three on the frame and evaluated the whole exact decision (CASE and re-check) on every pair of rows of
# the frame with every pair of the first two, ~20 of its 26 s at 10^5 frames.
#
# Within the pairs relation, a cheap necessary condition comes first: when a clause bounds the centre distance
# (ahead of r by Range(a, b), on X @ Y relative to r, within Range(a, b) of r), |dx| and |dy| are at most
# box(reach). Proof: reach() is the candidate condition's own upper bound of the computed distance (the
# distance's b, or the hypotenuse of the local coordinates' largest magnitudes, each widened by LENGTH_EPS and
# SLACK as _within widens them). For two entities that are not wild (|x|, |y| <= WILD_XY, finite), the computed
# differences, squares, sum and sqrt each round by half an ulp, so the true distance is at most the computed one
# times (1 + 1e-15) plus 1e-150 (an underflowed square); the local coordinates are a rotation by the rounded cos
# and sin, of norm within 1e-15 of 1, computed within 1e-8 m at these magnitudes. So the true |dx|, |dy| are below
# reach (1 + 1e-12) + 1e-8, and their computed values (one rounding) below box(reach) = reach (1 + BOX_MARGIN) +
# BOX_FLOOR. A wild entity is a candidate of every clause (clause_condition), so the box is `... OR wild`. The
# box costs two subtractions a pair where the candidate condition costs square roots and angles: DuckDB evaluates
# it first and the rest on the ~1 in 6 pairs of cars within it (measured on the Argoverse 2 log). A grid key
# instead (the 3 x 3 cells of side box(reach) around the anchor, a hash join on frame and cell) met a quarter of
# the frame's pairs but cost more than the frame's join with the box (3.6 vs 1.9 s at 10^5 frames: nine copies
# of every anchor row), so the join stays on the frame.
# The anchor is the earlier name of the clause of least reach, else the first earlier name the statement relates
# to; a lane relation (exact SQL, pipeline.query.lanes) filters its pairs as any other clause on the anchor does.
BOX_MARGIN = 1e-6
BOX_FLOOR = 1e-3  # metres


def _widened_hi(hi: float) -> float:
    """The upper bound _within puts in a candidate condition for a length Range's hi."""
    bound = hi + LENGTH_EPS
    return bound + _slack_len(bound)


def _widened_abs(lo: float, hi: float) -> float:
    """The largest magnitude a candidate condition of _within(lo - LENGTH_EPS, hi + LENGTH_EPS) lets through."""
    low = lo - LENGTH_EPS
    return max(abs(low - _slack_len(low)), abs(_widened_hi(hi)))


def reach(clause) -> float | None:
    """An upper bound of the computed centre distance of a candidate pair (entity, reference) of the clause, both
    not wild, or None (no bound, or one beyond the distance of any two entities that are not wild)."""
    if isinstance(clause, (DirectionPos, WithinDistance)):
        bound = _widened_hi(clause.distance.hi)
    elif isinstance(clause, LocalXYPos):
        bound = math.hypot(_widened_abs(clause.lateral.lo, clause.lateral.hi),
                           _widened_abs(clause.forward.lo, clause.forward.hi))
    else:
        return None
    return bound if bound <= 4 * WILD_XY else None  # (inf and NaN are not)


def box(bound: float) -> float:
    """The half side of the box around the anchor that holds every candidate of a clause of reach `bound`."""
    return bound * (1.0 + BOX_MARGIN) + BOX_FLOOR


@dataclass(frozen=True)
class Anchor:
    """The earlier name `ref` a statement is paired with; `reach`: the least reach of its clauses on it, if any."""

    ref: str
    reach: float | None = None


def anchor(st: Statement) -> Anchor | None:
    """The statement's anchor (see above), or None when it relates to no earlier name."""
    binary = [c for c in clauses(st) if c.ref not in (None, EGO_ID)]
    if not binary:
        return None
    reaches = [(r, k, c.ref) for k, c in enumerate(binary) if (r := reach(c)) is not None]
    if not reaches:
        return Anchor(binary[0].ref)
    bound, _, ref = min(reaches)
    return Anchor(ref, bound)


def pairs_cte(name: str, rows: str, ref_rows: str, st: Statement, ref_type: str, anc: Anchor,
              config: SynthConfig, materialized: bool = True) -> str:
    """The CTE `name`: the rows of `rows` (a name's, with its columns) that are candidates for the statement's
    clauses on its anchor, each with r2s_ref, the ord of the anchor's row in `ref_rows` it pairs with (a row once
    per such anchor row). Materialized (for the bindings' joins: inlined, DuckDB would merge it into them and
    reorder them), or not (counted as it streams, by the estimate)."""
    on = [_same_frame("e", "r")]
    if anc.reach is not None:
        half = lit(box(anc.reach))
        on.append(f"((abs(e.x - r.x) <= {half} AND abs(e.y - r.y) <= {half}) OR e.wild OR r.wild)")
    on += ["e.ord <> r.ord"] if _overlap(st.type, ref_type) else []
    on.append(f"({Condition.all([clause_condition(c, 'e', 'r', config) for c in clauses(st) if c.ref == anc.ref]).candidate})")
    return f"{name} AS {'MATERIALIZED ' if materialized else ''}(SELECT e.*, r.ord AS r2s_ref FROM {ref_rows} r JOIN {rows} e ON {' AND '.join(on)})"


# ----------------------------------------------------------------------------------------- the whole query

def _alias(k: int) -> str:
    return f"t{k}"


def clauses(st: Statement) -> tuple:
    """The statement's clauses, one per part it carries (synth.parts), each with a builder in BUILDERS."""
    return tuple(clause for _, clause in st.clauses())


def matches_select(all_bindings: bool) -> str:
    """The SELECT over the bindings relation m (bindings_query) that gives the matches file's rows: one per matching
    frame (frame_id, scene, timestamp_us, n_matches, binding = the first binding), or with all_bindings one per
    binding; frames in input order, bindings in lexicographic order of their entities' input rows."""
    if all_bindings:
        select = ("SELECT frame_id, scene, timestamp_us, count(*) OVER (PARTITION BY frame_ord) AS n_matches, binding "
                  "FROM m ORDER BY frame_ord, key")
    else:
        select = ("SELECT frame_id, any_value(scene) AS scene, any_value(timestamp_us) AS timestamp_us, "
                  "count(*) AS n_matches, arg_min(binding, key) AS binding FROM m GROUP BY frame_ord, frame_id "
                  "ORDER BY frame_ord")
    return select


# ego's row per frame, with frame_pos: consecutive frames of a scene have consecutive positions (what events are
# runs of).
def ego_select(with_lanes: bool = False) -> str:
    """ego's row per frame (EGO_TABLE's rows); with_lanes: with the lane facts of its row (pipeline.query.lanes),
    not yet the relation lists (ego_rows)."""
    facts = "".join(f", {c}" for c in lanes.FACT_COLUMNS) if with_lanes else ""
    return (f"SELECT fk, frame_id, ord AS frame_ord, row_number() OVER (PARTITION BY scene ORDER BY "
            f"frame_index, ord) AS frame_pos, scene, timestamp_us, x, y, heading, speed, c, s, wild{facts} "
            f"FROM {ROWS} WHERE is_ego")


def ego_rows(select: str, with_lanes: bool) -> str:
    """The rows of the CTE `ego` from `select` (ego_select's rows); with_lanes: joined to the relation lists of
    their lane, as the rows view joins them (pipeline.query.mining). Joined where the CTE is read, after the window
    and the sort of EGO_TABLE: ego's rows carrying the lists through those took 17 of a lane pattern's 60 s at
    10^6 frames (the sort moves every list)."""
    if not with_lanes:
        return select
    rels = ", ".join(f"ls.{c}" for c in lanes.RELATION_COLUMNS)
    return (f"SELECT e.*, {rels} FROM ({select}) e LEFT JOIN {lanes.LANE_SETS} ls ON ls.map_id = e.map_id "
            "AND ls.lane = e.lane")


def ego_cte(with_lanes: bool = False, chunk: Chunk | None = None) -> str:
    """The CTE `ego` (ego_rows); with a chunk, its frames' rows of EGO_TABLE (made by frame_chunks)."""
    select = (ego_select(with_lanes) if chunk is None else
              f"SELECT * FROM {EGO_TABLE} WHERE frame_ord BETWEEN {chunk.lo} AND {chunk.hi}")
    return f"ego AS ({ego_rows(select, with_lanes)})"


def _lane_columns(prefix: str) -> str:
    return "".join(f", {prefix}{c}" for c in lanes.FACT_COLUMNS + lanes.RELATION_COLUMNS)


EGO_CTE = ego_cte()


# ------------------------------------------------------------------------------------------ frames in chunks
# The bindings are built CHUNK_FRAMES frames at a time, each chunk's appended to a table (materialize): a join's
# tables and pairs hold one chunk's rows, so the memory of a query is bounded by the chunk, not by the frames
# (queue-of-three held 11 GB at 10^6 frames in one query, and more than twice the CPU spilling under 3 GB). A
# binding is of one frame and a frame is in one chunk, so the chunks' bindings together are the whole query's, and
# DISTINCT or GROUP BY over a frame's rows per chunk is global.
CHUNK_FRAMES = 100_000
EGO_TABLE = "r2s_ego"
ORD_FILE = 1099511627776  # ord = file_index * ORD_FILE + file_row_number (the rows view of pipeline.query.mining)


@dataclass(frozen=True)
class Chunk:
    """The frames whose ego rows' ords are lo..hi. Their rows lie strictly between `after` and `before`, the ego
    ords of the frames just before and after them (-1 and None at the ends): a frame's rows are one contiguous
    block with exactly one ego row (frames.dataset checks both), so another frame's ego row is outside it. The rows
    between are read by file and row number, which DuckDB's Parquet reader skips to without reading the others; the
    rows of the two frames at the ends that fall between are dropped by the join with the chunk's ego rows."""

    lo: int
    hi: int
    after: int
    before: int | None

    def rows(self, f: str) -> list[str]:
        """The conditions on the rows (alias f) of the chunk's frames."""
        where = [f"{f}.ord > {self.after}"]
        first = self.after // ORD_FILE if self.after >= 0 else 0
        where.append(f"{f}.r2s_file >= {first}")
        if self.before is not None:
            where += [f"{f}.ord < {self.before}", f"{f}.r2s_file <= {self.before // ORD_FILE}"]
            if self.before // ORD_FILE == first:
                where += [f"{f}.r2s_row > {self.after % ORD_FILE if self.after >= 0 else -1}",
                          f"{f}.r2s_row < {self.before % ORD_FILE}"]
        return where


def frame_chunks(con, with_lanes: bool, size: int | None = None) -> list[Chunk]:
    """Make EGO_TABLE (ego_select's rows, with_lanes their lane columns, in input order) in `con`, and the chunks of
    its frames."""
    con.execute(f"CREATE OR REPLACE TEMP TABLE {EGO_TABLE} AS {ego_select(with_lanes)} ORDER BY frame_ord")
    ords = con.execute(f"SELECT frame_ord FROM {EGO_TABLE} ORDER BY frame_ord").fetchnumpy()["frame_ord"].tolist()
    size = size or CHUNK_FRAMES
    return [Chunk(ords[i], ords[min(i + size, len(ords)) - 1], ords[i - 1] if i else -1,
                  ords[i + size] if i + size < len(ords) else None) for i in range(0, len(ords), size)]


def materialize(con, pattern: Pattern, config: SynthConfig, chunks: list[Chunk], table: str, select: str) -> None:
    """CREATE TEMP TABLE `table` from `select` (a SELECT over the bindings relation m), one chunk after another."""
    for k, chunk in enumerate(chunks or [None]):
        query = bindings_query(pattern, config, chunk) + "\n" + select
        con.execute(f"CREATE TEMP TABLE {table} AS {query}" if k == 0 else f"INSERT INTO {table} {query}")


def _name_ctes(pattern: Pattern, config: SynthConfig, alias: dict[str, str],
               chunk: Chunk | None = None) -> list[str]:
    """Per pattern name (its CTE named alias[name]) the rows it may bind: its type, and its clauses on ego or on
    nothing as the candidate filter (`sure` says whether they surely hold). They read the CTE `ego` (EGO_CTE).
    With a chunk, the rows of its frames (and of the two at its ends, which the join with ego drops)."""
    cols = ("f.fk, f.frame_id, f.scene, f.ord, f.entity_id, f.track_id, f.type, f.x, f.y, f.heading, f.speed, f.c, "
            "f.s, f.wild")
    if pattern.uses_lanes:  # the lane facts and relation lists of each row (pipeline.query.lanes)
        cols += _lane_columns("f.")
    ctes = []
    for st in pattern.statements:
        # Clauses on ego or on nothing filter the name's rows (ego joined per frame); the others filter the join.
        unary = [clause_condition(c, "f", None if c.ref is None else "g", config)
                 for c in clauses(st) if c.ref in (None, EGO_ID)]
        where = ["NOT f.is_ego"] + (chunk.rows("f") if chunk is not None else [])
        types = matched_types(st.type)
        if types is not None:
            where.append(f"f.type IN ({', '.join(repr(t) for t in sorted(types))})")
        cond = Condition.all(unary)
        where.append(f"({cond.candidate})")
        join_ego = f" JOIN ego g ON {_same_frame('f', 'g')}" if any(c.ref == EGO_ID for c in clauses(st)) else ""
        ctes.append(f"{alias[st.id]} AS (SELECT {cols}, ({cond.sure}) AS sure FROM {ROWS} f{join_ego} "
                    f"WHERE {' AND '.join(where)})")
    return ctes


def positional(values: list[str]) -> str:
    """A struct of the values with fields named by position (`0`, `1`, ...). DuckDB's struct field and column names
    ignore case and pattern names do not (`a` and `A` are two names), so every struct or column keyed by a pattern
    name is keyed by the name's position in the pattern; pipeline.query.mining names the fields as it writes them."""
    return "struct_pack(" + ", ".join(f'"{k}" := {v}' for k, v in enumerate(values)) + ")"


def bindings_query(pattern: Pattern, config: SynthConfig, chunk: Chunk | None = None) -> str:
    """`WITH ..., m AS (...)`: CTEs whose last, m, has one row per binding of the pattern in a frame: frame_id,
    frame_ord (the frame's order in the input), frame_pos (its position in its scene by frame index, from 1),
    scene, timestamp_us, key (the bound rows' ordinals), binding (name -> entity id), tracks (name -> track id),
    the two structs keyed by the names' positions (positional). It calls r2s_exact(numbers, types) on the
    candidates that are not sure: numbers are ego's x, y, heading, speed, then the same per name; types one per
    name. With a chunk, over its frames alone (EGO_TABLE made by frame_chunks)."""
    names = pattern.names
    alias = {name: _alias(k) for k, name in enumerate(names)} | {EGO_ID: "g"}
    ego = ego_cte(pattern.uses_lanes, chunk)
    name_ctes = _name_ctes(pattern, config, alias, chunk)
    ctes = [ego, *name_ctes]
    pairs = _shared_pairs(pattern, config, alias, name_ctes)
    ctes += list(dict.fromkeys(pairs.values()))
    first = alias[names[0]]
    joins, sure_parts, candidate_parts = [], [], []
    for k, st in enumerate(pattern.statements):
        a = alias[st.id]
        sure_parts.append(f"{a}.sure")
        if k == 0:
            continue
        anc = anchor(st)
        source = a
        if anc is None:
            on = [_same_frame(a, first)]
        else:  # its rows paired with its anchor's (its frame is the anchor's: an ord is one row of the input)
            source = f"{pairs[st.id].split(' AS ', 1)[0]} {a}"
            on = [f"{a}.r2s_ref = {alias[anc.ref]}.ord"]
        # Injective: a different input row from every earlier name whose types can coincide.
        on += [f"{a}.ord <> {alias[other.id]}.ord" for other in pattern.statements[:k] if _overlap(st.type, other.type)]
        bcond = Condition.all(_binary(st, alias, config))
        sure_parts.append(f"({bcond.sure})")
        # The candidate conditions of the clauses on the anchor hold on every row of the pairs (pairs_cte): only
        # the others filter the join (queue-of-three evaluated its distances and cones twice a binding).
        rest = bcond if anc is None else Condition.all(_binary(st, alias, config, skip=anc.ref))
        if rest.candidate != "TRUE":
            on.append(f"({rest.candidate})")
            candidate_parts.append(f"({rest.candidate})")
        joins.append(f"JOIN {source} ON {' AND '.join(on)}")
    if pattern.ego is not None:
        # The ego line: conditions on g, the frame's ego row, in the final filter (the ego CTE keeps every frame:
        # frame_pos numbers a scene's frames for events).
        ego = Condition.all([clause_condition(c, "g", None if c.ref is None else alias[c.ref], config)
                             for c in clauses(pattern.ego)])
        sure_parts.append(f"({ego.sure})")
        candidate_parts.append(f"({ego.candidate})")
    numbers = [f"{a}.{c}" for a in ["g"] + [alias[n] for n in names] for c in ("x", "y", "heading", "speed")]
    types = [f"{alias[n]}.type" for n in names]
    key = "[" + ", ".join(f"{alias[n]}.ord" for n in names) + "]"
    binding = positional([f"{alias[n]}.entity_id" for n in names])
    tracks = positional([f"{alias[n]}.track_id" for n in names])
    ctes.append(
        f"m AS (SELECT g.frame_id, g.frame_ord, g.frame_pos, g.scene, g.timestamp_us, {key} AS key, "
        f"{binding} AS binding, {tracks} AS tracks "
        f"FROM {first} {' '.join(joins)} JOIN ego g ON {_same_frame(first, 'g')} "
        # CASE, not OR: DuckDB reorders a filter's conjuncts adaptively, and the exact check must only ever see
        # candidates that are not sure.
        f"WHERE CASE WHEN {' AND '.join(sure_parts)} THEN TRUE WHEN {' AND '.join(candidate_parts) or 'TRUE'} "
        f"THEN {EXACT_UDF}([{', '.join(numbers)}], [{', '.join(types)}]) ELSE FALSE END)")
    return "WITH " + ",\n".join(ctes)


def _shared_pairs(pattern: Pattern, config: SynthConfig, alias: dict[str, str], name_ctes: list[str]) -> dict[str, str]:
    """Per name with an anchor, the CTE (pairs_cte) of its pairs, one CTE for the names whose pairs are one relation.
    The pairs of rows E with anchor rows A (pairs_cte) depend on the rows and the statement's clauses on the anchor,
    not on the names: two names whose rows are one query (the same type and clauses on ego and nothing) have the
    same rows, and the bindings join keeps of a name's pairs those whose anchor row is the anchor's (r2s_ref =
    anchor.ord), so the pairs of E with any superset of A's rows serve as well: the rows of a name with no clause on
    ego or nothing and A's types. So queue-of-three's b (ahead of a) and c (ahead of b) share one relation, the car
    pairs of its clauses (a's rows are among b's: its one frame join of car pairs, not two, ~45% of its time)."""
    body = {st.id: cte.split(" AS ", 1)[1] for st, cte in zip(pattern.statements, name_ctes)}
    same = {st.id: next(o.id for o in pattern.statements if body[o.id] == body[st.id]) for st in pattern.statements}
    # names whose rows are every row of their types (a superset of the rows of any name of those types)
    every = [st for st in pattern.statements
             if same[st.id] == st.id and not any(c.ref in (None, EGO_ID) for c in clauses(st))]

    def text(st: Statement, anc: Anchor, ref: str) -> str:
        return pairs_cte("{}", alias[same[st.id]], alias[ref], st, _type_of(pattern, anc.ref), anc, config)

    own = {st.id: text(st, anchor(st), same[anchor(st).ref]) for st in pattern.statements[1:] if anchor(st)}
    chosen = dict(own)
    for st in pattern.statements[1:]:
        anc = anchor(st)
        if anc is None:
            continue
        for wider in every:
            if matched_types(wider.type) != matched_types(_type_of(pattern, anc.ref)):
                continue
            shared = text(st, anc, wider.id)
            if any(other != st.id and t == shared for other, t in own.items()):
                chosen[st.id] = shared
                break
    # one CTE per relation, named by the first name that uses it
    named = {}
    for name, t in chosen.items():
        named.setdefault(t, t.replace("{}", f"{alias[name]}_pairs", 1))
    return {name: named[t] for name, t in chosen.items()}


def _binary(st: Statement, alias: dict[str, str], config: SynthConfig, skip: str | None = None) -> list[Condition]:
    """The conditions of a statement's clauses between two pattern names (they filter the join), but those on
    `skip`."""
    return [clause_condition(c, alias[st.id], alias[c.ref], config) for c in clauses(st)
            if c.ref not in (None, EGO_ID, skip)]


def estimate_ctes(pattern: Pattern, config: SynthConfig, fanout: bool, label: str = "p",
                  chunk: Chunk | None = None) -> list[str]:
    """CTEs ending in `label`: one row per frame (fk, frame_id, scene, rows: its non-ego rows, p) where p bounds
    from above what the pattern's join (bindings_query) builds in the frame: its candidate bindings, at most the
    product over the names of how many rows each may bind (its type and its clauses on ego), plus the rows of each
    name's pairs with its anchor (pairs_cte), at most the product of the two names' rows. With `fanout`, tighter:
    in the product a name constrained by an earlier name counts at most the rows that may stand in that relation
    to one row of the earlier name (its anchor where it has one: the pairs the query joins, counted), and the
    pairs are counted. A binding picks each name among those rows, so the product is an upper bound. Names and
    helper CTEs are prefixed by `label`, so several patterns' estimates share a query."""
    names = pattern.names
    alias = {name: f"{label}_{_alias(k)}" for k, name in enumerate(names)} | {EGO_ID: "g"}
    ctes = _name_ctes(pattern, config, alias, chunk)
    factors, pairs = [], []
    for k, st in enumerate(pattern.statements):
        a = alias[st.id]
        n_k = f"{label}_n{k}"
        anc = anchor(st) if k else None
        if anc is not None:
            count = f"{label}_n{names.index(anc.ref)}.n"
            pairs.append(f"coalesce({n_k}.pairs, 0)::DOUBLE" if fanout else f"coalesce({count} * {n_k}.n, 0)::DOUBLE")
        if fanout and anc is not None:
            ctes.append(pairs_cte(f"{a}_pairs", a, alias[anc.ref], st, _type_of(pattern, anc.ref), anc, config,
                                  materialized=False))
            ctes.append(f"{n_k} AS (SELECT fk, frame_id, max(n) AS n, sum(n) AS pairs FROM (SELECT fk, frame_id, "
                        f"count(*) AS n FROM {a}_pairs GROUP BY fk, frame_id, r2s_ref) GROUP BY fk, frame_id)")
        else:
            ctes.append(f"{n_k} AS (SELECT fk, frame_id, count(*) AS n FROM {a} GROUP BY fk, frame_id)")
        factors.append(f"coalesce({n_k}.n, 0)::DOUBLE")
    joins = " ".join(f"LEFT JOIN {label}_n{k} ON {_same_frame(f'{label}_n{k}', 'g')}" for k in range(len(names)))
    ctes.append(f"{label} AS (SELECT g.fk, g.frame_id, g.scene, g.rows, {' + '.join([' * '.join(factors), *pairs])} "
                f"AS p FROM r2s_frames g {joins})")
    return ctes


# The frames an estimate runs over: one row per frame with its scene and non-ego rows.
ESTIMATE_FRAMES = (f"r2s_frames AS (SELECT fk, frame_id, any_value(scene) AS scene, count(*) - 1 AS rows "
                   f"FROM {ROWS} GROUP BY fk, frame_id)")


def estimate_query(pattern: Pattern, config: SynthConfig, fanout: bool, per_frame: bool = False,
                   chunk: Chunk | None = None) -> str:
    """One aggregate over estimate_ctes: (largest product, its frame id, that frame's non-ego rows, sum of the
    products), or with per_frame one row per frame (frame id, product). With a chunk, over its frames (the query's
    own chunks: frame_chunks): the largest of the chunks' and the sum of their sums are the whole estimate."""
    if chunk is None:
        ctes = [ego_cte(pattern.uses_lanes), ESTIMATE_FRAMES, *estimate_ctes(pattern, config, fanout)]
    else:  # the frames whose ego row is the chunk's (the two at its ends, read in part, have none between)
        frames = (f"r2s_frames AS (SELECT fk, frame_id, any_value(scene) AS scene, count(*) - 1 AS rows FROM {ROWS} f "
                  f"WHERE {' AND '.join(chunk.rows('f'))} GROUP BY fk, frame_id HAVING bool_or(is_ego))")
        ctes = [ego_cte(pattern.uses_lanes, chunk), frames,
                *estimate_ctes(pattern, config, fanout, chunk=chunk)]
    return "WITH " + ",\n".join(ctes) + "\n" + estimate_select("p", "0", per_frame)


def estimate_select(products: str, extra: str, per_frame: bool) -> str:
    """The estimate's answer from a relation of per-frame products (frame_id, rows, p) and a scalar SQL `extra`
    added to the total: (largest product, its frame id, that frame's non-ego rows, total), or per frame (frame id,
    product)."""
    if per_frame:
        return f"SELECT frame_id, p FROM {products}"
    return f"SELECT max(p), arg_max(frame_id, p), arg_max(rows, p), sum(p) + ({extra}) FROM {products}"


def _same_frame(a: str, b: str) -> str:
    # fk = hash(frame_id): joining on an integer is faster than on the id; the id comparison settles collisions.
    return f"{a}.fk = {b}.fk AND {a}.frame_id = {b}.frame_id"


def _type_of(pattern: Pattern, name: str) -> str:
    return next(st.type for st in pattern.statements if st.id == name)


def _overlap(t1: str, t2: str) -> bool:
    a, b = matched_types(t1), matched_types(t2)
    return a is None or b is None or bool(a & b)
