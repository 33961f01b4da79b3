"""The numbers of `r2s report`: a programs file or dataset in, frozen values out. No report files, no plots.

The programs are aggregated by DuckDB, streaming over the Parquet files (column projection, parallel scans,
out-of-core when a group-by outgrows memory), so a report over 10^6 frames neither loads the programs nor their
text into Python: the statistics are GROUP BY queries, and relation usage is counted in the DSL text with
substring counts (exact: ids are identifiers, never DSL keywords, and hold neither spaces nor parentheses).

A "config" is what a row was synthesized with, named by its strategy alone unless the rows mix oracles or
solvers (then "astar-cpa / smt", ...), so one programs dataset can hold several of the paper's columns. A frame
run twice under one config counts once (the last row: later file, later row).
"""

from __future__ import annotations

import os
import tempfile
from collections import Counter
from dataclasses import dataclass

import duckdb
import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from pipeline.programs import STATUSES, ProgramsError, check_programs_schema, programs_files
from synth.dsl import AbsoluteHeading, AbsoluteXYPos, DslError, parse_program
from synth.parts import HEADING, LANE, MOTION, POSITION

# Entity-count buckets (N excludes ego). Later buckets are wide because dense frames are rare and slow.
BUCKETS: tuple[tuple[int, int | None], ...] = ((0, 0), (1, 5), (6, 10), (11, 20), (21, 40), (41, 80), (81, None))
# The absolute-coordinate program declares every entity with `on Range @ Range, facing Range deg`: 2 + 2.
ABSOLUTE_COST_PER_ENTITY = AbsoluteXYPos.cost + AbsoluteHeading.cost
# Relation kinds in the order the grammar lists them (position first, then heading, then motion if any).
POSITION_KINDS = POSITION.kinds
HEADING_KINDS = HEADING.kinds
MOTION_KINDS = MOTION.kinds
LANE_KINDS = LANE.kinds
# Where the lane kinds say an entity is (the share of entities on / off lanes): in a lane (a relation to another
# entity's lane, or a lane by id), in no lane (off lane, off road), or either (an intersection or a crosswalk may
# be in a lane or not; anywhere says nothing).
ON_LANE_KINDS = ("same lane", "lane left", "lane right", "oncoming lane", "lane by id")
OFF_LANE_KINDS = ("off lane", "off road")
RELATION_KINDS = POSITION_KINDS + HEADING_KINDS
ALL = "all"
# Substrings that mark each relation in a statement `ID = new TYPE POS, HEADING` (docs/dsl.md). The
# relative position is the only `@ Range(...)` followed by `relative to`; the absolute heading is a `deg` Range
# without one. Counted with replace() arithmetic, which DuckDB runs at memory speed (a regex pass is ~10x slower).
_MARKS = {
    "ahead": " ahead of ", "behind": " behind ", "left": " left of ", "right": " right of ",
    "relative position": ") relative to ", "at": " @ ",
    "toward": "facing toward ", "away": "facing away from ", "relative heading": ") deg relative to ",
    "deg": ") deg",
    "stationary": ", stationary", "moving like": ", moving like ", "relative speed": ") m/s relative to ",
    "speed": ") m/s",
    # LANE (docs/dsl.md, "Lanes"): `in lane left of` holds " left of " too, so position's left / right subtract
    # the lane forms.
    "same lane": ", in lane of ", "lane left": " lane left of ", "lane right": " lane right of ",
    "oncoming lane": ", in oncoming lane of ", "in intersection": ", in intersection", "on crosswalk": ", on crosswalk",
    "off road": ", off road", "off lane": ", off lane", "lane by id": ', in lane "', "anywhere": ", anywhere",
}
# Points drawn per config in a scatter plot: past this, a deterministic sample (by a hash of the frame id).
PLOT_POINTS = 4000


def bucket_label(n: int) -> str:
    for lo, hi in BUCKETS:
        if n >= lo and (hi is None or n <= hi):
            return f"{lo}+" if hi is None else (str(lo) if lo == hi else f"{lo}-{hi}")
    return "?"  # negative counts: a damaged file, kept visible rather than dropped


