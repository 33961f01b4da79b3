"""Temporal patterns over a frames dataset (synth.patterns.temporal; the definition is docs/dsl.md, "Temporal patterns"),
as DuckDB statements run one after another in the query's session.

1. Each step is a one-frame pattern: its bindings in every frame come from the one-frame query
   (pipeline.query.sql.bindings_query, with its exact re-check of near-boundary candidates), keyed by the tracks
   they bind. Behaviours filter them: computed only for the tracks those steps bind (r2s_watched; ego in the
   scenes where a step asks for ego's), in one pass of windows over each such track's own rows (behaviours(): one
   entry per behaviour, a column of r2s_behaviour).
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
from dataclasses import dataclass

from pipeline.query.lanes import SIDE_PAIRS
from pipeline.query.sql import (
    ESTIMATE_FRAMES,
    ROWS,
    Chunk,
    ego_cte,
    estimate_ctes,
    estimate_select,
    materialize,
    positional,
)
from synth.config import SynthConfig
from synth.parts.motion import SPEED_EPS
from synth.patterns.one_frame import Pattern
from synth.patterns.temporal import (
    LANE_CHANGE_WINDOW_US,
    MOVING_SPEED,
    SPEED_CHANGE,
    SPEED_CHANGE_WINDOW_US,
    STOP_WINDOW_US,
    TURN_ANGLE,
    TURN_WINDOW_US,
    Step,
    TemporalPattern,
)
from synth.scene import EGO_ID

POSITIONS = "r2s_fpos"
BEHAVIOUR_TABLE = "r2s_behaviour"
WATCHED = "r2s_watched"
IDS = "r2s_ids"
CANDIDATES = "r2s_candidates"
BEHAVING = "r2s_b"  # the alias of a watched row with its window aggregates, where a behaviour's test reads them


def _var(k: int) -> str:
    # The track column of the pattern's k-th variable (TemporalPattern.names): by position, as sql.positional keys
    # structs (DuckDB's column names ignore case, the pattern's names do not), and prefixed (never `scene`).
    return f'"v{k}"'


def _lit(v: float) -> str:
    return f"'{float(v)!r}'::DOUBLE"


@dataclass(frozen=True)
class Behaviour:
    """How a behaviour is read from a track's own rows: `aggregates`, window aggregates over the track's earlier
    rows (alias -> SQL, over a window of WINDOWS), and `holds`, the condition on the row and those aliases. NULL
    (no earlier row, no speed, no finite heading, no lane) counts as false."""

    aggregates: tuple[tuple[str, str], ...]
    holds: str


def _window(width_us: int, by: str = "") -> str:
    # A track's rows of the same scene (ego's: is_ego, its track_id nulled, one track a scene) whose timestamp is
    # within width_us before the row's (RANGE over the integer timestamps: rows at the same timestamp are not
    # earlier).
    return (f"PARTITION BY scene, is_ego, track_id{by} ORDER BY timestamp_us RANGE BETWEEN {width_us} PRECEDING "
            "AND 1 PRECEDING")


WINDOWS = {"change": _window(SPEED_CHANGE_WINDOW_US), "stop": _window(STOP_WINDOW_US), "turn": _window(TURN_WINDOW_US),
           "lane": _window(LANE_CHANGE_WINDOW_US, ", map_id")}


def behaviours(config: SynthConfig) -> dict[str, Behaviour]:
    """Every behaviour's reading (synth.patterns.temporal.BEHAVIOURS; docs/dsl.md defines them). Exact: for the speed
    behaviours the extreme speed of the window decides, and IEEE subtraction is monotone, so `v - min(v') >= A` iff
    some v' has `v - v' >= A`; headings wrap, so turning compares every earlier finite heading of the window (a
    list) by synth.patterns.temporal.turn_of's operations on map_heading (r2s_norm is synth.geometry.normalize);
    changing lanes collects the earlier in-lane rows' lanes of the same map, and the row's lane must be left or
    right of one of them (`rel_left`, `rel_right` of pipeline.query.lanes, LaneGraph.related of their lane, as
    rows of SIDE_PAIRS): the lookup of `in lane left of`."""
    turn = "r2s_norm(map_heading - q + 180.0) - 180.0"
    headings = ("r2s_headings", "list(map_heading) FILTER (WHERE isfinite(map_heading)) OVER turn")

    def turning(test: str) -> Behaviour:
        return Behaviour((headings,), f"isfinite(map_heading) AND list_bool_or(list_transform(r2s_headings, "
                                      f"lambda q: {test}))")

    # The distinct earlier lanes (a track keeps its lane for many rows: one or two a window), then the lanes left
    # or right of them as rows of SIDE_PAIRS: the same set as the union of their relation lists, without building
    # that union for every row (8x faster on a 10^5-frame replica of the shipped Argoverse 2 log).
    earlier = ("r2s_earlier_lanes", "list(DISTINCT lane) FILTER (WHERE lane IS NOT NULL) OVER lane")
    beside = (f"lane IS NOT NULL AND EXISTS (SELECT 1 FROM {SIDE_PAIRS} p WHERE p.map_id = {BEHAVING}.map_id "
              f"AND p.to_lane = {BEHAVING}.lane AND list_contains({BEHAVING}.r2s_earlier_lanes, p.from_lane))")
    return {
        "accelerating": Behaviour((("r2s_min_1s", "min(speed) OVER change"),),
                                  f"speed - r2s_min_1s >= {_lit(SPEED_CHANGE)}"),
        "braking": Behaviour((("r2s_max_1s", "max(speed) OVER change"),), f"r2s_max_1s - speed >= {_lit(SPEED_CHANGE)}"),
        "stopping": Behaviour((("r2s_max_3s", "max(speed) OVER stop"),),
                              f"speed <= {_lit(config.v_stop + SPEED_EPS)} AND r2s_max_3s >= {_lit(MOVING_SPEED)}"),
        "turning left": turning(f"{turn} >= {_lit(TURN_ANGLE)}"),
        "turning right": turning(f"{turn} <= {_lit(-TURN_ANGLE)}"),
        "changing lanes": Behaviour((earlier,), beside),
    }


def _column(behaviour: str) -> str:
    return '"' + behaviour.replace(" ", "_") + '"'


def watched_sql(pattern: TemporalPattern) -> str:
    """The tracks (scene, is_ego, track_id; ego's track_id null) whose behaviours a step asks for, among those the
    step binds (ego: in the scenes where the step holds): only their rows are read for behaviours (a track's
    behaviour at a frame reads its own rows, whichever bindings they are in)."""
    def track(n: str) -> str:
        return "TRUE AS is_ego, NULL AS track_id" if n == EGO_ID else f"FALSE AS is_ego, {_var(pattern.names.index(n))} AS track_id"
    parts = [f"SELECT DISTINCT scene, {track(n)} FROM r2s_held{k}"
             for k, step in enumerate(pattern.steps) for n in dict.fromkeys(n for n, _ in step.behaviours)]
    return f"CREATE TEMP TABLE {WATCHED} AS SELECT DISTINCT scene, is_ego, track_id FROM ({' UNION ALL '.join(parts)})"


def behaviour_sql(used: list[str], config: SynthConfig) -> str:
    """One row per row of a watched track (with a timestamp): frame_id, is_ego, track_id (null for ego) and a column
    per used behaviour, computed in one pass of windows over the track's own rows in the scene."""
    table = behaviours(config)
    aggregates = dict(a for b in used for a in table[b].aggregates)
    windows = ", ".join(f"{name} AS ({WINDOWS[name]})" for name in WINDOWS
                        if any(f"OVER {name}" in sql for sql in aggregates.values()))
    # Every column of the rows (DuckDB reads only those used), so a behaviour may read any of them; ego's rows are
    # one track of the scene whatever their track_id.
    rows = (f"SELECT * REPLACE (CASE WHEN is_ego THEN NULL ELSE track_id END AS track_id) FROM {ROWS} "
            "WHERE timestamp_us IS NOT NULL")
    inner = (f"SELECT r.*, {', '.join(f'{sql} AS {alias}' for alias, sql in aggregates.items())} "
             f"FROM ({rows}) r SEMI JOIN {WATCHED} w ON w.scene = r.scene AND w.is_ego = r.is_ego "
             f"AND w.track_id IS NOT DISTINCT FROM r.track_id WINDOW {windows}")
    columns = ", ".join(f"coalesce({table[b].holds}, FALSE) AS {_column(b)}" for b in used)
    return (f"CREATE TEMP TABLE {BEHAVIOUR_TABLE} AS SELECT frame_id, is_ego, track_id, {columns} "
            f"FROM ({inner}) {BEHAVING}")


def step_select(k: int, pattern: Pattern, with_frame: bool, variables: tuple[str, ...]) -> tuple[str, str]:
    """The table and the SELECT over the bindings relation m of step k (sql.materialize): the frames (scene,
    position, timestamp) and track tuples at which its statements hold (its tracks struct is keyed by the step's
    positions, its columns by the positions of the whole pattern's `variables`), r2s_step{k}, or, when the step
    has behaviours to filter by, r2s_held{k} with each frame's id. DISTINCT per chunk of frames is DISTINCT over
    all: a row is of one frame."""
    cols = ", ".join(f'm.tracks."{j}" AS {_var(variables.index(n))}' for j, n in enumerate(pattern.names))
    table, frame = (f"r2s_held{k}", "m.frame_id, ") if with_frame else (f"r2s_step{k}", "")
    return table, f"SELECT DISTINCT m.scene, {frame}m.frame_pos, m.timestamp_us, {cols} FROM m"


def behaving_sql(k: int, step: Step, variables: tuple[str, ...]) -> str:
    """r2s_step{k}: the rows of r2s_held{k} whose variables (and ego) show the step's behaviours in that frame (any
    row of the track in the frame, should a frames file give a track two)."""
    def track(n: str) -> str:
        return "x.is_ego" if n == EGO_ID else f"NOT x.is_ego AND x.track_id = h.{_var(variables.index(n))}"
    tests = " AND ".join(f"EXISTS (SELECT 1 FROM {BEHAVIOUR_TABLE} x WHERE x.frame_id = h.frame_id AND {track(n)} "
                         f"AND x.{_column(b)})" for n, b in step.behaviours)
    cols = ", ".join(f"h.{_var(variables.index(n))}" for n in step.names)
    return (f"CREATE TEMP TABLE r2s_step{k} AS SELECT h.scene, h.frame_pos, h.timestamp_us, {cols} "
            f"FROM r2s_held{k} h WHERE {tests}")


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


def prepare(con, pattern: TemporalPattern, config: SynthConfig, exact_check: Callable[[Pattern], None],
            chunks: list[Chunk]) -> str:
    """Run the statements that build the pattern's tables in `con` (whose ROWS view and EGO_TABLE, cut into
    `chunks`, exist: sql.frame_chunks); returns the `WITH m AS (...)` that the matches and events selects read.
    exact_check(pattern) registers the exact re-check UDF of a step before its query runs."""
    con.execute(f"CREATE TEMP TABLE {POSITIONS} AS SELECT scene, frame_id, ord AS frame_ord, row_number() OVER "
                f"(PARTITION BY scene ORDER BY frame_index, ord) AS frame_pos, timestamp_us FROM {ROWS} WHERE is_ego")
    con.execute(f"CREATE TEMP TABLE {IDS} AS SELECT scene, track_id, min(entity_id) AS entity_id FROM {ROWS} "
                "WHERE NOT is_ego GROUP BY scene, track_id")
    for k, step in enumerate(pattern.steps):
        exact_check(step.pattern)
        materialize(con, step.pattern, config, chunks,
                    *step_select(k, step.pattern, bool(step.behaviours), pattern.names))
    # Behaviours only of the tracks the steps that ask for them bind (few, next to every track of the frames).
    used = list(dict.fromkeys(b for s in pattern.steps for _, b in s.behaviours))
    if used:
        con.execute(watched_sql(pattern))
        con.execute(behaviour_sql(used, config))
        for k, step in enumerate(pattern.steps):
            if step.behaviours:
                con.execute(behaving_sql(k, step, pattern.names))
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
