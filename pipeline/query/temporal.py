"""Temporal patterns over a frames dataset (synth.temporal; the definition is docs/dsl.md, "Temporal patterns"),
as DuckDB statements run one after another in the query's session.

1. Each step is a one-frame pattern: its bindings in every frame come from the one-frame query
   (pipeline.query.sql.bindings_query, with its exact re-check of near-boundary candidates), keyed by the tracks
   they bind; behaviours filter them (per track and frame, computed with windows over the track's timestamps).
2. The candidate bindings of the whole pattern: the steps' track tuples joined on their shared variables, every
   variable a different track.
3. The steps are chained per (scene, binding) over frame positions with window functions: a step's *feasible
   ends* are the frames p where the step holds, inside a run of consecutive frames where it holds that contains
   a feasible *start* a <= p with t(p) - t(a) >= its `for at least`; a start is a frame where the step holds after
   a feasible end q < p of the previous step (with `within T`: t(p) - t(q) <= T). The pattern matches at the last
   step's feasible ends.
The result is the relation m of sql.bindings_query (one row per binding and frame), so per-frame matches and
events are the same selects as for one-frame patterns. Every table is DuckDB's: it spills under its memory limit.
"""

from __future__ import annotations

from collections.abc import Callable

from pipeline.query.sql import (
    ESTIMATE_FRAMES,
    ROWS,
    bindings_query,
    ego_cte,
    estimate_ctes,
    estimate_select,
    positional,
)
from synth.config import SynthConfig
from synth.parts.motion import SPEED_EPS
from synth.pattern import Pattern
from synth.scene import EGO_ID
from synth.temporal import (
    LANE_BEHAVIOURS,
    LANE_CHANGE_WINDOW_US,
    MOVING_SPEED,
    SPEED_BEHAVIOURS,
    SPEED_CHANGE,
    SPEED_CHANGE_WINDOW_US,
    STOP_WINDOW_US,
    TURN_ANGLE,
    TURN_WINDOW_US,
    TURNING,
    TemporalPattern,
)

POSITIONS = "r2s_fpos"
BEHAVIOUR_TABLE = "r2s_behaviour"
TURNING_TABLE = "r2s_turning"
LANE_CHANGE_TABLE = "r2s_lane_change"
# Where each behaviour is read: (table, column). Ego's behaviours are in the same tables suffixed EGO_SUFFIX, over
# ego's rows (EGO_ROWS: one track per scene, EGO_TRACK); the variables' over the other rows (OTHER_ROWS).
BEHAVIOUR_COLUMNS = ({b: (BEHAVIOUR_TABLE, b) for b in SPEED_BEHAVIOURS}
                     | {b: (TURNING_TABLE, b.replace(" ", "_")) for b in TURNING}
                     | {b: (LANE_CHANGE_TABLE, b.replace(" ", "_")) for b in LANE_BEHAVIOURS})
EGO_SUFFIX = "_ego"
EGO_TRACK = "'ego'"
OTHER_ROWS = f"(SELECT * FROM {ROWS} WHERE NOT is_ego)"
EGO_ROWS = f"(SELECT * REPLACE ({EGO_TRACK} AS track_id) FROM {ROWS} WHERE is_ego)"
IDS = "r2s_ids"
CANDIDATES = "r2s_candidates"


def _var(k: int) -> str:
    # The track column of the pattern's k-th variable (TemporalPattern.names): by position, as sql.positional keys
    # structs (DuckDB's column names ignore case, the pattern's names do not), and prefixed (never `scene`).
    return f'"v{k}"'


def _lit(v: float) -> str:
    return f"'{float(v)!r}'::DOUBLE"


def behaviour_sql(config: SynthConfig, rows: str = OTHER_ROWS, table: str = BEHAVIOUR_TABLE) -> str:
    """One row per (scene, frame, track) of `rows` (non-ego entities, or ego's): is it accelerating, braking,
    stopping there?
    A track's earlier frames are those of the same scene whose timestamp is within the window before (RANGE
    over the integer timestamps); rows without a speed take part in none. Exact: the extreme speed of the window
    decides, and IEEE subtraction is monotone, so `v - min(v') >= A` iff some v' has `v - v' >= A`."""
    change = (f"PARTITION BY scene, track_id ORDER BY timestamp_us RANGE BETWEEN {SPEED_CHANGE_WINDOW_US} PRECEDING "
              "AND 1 PRECEDING")
    stop = f"PARTITION BY scene, track_id ORDER BY timestamp_us RANGE BETWEEN {STOP_WINDOW_US} PRECEDING AND 1 PRECEDING"
    return (
        f"CREATE TEMP TABLE {table} AS SELECT scene, frame_id, track_id, "
        f"bool_or(coalesce(accelerating, FALSE)) AS accelerating, bool_or(coalesce(braking, FALSE)) AS braking, "
        f"bool_or(coalesce(stopping, FALSE)) AS stopping FROM ("
        f"SELECT scene, frame_id, track_id, speed - min(speed) OVER ({change}) >= {_lit(SPEED_CHANGE)} AS accelerating, "
        f"max(speed) OVER ({change}) - speed >= {_lit(SPEED_CHANGE)} AS braking, "
        f"speed <= {_lit(config.v_stop + SPEED_EPS)} AND max(speed) OVER ({stop}) >= {_lit(MOVING_SPEED)} AS stopping "
        f"FROM {rows}) GROUP BY scene, frame_id, track_id"
    )