def bucket_order(labels) -> list[str]:
    """Bucket labels in ascending order of N (labels are not sortable as text: '11-20' < '6-10')."""
    rank = {bucket_label(lo): i for i, (lo, _) in enumerate(BUCKETS)}
    return sorted(set(labels), key=lambda b: (rank.get(b, len(rank)), b))


def _bucket_sql(column: str) -> str:
    cases = " ".join(f"WHEN {column} BETWEEN {lo} AND {hi if hi is not None else 2**31 - 1} THEN "
                     f"'{bucket_label(lo)}'" for lo, hi in BUCKETS)
    return f"CASE {cases} ELSE '?' END"


def _count(column: str, mark: str) -> str:
    return f"(length({column}) - length(replace({column}, '{mark}', ''))) // {len(mark)}"


# ------------------------------------------------------------------------------------------------ the data

@dataclass(frozen=True)
class Overview:
    source: str
    rows: int  # rows read, duplicates included
    frames: int  # distinct frame ids
    configs: tuple[str, ...]  # in a stable order
    oracles: tuple[str, ...]
    solvers: tuple[str, ...]
    versions: tuple[str, ...]
    duplicates_dropped: int


class ProgramsDB:
    """A programs file or dataset directory as DuckDB table `p`: one row per (frame, config), with columns
    config, bucket, the numeric columns, the relation counts of its program, and where the row is (filename,
    file_row_number) to fetch its text later. The text columns stay in the files."""

    def __init__(self, path: str | os.PathLike, memory_limit_mb: int = 1024) -> None:
        self.source = str(path)
        self.files = programs_files(path)
        for f in self.files:
            where = f if len(self.files) > 1 else self.source
            check_programs_schema(_schema(f, where), where)
        self._tmp = tempfile.TemporaryDirectory(prefix="r2s-report-")
        self.con = duckdb.connect(config={"memory_limit": f"{memory_limit_mb}MB", "temp_directory": self._tmp.name,
                                          "threads": max(1, os.cpu_count() or 1)})
        self.con.read_parquet(self.files, filename=True, file_row_number=True, union_by_name=True).create_view("raw")
        self._check_values()
        self.overview = self._prepare()

    def close(self) -> None:
        self.con.close()
        self._tmp.cleanup()

    def __enter__(self) -> ProgramsDB:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def sql(self, query: str, params: list | None = None) -> list[tuple]:
        return self.con.execute(query, params or []).fetchall()

    def df(self, query: str, params: list | None = None) -> pd.DataFrame:
        return self.con.execute(query, params or []).df()

    def _check_values(self) -> None:
        known = ", ".join(f"'{s}'" for s in STATUSES)
        nulls, bad, rows = self.sql(
            f"SELECT [count(*) FILTER (frame_id IS NULL), count(*) FILTER (status IS NULL), "
            f"count(*) FILTER (config_hash IS NULL)], "
            f"list(DISTINCT status) FILTER (status IS NOT NULL AND status NOT IN ({known})), count(*) FROM raw")[0]
        for column, n in zip(("frame_id", "status", "config_hash"), nulls):
            if n:
                raise ProgramsError(f"{self.source}: column {column} has a missing value")
        if bad:
            raise ProgramsError(f"{self.source}: unknown status value(s) {', '.join(map(repr, sorted(bad)[:5]))}")
        self.rows = rows

    def _prepare(self) -> Overview:
        oracles, solvers = self.sql("SELECT count(DISTINCT coalesce(oracle, '?')), count(DISTINCT coalesce(solver, "
                                    "'?')) FROM raw")[0]
        config = "coalesce(strategy, '?')"
        for column, n in (("oracle", oracles), ("solver", solvers)):
            if n > 1:
                config += f" || ' / ' || coalesce({column}, '?')"
        marks = ", ".join(f"{_count('program', m)} AS \"k_{k}\"" for k, m in _MARKS.items())
        n = "coalesce(n_entities, -1)"
        casts = ", ".join(f"CAST({c} AS {t}) AS {c}" for c, t in (
            ("cost", "INTEGER"), ("lower_bound", "INTEGER"), ("runtime_s", "DOUBLE"), ("peak_rss_mb", "DOUBLE"),
            ("smt_queries", "BIGINT")))
        select = (f"SELECT frame_id, status, {config} AS config, CAST({n} AS INTEGER) AS n_entities, "
                  f"{_bucket_sql(n)} AS bucket, {casts}, error, oracle, solver, version, filename, file_row_number, "
                  f"program IS NOT NULL AS has_program, {_count('program', ' = new ')} AS statements, "
                  f"CASE WHEN coalesce(program, '') = '' THEN 0 ELSE {_count('program', chr(10))} + "
                  f"CASE WHEN right(program, 1) = chr(10) THEN 0 ELSE 1 END END AS lines, {marks} FROM raw")
        distinct = self.sql(f"SELECT count(DISTINCT (frame_id, {config})) FROM raw")[0][0]
        if distinct < self.rows:  # the last row of a (frame, config) counts: later file, then later row
            select += (f" QUALIFY row_number() OVER (PARTITION BY frame_id, {config} "
                       "ORDER BY filename DESC, file_row_number DESC) = 1")
        self.con.execute(f"CREATE TEMP TABLE p AS {select}")
        configs = tuple(r[0] for r in self.sql("SELECT DISTINCT config FROM p ORDER BY config"))

        def values(column: str) -> tuple[str, ...]:
            return tuple(r[0] for r in self.sql(f"SELECT DISTINCT {column} FROM p WHERE {column} IS NOT NULL "
                                                f"ORDER BY 1"))

        frames = self.sql("SELECT count(DISTINCT frame_id) FROM p")[0][0]
        return Overview(self.source, self.rows, frames, configs, values("oracle"), values("solver"),
                        values("version"), self.rows - distinct)