def turning_sql(rows: str = OTHER_ROWS, table: str = TURNING_TABLE) -> str:
    """One row per (scene, frame, track) of `rows` that has an earlier row within TURN_WINDOW_US: has it
    turned left, right since one of them? Every earlier row of the track in the window is compared (a self-join
    on the track: headings wrap, so no window extreme decides), by synth.temporal.turn_of's operations on
    map_heading (r2s_norm is synth.geometry.normalize); rows without a finite map_heading or a timestamp take part
    in none."""
    rows = (f"SELECT scene, frame_id, track_id, timestamp_us, map_heading AS h FROM {rows} "
            "WHERE isfinite(map_heading) AND timestamp_us IS NOT NULL")
    turn = "r2s_norm(p.h - q.h + 180.0) - 180.0"
    return (
        f"CREATE TEMP TABLE {table} AS WITH h AS ({rows}) "
        f"SELECT p.scene, p.frame_id, p.track_id, bool_or({turn} >= {_lit(TURN_ANGLE)}) AS turning_left, "
        f"bool_or({turn} <= {_lit(-TURN_ANGLE)}) AS turning_right "
        f"FROM h p JOIN h q ON p.scene = q.scene AND p.track_id = q.track_id "
        f"AND q.timestamp_us >= p.timestamp_us - {TURN_WINDOW_US} AND q.timestamp_us < p.timestamp_us "
        "GROUP BY p.scene, p.frame_id, p.track_id"
    )


def lane_change_sql(rows: str = OTHER_ROWS, table: str = LANE_CHANGE_TABLE) -> str:
    """One row per (scene, frame, track) of `rows` in a lane: is it changing lanes there, its lane on the chain of
    the left or right neighbour of its lane at one of its rows within LANE_CHANGE_WINDOW_US before, in the same map?
    The window collects those earlier rows' relation lists (the `rel_left`, `rel_right` of pipeline.query.lanes,
    LaneGraph.related of their lane), so the test is the list lookup of `in lane left of`; rows in no lane or
    without a timestamp take part in none."""
    window = (f"PARTITION BY scene, track_id, map_id ORDER BY timestamp_us RANGE BETWEEN {LANE_CHANGE_WINDOW_US} "
              "PRECEDING AND 1 PRECEDING")
    return (
        f"CREATE TEMP TABLE {table} AS SELECT scene, frame_id, track_id, "
        f"bool_or(coalesce(changing_lanes, FALSE)) AS changing_lanes FROM ("
        f"SELECT scene, frame_id, track_id, list_contains(flatten(list(list_concat(coalesce(rel_left, []), "
        f"coalesce(rel_right, []))) OVER ({window})), lane) AS changing_lanes "
        f"FROM {rows} WHERE lane IS NOT NULL AND timestamp_us IS NOT NULL) GROUP BY scene, frame_id, track_id"
    )


# The SQL of each behaviour table, by the table it makes (rows, table) -> statement.
BEHAVIOUR_SQL = {BEHAVIOUR_TABLE: lambda config, rows, table: behaviour_sql(config, rows, table),
                 TURNING_TABLE: lambda config, rows, table: turning_sql(rows, table),
                 LANE_CHANGE_TABLE: lambda config, rows, table: lane_change_sql(rows, table)}


def _behaviour_of(n: str, names: tuple[str, ...]) -> tuple[str, str]:
    """(table suffix, SQL of the track) of a step's name or ego, for the behaviour join."""
    return (EGO_SUFFIX, EGO_TRACK) if n == EGO_ID else ("", f'm.tracks."{names.index(n)}"')