def _schema(path: str, where: str):
    try:
        return pq.ParquetFile(path).schema_arrow
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ProgramsError(f"{where} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:120]})") from None


# ------------------------------------------------------------------------------------------------ statistics

@dataclass(frozen=True)
class GroupStats:
    """One line of the statistics tables: a config (or all) within a bucket (or all)."""

    config: str
    bucket: str
    frames: int
    statuses: tuple[tuple[str, int], ...]  # every status of STATUSES, in that order
    optimal_pct: float
    mean_cost: float | None  # over frames with a program
    cost_per_entity: float | None  # mean of cost / N over frames with a program and N > 0
    absolute_ratio: float | None  # the same over 4 (the absolute program's cost per entity): 1.0 = no better
    runtime_median: float | None  # over frames that ran (errors excluded: they record no search time)
    runtime_p95: float | None
    runtime_max: float | None
    peak_rss_mb: float | None  # the largest over the group (0, as failure rows may carry, means unknown)
    smt_queries: int

    def count(self, status: str) -> int:
        return dict(self.statuses)[status]


def _stats_sql(keys: str) -> str:
    counts = ", ".join(f"count(*) FILTER (status = '{s}')" for s in STATUSES)
    ran = "status <> 'error' AND runtime_s IS NOT NULL"
    return (f"SELECT {keys}, count(*), {counts}, avg(cost), avg(cost / n_entities) FILTER (n_entities > 0), "
            f"quantile_cont(runtime_s, 0.5) FILTER ({ran}), quantile_cont(runtime_s, 0.95) FILTER ({ran}), "
            f"max(runtime_s) FILTER ({ran}), max(peak_rss_mb) FILTER (peak_rss_mb > 0), "
            f"coalesce(sum(smt_queries), 0) FROM p GROUP BY {keys}")


def _group(config: str, bucket: str, r: tuple) -> GroupStats:
    frames, *rest = r
    counts, (mean_cost, per_entity, median, p95, top, rss, smt) = rest[:len(STATUSES)], rest[len(STATUSES):]
    statuses = tuple((s, int(c)) for s, c in zip(STATUSES, counts))
    return GroupStats(config, bucket, int(frames), statuses, 100.0 * statuses[0][1] / frames if frames else 0.0,
                      mean_cost, per_entity, None if per_entity is None else per_entity / ABSOLUTE_COST_PER_ENTITY,
                      median, p95, top, rss, int(smt))