def step_sql(k: int, pattern: Pattern, behaviours: tuple[tuple[str, str], ...], variables: tuple[str, ...],
             config: SynthConfig) -> str:
    """The frames (scene, position, timestamp) and track tuples at which step k holds (its tracks struct is keyed
    by the step's positions, its columns by the positions of the whole pattern's `variables`)."""
    names = pattern.names
    cols = ", ".join(f'm.tracks."{j}" AS {_var(variables.index(n))}' for j, n in enumerate(names))
    joins = "".join(
        f" JOIN {BEHAVIOUR_COLUMNS[b][0]}{_behaviour_of(n, names)[0]} b{j} ON b{j}.frame_id = m.frame_id AND "
        f"b{j}.track_id = {_behaviour_of(n, names)[1]} AND b{j}.{BEHAVIOUR_COLUMNS[b][1]}"
        for j, (n, b) in enumerate(behaviours))
    return (f"CREATE TEMP TABLE r2s_step{k} AS {bindings_query(pattern, config)}\n"
            f"SELECT DISTINCT m.scene, m.frame_pos, m.timestamp_us, {cols} FROM m{joins}")


def candidates_sql(pattern: TemporalPattern) -> str:
    """Every binding of the pattern's variables to distinct tracks that each step binds somewhere in the scene."""
    names = pattern.names
    parts = []
    for k, step in enumerate(pattern.steps):
        cols = ", ".join(_var(names.index(n)) for n in step.names)
        parts.append(f"(SELECT DISTINCT scene, {cols} FROM r2s_step{k}) s{k}")
    sql = parts[0]
    seen = set(pattern.steps[0].names)
    for k, step in enumerate(pattern.steps[1:], start=1):
        shared = ["scene"] + [_var(names.index(n)) for n in step.names if n in seen]
        sql += f" JOIN {parts[k]} USING ({', '.join(shared)})"
        seen |= set(step.names)
    distinct = [f"{_var(i)} <> {_var(j)}" for i in range(len(names)) for j in range(i + 1, len(names))]
    where = f" WHERE {' AND '.join(distinct)}" if distinct else ""
    return f"CREATE TEMP TABLE {CANDIDATES} AS SELECT scene, {', '.join(map(_var, range(len(names))))} FROM {sql}{where}"


def ends_sql(k: int, pattern: TemporalPattern) -> str:
    """r2s_ends{k}: (scene, binding, position, timestamp) where step k can end a chain of steps 0..k."""
    step = pattern.steps[k]
    variables = range(len(pattern.names))
    allv = ", ".join(map(_var, variables))
    using = ", ".join(["scene"] + [_var(pattern.names.index(n)) for n in step.names])
    held = (f"SELECT h.scene, {', '.join('c.' + _var(j) for j in variables)}, h.frame_pos, h.timestamp_us "
            f"FROM r2s_step{k} h JOIN {CANDIDATES} c USING ({using})")
    part = f"PARTITION BY scene, {allv}"
    if k == 0:
        starts = f"s AS (SELECT *, TRUE AS ok FROM ({held}))"
    else:
        # The previous step's ends before each frame: E rows sort after step rows at the same position, so the
        # frames strictly before p are exactly the rows preceding p's.
        within = "TRUE" if step.within_us is None else f"timestamp_us - prev_t <= {step.within_us}"
        starts = (
            f"u AS (SELECT *, 0 AS kind FROM ({held}) UNION ALL "
            f"SELECT scene, {allv}, frame_pos, timestamp_us, 1 AS kind FROM r2s_ends{k - 1}), "
            f"w AS (SELECT *, max(CASE WHEN kind = 1 THEN timestamp_us END) OVER prior AS prev_t, "
            f"bool_or(kind = 1) OVER prior AS has_prev FROM u "
            f"WINDOW prior AS ({part} ORDER BY frame_pos, kind ROWS BETWEEN UNBOUNDED PRECEDING AND 1 PRECEDING)), "
            f"s AS (SELECT scene, {allv}, frame_pos, timestamp_us, coalesce(has_prev, FALSE) AND ({within}) AS ok "
            f"FROM w WHERE kind = 0)")
    lasts = "TRUE" if not step.for_at_least_us else f"timestamp_us - a_t >= {step.for_at_least_us}"
    return (
        f"CREATE TEMP TABLE r2s_ends{k} AS WITH {starts}, "
        f"i AS (SELECT *, frame_pos - row_number() OVER ({part} ORDER BY frame_pos) AS run FROM s), "
        f"a AS (SELECT *, bool_or(ok) OVER upto AS started, min(CASE WHEN ok THEN timestamp_us END) OVER upto AS a_t "
        f"FROM i WINDOW upto AS ({part}, run ORDER BY frame_pos ROWS BETWEEN UNBOUNDED PRECEDING AND CURRENT ROW)) "
        f"SELECT scene, {allv}, frame_pos, timestamp_us FROM a WHERE started AND ({lasts})"
    )