def by_config(db: ProgramsDB) -> list[GroupStats]:
    """One line per config over all its frames."""
    rows = {r[0]: r[1:] for r in db.sql(_stats_sql("config"))}
    return [_group(c, ALL, rows[c]) for c in db.overview.configs]


def by_bucket(db: ProgramsDB) -> list[GroupStats]:
    """One line per (bucket, config) that has frames, buckets in ascending N."""
    rows = {(r[0], r[1]): r[2:] for r in db.sql(_stats_sql("bucket, config"))}
    return [_group(c, b, rows[(b, c)]) for b in bucket_order(b for b, _ in rows) for c in db.overview.configs
            if (b, c) in rows]


# ------------------------------------------------------------------------------------------------ relations

@dataclass(frozen=True)
class RelationUsage:
    counts: pd.DataFrame  # index RELATION_KINDS + MOTION_KINDS + LANE_KINDS, one column per config, integer counts
    unparsable: tuple[tuple[str, str, str], ...]  # (config, frame_id, parser message) of programs not in the DSL
    unparsable_total: int = 0

    @property
    def motion(self) -> bool:
        """Do any programs say how fast their entities move?"""
        return bool(self.counts.loc[list(MOTION_KINDS)].to_numpy().sum())

    @property
    def lanes(self) -> bool:
        """Do any programs say where their entities are on the road?"""
        return bool(self.counts.loc[list(LANE_KINDS)].to_numpy().sum())

    @property
    def kinds(self) -> tuple[str, ...]:
        """The kinds to show: the paper's always, motion's and lanes' when some program has them."""
        return RELATION_KINDS + (MOTION_KINDS if self.motion else ()) + (LANE_KINDS if self.lanes else ())

    def lane_shares(self, config: str) -> dict[str, float] | None:
        """Of the entities with a lane clause under a config: the share in a lane, in no lane, and either (in an
        intersection, on a crosswalk, anywhere); None without lane clauses."""
        counts = self.counts[config]
        total = int(counts.loc[list(LANE_KINDS)].sum())
        if not total:
            return None
        on, off = int(counts.loc[list(ON_LANE_KINDS)].sum()), int(counts.loc[list(OFF_LANE_KINDS)].sum())
        return {"in a lane": on / total, "in no lane": off / total, "either": (total - on - off) / total}


def relation_kinds(program_text: str) -> Counter:
    """How often each relation kind occurs in one DSL program (parsed with the DSL's own parser)."""
    return Counter(clause.kind for s in parse_program(program_text).statements for _, clause in s.clauses())


# Programs whose text the substring counts do not account for are parsed one by one; past this many, the rest
# are listed as not counted rather than parsed (a damaged dataset, not a few odd rows).
MAX_PARSED = 10_000


def relation_usage(db: ProgramsDB, examples: int = 3) -> RelationUsage:
    """Counts per kind and config. The counts come from substrings where every line of a program is one
    statement with one position and one heading (every program r2s writes); any other program is parsed with
    the DSL's own parser, and counted if it parses, or listed with the parser's message if not."""
    k = {name: f'"k_{name}"' for name in _MARKS}
    left, right = f"({k['left']} - {k['lane left']})", f"({k['right']} - {k['lane right']})"
    lane = " + ".join(k[kind] for kind in LANE_KINDS)
    consistent = (f"statements = lines AND {k['ahead']} + {k['behind']} + {left} + {right} + {k['at']} "
                  f"= statements AND {k['toward']} + {k['away']} + {k['deg']} = statements AND "
                  f"{k['stationary']} + {k['moving like']} + {k['speed']} <= statements "  # motion is optional
                  f"AND {lane} <= statements")  # and lanes
    every = RELATION_KINDS + MOTION_KINDS + LANE_KINDS
    # Every kind with a substring of its own; an absolute form is its part's Ranges without `relative to`.
    kinds = {**{name: f"sum({k[name]})" for name in every if name in _MARKS},
             "left": f"sum({left})", "right": f"sum({right})",
             "absolute position": f"sum({k['at']} - {k['relative position']})",
             "absolute heading": f"sum({k['deg']} - {k['relative heading']})",
             "absolute speed": f"sum({k['speed']} - {k['relative speed']})"}
    rows = db.sql(f"SELECT config, {', '.join(kinds[kind] for kind in every)} FROM p "
                  f"WHERE has_program AND {consistent} GROUP BY config")
    counts = pd.DataFrame(0, index=list(every), columns=list(db.overview.configs), dtype=int)
    for config, *values in rows:
        counts[config] = [int(v or 0) for v in values]
    odd = db.sql(f"SELECT config, frame_id, filename, file_row_number FROM p WHERE has_program AND NOT ({consistent}) "
                 f"ORDER BY config, frame_id")
    texts = programs_text(db, [(f, r) for _, _, f, r in odd[:MAX_PARSED]])
    unparsable, total = [], len(odd) - len(odd[:MAX_PARSED])
    for config, frame_id, filename, row in odd[:MAX_PARSED]:
        try:
            for kind, n in relation_kinds(texts[(filename, row)]).items():
                counts.loc[kind, config] += n
        except DslError as exc:  # a damaged program must not sink the whole report; it is listed instead
            total += 1
            if len(unparsable) < examples:
                unparsable.append((config, frame_id, str(exc)))
    return RelationUsage(counts, tuple(unparsable), total)


def program_text(db: ProgramsDB, filename: str, row: int) -> str:
    return programs_text(db, [(filename, row)])[(filename, row)]


def programs_text(db: ProgramsDB, where: list[tuple[str, int]]) -> dict[tuple[str, int], str]:
    """The program column of a few rows, read from their files only."""
    out: dict[tuple[str, int], str] = {}
    for filename in sorted({f for f, _ in where}):
        rows = sorted(r for f, r in where if f == filename)
        got = db.con.execute("SELECT file_row_number, program FROM read_parquet(?, file_row_number = true) "
                             "WHERE file_row_number IN (SELECT unnest(?))", [filename, rows]).fetchall()
        out.update({(filename, r): text for r, text in got})
    return out


# ------------------------------------------------------------------------------------------------ failures

@dataclass(frozen=True)
class FailureGroup:
    """Frames that failed the same way under one config: listed once, with a few examples."""

    config: str
    status: str
    message: str
    frames: int
    examples: tuple[str, ...]


def failures(db: ProgramsDB, examples: int = 3) -> list[FailureGroup]:
    """Error rows (and any other row carrying an error message), grouped by config, status and message."""
    rows = db.sql(
        "SELECT config, status, message, count(*), list(frame_id ORDER BY frame_id)[1:?] FROM ("
        "  SELECT config, status, frame_id, "
        "  left(split_part(coalesce(error, '(no message)'), chr(10), 1), 200) AS message FROM p "
        "  WHERE status = 'error' OR error IS NOT NULL) GROUP BY ALL", [examples])
    groups = [FailureGroup(c, s, m, int(n), tuple(ids)) for c, s, m, n, ids in rows]
    return sorted(groups, key=lambda f: (-f.frames, f.config, f.status, f.message))


# ------------------------------------------------------------------------------------------------ table 3

@dataclass(frozen=True)
class SideBySide:
    """The paper's Table 3: one row per frame (by N), one (time, memory) pair of cells per config."""

    frames: pd.DataFrame  # columns frame_id, n_entities; rows in ascending N
    status: pd.DataFrame  # frame x config -> status (NaN: the config did not run the frame)
    runtime_s: pd.DataFrame
    peak_rss_mb: pd.DataFrame
    total_frames: int  # before sampling down to max_rows