def prepare(con, pattern: TemporalPattern, config: SynthConfig, exact_check: Callable[[Pattern], None]) -> str:
    """Run the statements that build the pattern's tables in `con` (whose ROWS view exists); returns the
    `WITH m AS (...)` that the matches and events selects read. exact_check(pattern) registers the exact re-check
    UDF of a step before its query runs."""
    con.execute(f"CREATE TEMP TABLE {POSITIONS} AS SELECT scene, frame_id, ord AS frame_ord, row_number() OVER "
                f"(PARTITION BY scene ORDER BY frame_index, ord) AS frame_pos, timestamp_us FROM {ROWS} WHERE is_ego")
    con.execute(f"CREATE TEMP TABLE {IDS} AS SELECT scene, track_id, min(entity_id) AS entity_id FROM {ROWS} "
                "WHERE NOT is_ego GROUP BY scene, track_id")
    used = {(BEHAVIOUR_COLUMNS[b][0], n == EGO_ID) for s in pattern.steps for n, b in s.behaviours}
    for table, ego in sorted(used):
        con.execute(BEHAVIOUR_SQL[table](config, EGO_ROWS if ego else OTHER_ROWS, table + (EGO_SUFFIX if ego else "")))
    for k, step in enumerate(pattern.steps):
        exact_check(step.pattern)
        con.execute(step_sql(k, step.pattern, step.behaviours, pattern.names, config))
    con.execute(candidates_sql(pattern))
    for k in range(len(pattern.steps)):
        con.execute(ends_sql(k, pattern))
    names = pattern.names
    last = len(pattern.steps) - 1
    joins = " ".join(f"JOIN {IDS} i{j} ON i{j}.scene = e.scene AND i{j}.track_id = e.{_var(j)}"
                     for j in range(len(names)))
    binding = positional([f"i{j}.entity_id" for j in range(len(names))])
    tracks = positional([f"e.{_var(j)}" for j in range(len(names))])
    key = ", ".join(f"i{j}.entity_id" for j in range(len(names)))
    return (f"WITH m AS (SELECT f.frame_id, f.frame_ord, f.frame_pos, f.scene, f.timestamp_us, [{key}] AS key, "
            f"{binding} AS binding, {tracks} AS tracks "
            f"FROM r2s_ends{last} e JOIN {POSITIONS} f ON f.scene = e.scene AND f.frame_pos = e.frame_pos {joins})")


def estimate_query(pattern: TemporalPattern, config: SynthConfig, fanout: bool, per_frame: bool = False) -> str:
    """The estimate of sql.estimate_query for a temporal pattern: the steps' one-frame joins run one after another,
    so a frame's product is the largest of its steps' (sql.estimate_ctes) and the total sums every step's products
    over every frame, plus a bound on the candidate bindings of the whole pattern in each scene (candidates_sql):
    for any step j, at most (the step's bindings over the scene's frames) x (for each variable not in step j, the
    tracks of the scene that one of its statements may bind), the least over the steps. With per_frame, one row per
    frame and step (frame id, step, product)."""
    names = pattern.names
    ctes = [ego_cte(pattern.uses_lanes), ESTIMATE_FRAMES]
    for k, step in enumerate(pattern.steps):
        ctes += estimate_ctes(step.pattern, config, fanout, label=f"s{k}")
    steps = " UNION ALL ".join(f"SELECT {k} AS step, frame_id, rows, p, scene FROM s{k}"
                               for k in range(len(pattern.steps)))
    ctes.append(f"p AS ({steps})")
    if per_frame:
        return "WITH " + ",\n".join(ctes) + "\nSELECT frame_id, step, p FROM p"
    # A variable's tracks in a scene: those one step's statement for it may bind (its first step's, the rows CTE
    # s{k}_t{i} of estimate_ctes).
    for v, name in enumerate(names):
        k = next(k for k, s in enumerate(pattern.steps) if name in s.names)
        rows = f"s{k}_t{pattern.steps[k].names.index(name)}"
        ctes.append(f"r2s_v{v} AS (SELECT scene, count(DISTINCT track_id)::DOUBLE AS n FROM {rows} GROUP BY scene)")
    joins = "".join(f" LEFT JOIN r2s_v{v} USING (scene)" for v in range(len(names)))
    bounds = []
    for k, step in enumerate(pattern.steps):
        ctes.append(f"r2s_t{k} AS (SELECT scene, sum(p) AS n FROM s{k} GROUP BY scene)")
        joins += f" LEFT JOIN r2s_t{k} USING (scene)"
        bounds.append(" * ".join([f"coalesce(r2s_t{k}.n, 0)"] + [f"coalesce(r2s_v{v}.n, 0)" for v, n in
                                                                  enumerate(names) if n not in step.names]))
    least = bounds[0] if len(bounds) == 1 else f"least({', '.join(bounds)})"
    ctes.append(f"r2s_cand AS (SELECT {least} AS n FROM (SELECT DISTINCT scene FROM r2s_frames) sc{joins})")
    return "WITH " + ",\n".join(ctes) + "\n" + estimate_select("p", "SELECT coalesce(sum(n), 0) FROM r2s_cand", False)