def side_by_side(db: ProgramsDB, max_rows: int = 40) -> SideBySide:
    """Pivot; with more than max_rows frames keep an even spread over the N order (first and last always)."""
    total = db.overview.frames
    keep = sorted(set(np.linspace(0, total - 1, min(max_rows, total)).round().astype(int).tolist()))
    frames = db.df("SELECT frame_id, n_entities FROM (SELECT frame_id, max(n_entities) AS n_entities, "
                   "row_number() OVER (ORDER BY max(n_entities), frame_id) - 1 AS pos FROM p GROUP BY frame_id) "
                   "WHERE pos IN (SELECT unnest(?)) ORDER BY pos", [keep])
    cells = db.df("SELECT frame_id, config, status, runtime_s, peak_rss_mb FROM p "
                  "WHERE frame_id IN (SELECT unnest(?))", [frames["frame_id"].tolist()])

    def pivot(col: str) -> pd.DataFrame:
        return cells.pivot(index="frame_id", columns="config", values=col).reindex(
            index=frames["frame_id"], columns=list(db.overview.configs))

    return SideBySide(frames, pivot("status"), pivot("runtime_s"), pivot("peak_rss_mb"), total)


# ------------------------------------------------------------------------------------------------ frames to look at

@dataclass(frozen=True)
class LookFrame:
    """A frame worth a look, why, and what to render it with."""

    reason: str
    frame_id: str
    config: str
    status: str
    n_entities: int
    cost: int | None
    lower_bound: int | None
    runtime_s: float | None
    error: str | None
    program: str | None


LOOK_REASONS = (
    ("largest cost", "cost IS NOT NULL", "cost DESC, n_entities DESC"),
    ("slowest", "runtime_s IS NOT NULL AND status <> 'error'", "runtime_s DESC"),
    ("feasible (stopped, not proven)", "status = 'feasible'", "cost - lower_bound DESC NULLS LAST, n_entities DESC"),
    ("timeout", "status = 'timeout'", "n_entities DESC"),
    ("memout", "status = 'memout'", "n_entities DESC"),
    ("error", "status = 'error'", "n_entities DESC"),
)


def frames_to_look_at(db: ProgramsDB, per_reason: int = 3) -> list[LookFrame]:
    """A few frames per reason (largest cost, slowest, each way of stopping short), each frame once."""
    picked, seen = [], set()
    for reason, where, order in LOOK_REASONS:
        rows = db.sql(f"SELECT frame_id, config, status, n_entities, cost, lower_bound, runtime_s, error, filename, "
                      f"file_row_number FROM p WHERE {where} ORDER BY {order}, frame_id, config LIMIT ?",
                      [per_reason + len(seen)])
        for r in [r for r in rows if (r[0], r[1]) not in seen][:per_reason]:
            seen.add((r[0], r[1]))
            picked.append((reason, r))
    texts = programs_text(db, [(r[8], r[9]) for _, r in picked])
    return [LookFrame(reason, r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], texts.get((r[8], r[9])))
            for reason, r in picked]


# ------------------------------------------------------------------------------------------------ plot data

def plot_points(db: ProgramsDB, limit: int = PLOT_POINTS) -> tuple[pd.DataFrame, dict[str, int]]:
    """Up to `limit` rows per config for the scatter plots (all of them when there are fewer), chosen by a hash of
    the frame id, so the same frames are drawn for every config and every run; and the rows each config has."""
    points = db.df("SELECT config, status, n_entities, runtime_s, cost FROM p "
                   "QUALIFY row_number() OVER (PARTITION BY config ORDER BY hash(frame_id), frame_id) <= ? "
                   "ORDER BY config, hash(frame_id), frame_id", [limit])
    totals = dict(db.sql("SELECT config, count(*) FROM p GROUP BY config"))
    return points, totals


def per_n(db: ProgramsDB) -> pd.DataFrame:
    """Median runtime (frames that ran) and mean cost per (config, N), over every row."""
    return db.df("SELECT config, n_entities, quantile_cont(runtime_s, 0.5) FILTER (status <> 'error' AND runtime_s "
                 "IS NOT NULL) AS runtime_median, avg(cost) AS mean_cost FROM p GROUP BY config, n_entities "
                 "ORDER BY config, n_entities")


def cost_counts(db: ProgramsDB) -> pd.DataFrame:
    """How many rows have each (config, cost, N): the histograms are binned from these few thousand counts."""
    return db.df("SELECT config, cost, n_entities, count(*) AS rows FROM p WHERE cost IS NOT NULL GROUP BY ALL "
                 "ORDER BY ALL")

