"""Scenario mining: every frame of a frames dataset that matches a pattern (synth.patterns.one_frame), through DuckDB.

The pattern becomes one query (pipeline.query.sql); this module owns the I/O around it: the input (a frames file or
dataset, checked by frames.dataset as every verb checks it), the DuckDB session (threads, memory limit,
a spill directory), the exact re-check of near-boundary bindings in Python, and the atomic, streaming write of
matches.parquet.

matches.parquet: frame_id, scene, timestamp_us, n_matches (distinct bindings in the frame), binding; one row per
matching frame (binding: the first, in lexicographic order of the entities' input rows, i.e. the nearest for
extracted frames), or with all_bindings one row per binding. `binding` is a struct with one string field per pattern
name, in declaration order: its keys are the same on every row, so a struct is the typed form of the name -> entity
map (pandas gives a dict, DuckDB `binding.ped`, polars `.struct.field("ped")`) where a Parquet MAP reads back as a
list of pairs and a JSON string needs parsing.
"""

from __future__ import annotations

import os
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Sequence
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import duckdb
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from frames.dataset import FramesDataset
from frames.maps import maps_dir, read_maps
from frames.rows import FramesError, write_frames
from frames.schema import ROAD_COLUMNS
from pipeline.errors import UserError
from pipeline.outputs import output_place
from pipeline.query.events import events_select
from pipeline.query.lanes import FACT_COLUMNS, LANE_SETS, RELATION_COLUMNS, lane_sets, side_pairs_sql, without_lanes
from pipeline.query.notes import absent_types_note
from pipeline.query.sql import (
    EXACT_UDF,
    MACROS,
    ORD_FILE,
    ROW_COLUMNS,
    ROWS,
    WILD_HEADING,
    WILD_XY,
    estimate_query,
    frame_chunks,
    matches_select,
    materialize,
)
from pipeline.query.stop import leftover
from pipeline.query.temporal import estimate_query as temporal_estimate_query
from pipeline.query.temporal import prepare
from storage.atomic import atomic_path
from synth.config import SynthConfig
from synth.patterns.one_frame import MAX_NAMES, Pattern, binding_holds, matched_types
from synth.patterns.temporal import MAX_STEPS, TURNING, TemporalPattern, parse_query_pattern
from synth.scene import EGO_ID, Entity

BATCH_ROWS = 65536
LOG_EVERY_S = 30.0
# The bounds of a query (docs/cli.md, "Inputs and their bounds"). A pattern's names are joined per frame, so
# names related neither to each other nor to ego multiply: four unrelated `Object` names over the 141 entities
# of the largest shipped nuScenes frame are 4 x 10^8 candidate bindings in that one frame. The join's candidates
# are estimated before it runs (sql.estimate_query, temporal.estimate_query) and the query is refused beyond
# MAX_FRAME_BINDINGS in a frame or MAX_BINDINGS in all (about 10 minutes of DuckDB on 2 cores at the ~1.5 million
# a second measured for unrelated names). DuckDB plans every name as a join, so their number is bounded too; the
# spill under the memory limit is capped.
MAX_PATTERN_NAMES = MAX_NAMES  # synth.patterns.one_frame refuses more as it reads them; a Pattern built in code is checked here
MAX_FRAME_BINDINGS = 10**6
MAX_BINDINGS = 10**9
SPILL_LIMIT_MB = 8192
BINDINGS_TABLE = "r2s_m"
# Without --memory-limit DuckDB's own default (80% of RAM) let its buffer pool grow past what a chunk of frames needs
# (pipeline.query.sql.CHUNK_FRAMES): queue-of-three at 10^6 frames peaked at 4,736 MB RSS; under 3072 MB, 3,303 MB for
# 6-10% more CPU (bench/results/query.md). A machine with less RAM keeps DuckDB's 80%.
DEFAULT_MEMORY_LIMIT_MB = 3072


def default_memory_limit_mb() -> int:
    """The memory limit of a query without --memory-limit: DEFAULT_MEMORY_LIMIT_MB, or 80% of RAM if that is less."""
    ram_mb = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2**20
    return min(DEFAULT_MEMORY_LIMIT_MB, ram_mb * 8 // 10)


@dataclass(frozen=True)
class QuerySummary:
    frames_scanned: int
    frames_matched: int
    bindings: int
    checked_exactly: int  # candidate bindings near a boundary, decided by synth.semantics in Python
    seconds: float
    events: int | None = None  # with events: the events written (frames_matched and bindings are then 0)

    def line(self) -> str:
        if self.events is not None:
            return f"{self.frames_scanned} frames scanned, {self.events} events, {self.seconds:.2f} s"
        return (f"{self.frames_scanned} frames scanned, {self.frames_matched} matched ({self.bindings} bindings), "
                f"{self.seconds:.2f} s")


def _sql_list(files: Sequence[str]) -> str:
    return "[" + ", ".join("'" + f.replace("'", "''") + "'" for f in files) + "]"


def _open(files: Sequence[str], has_speed: bool, threads: int | None, memory_limit_mb: int | None, spill_dir: str,
          lane_sets: pa.Table | None = None, has_world: bool = False):
    """A DuckDB session with the rows view of the files (with lane_sets, each row's lane facts and relation lists:
    pipeline.query.lanes; map_heading, the heading in the world, where has_world)."""
    con = duckdb.connect(config={"threads": threads or os.cpu_count() or 1, "temp_directory": spill_dir,
                                 "max_temp_directory_size": f"{SPILL_LIMIT_MB}MiB",
                                 "memory_limit": f"{memory_limit_mb or default_memory_limit_mb()}MB"})
    # Progress is tracked for _Progress, never printed by DuckDB itself (it would write to stdout).
    con.execute("SET enable_progress_bar = true")
    con.execute("SET enable_progress_bar_print = false")
    source = f"read_parquet({_sql_list(files)}, file_row_number = true, union_by_name = true)"
    lane_columns, lane_join = "", ""
    if lane_sets is not None:
        con.register("r2s_lane_sets_arrow", lane_sets)
        con.execute(f"CREATE TEMP TABLE {LANE_SETS} AS SELECT * FROM r2s_lane_sets_arrow")
        con.unregister("r2s_lane_sets_arrow")
        con.execute(side_pairs_sql())
        lane_columns = "".join(f"src.{c}, " for c in FACT_COLUMNS) + "".join(f"ls.{c}, " for c in RELATION_COLUMNS)
        lane_join = f" LEFT JOIN {LANE_SETS} ls ON ls.map_id = src.map_id AND ls.lane = src.lane"
    # ord, the row ordinal (file number, then row in the file), orders frames and bindings deterministically.
    # speed is optional (frames of sources without velocities lack it): unknown is NULL, as in a file that has it.
    con.execute(
        f"CREATE TEMP VIEW {ROWS} AS SELECT hash(frame_id) AS fk, frame_id, scene, frame_index, timestamp_us, "
        f"entity_id, track_id, type, "
        f"x, y, heading, {'speed' if has_speed else 'NULL::DOUBLE AS speed'}, "
        f"{'map_heading' if has_world else 'NULL::DOUBLE AS map_heading'}, is_ego, "
        f"file_index::BIGINT * {ORD_FILE} + file_row_number AS ord, file_index AS r2s_file, "
        f"file_row_number AS r2s_row, {ROW_COLUMNS}, "
        f"{lane_columns}"
        f"NOT (abs(x) <= {WILD_XY} AND abs(y) <= {WILD_XY} AND abs(heading) <= {WILD_HEADING}) AS wild "
        f"FROM {source} src{lane_join}")
    for macro in MACROS:
        con.execute(macro)
    return con


class _Named:
    """The query's batches with their name-keyed structs (binding, tracks) keyed by the pattern's names: the query
    keys them by position (sql.positional: DuckDB's field names ignore case, the pattern's names do not)."""

    def __init__(self, reader, names: tuple[str, ...]):
        self.reader, self.names = reader, names
        fields = [pa.field(n, pa.string()) for n in names]
        schema = reader.schema
        self.columns = [i for i, f in enumerate(schema) if f.name in ("binding", "tracks")]
        for i in self.columns:
            typed = pa.struct([f.with_type(schema.field(i).type.field(k).type) for k, f in enumerate(fields)])
            schema = schema.set(i, pa.field(schema.field(i).name, typed))
        self.schema = schema

    def __iter__(self):
        for batch in self.reader:
            arrays = list(batch.columns)
            for i in self.columns:
                column = arrays[i]
                arrays[i] = pa.StructArray.from_arrays([column.field(k) for k in range(len(self.names))],
                                                       fields=list(self.schema.field(i).type), mask=column.is_null())
            yield pa.RecordBatch.from_arrays(arrays, schema=self.schema)


def _write_matches(reader, path: Path) -> tuple[int, int]:
    """Stream the query's batches into Parquet; returns (frames matched, bindings)."""
    frames_matched = bindings = 0
    last = None
    with pq.ParquetWriter(path, reader.schema, compression="zstd") as writer:
        for batch in reader:
            writer.write_batch(batch)
            # Rows of a frame are consecutive (ordered by frame), each carrying the frame's count.
            for fid, n in zip(batch.column("frame_id").to_pylist(), batch.column("n_matches").to_pylist()):
                if fid != last:
                    frames_matched, bindings, last = frames_matched + 1, bindings + n, fid
    return frames_matched, bindings


def _write_rows(reader, path: Path) -> int:
    """Stream the query's batches into Parquet; returns the rows written."""
    rows = 0
    with pq.ParquetWriter(path, reader.schema, compression="zstd") as writer:
        for batch in reader:
            writer.write_batch(batch)
            rows += batch.num_rows
    return rows


class _ExactCheck:
    """The Python UDF: is a candidate binding a match by synth.semantics? Its arguments: the numbers (ego x, y,
    heading, speed, then the same per name; a speed may be None) and the types (per name), as two lists."""

    def __init__(self, pattern: Pattern, config: SynthConfig):
        self.pattern, self.config, self.calls = pattern, config, 0

    def __call__(self, numbers, types):
        names = self.pattern.names
        out = []
        for v, t in zip(numbers.to_pylist(), types.to_pylist()):
            ego = Entity(EGO_ID, "Car", v[0], v[1], v[2], speed=v[3])
            binding = {n: Entity(n, t[i], *v[4 + 4 * i: 7 + 4 * i], speed=v[7 + 4 * i]) for i, n in enumerate(names)}
            out.append(binding_holds(self.pattern, ego, binding, self.config))
        self.calls += len(out)
        return pa.array(out, pa.bool_())


class _Progress:
    """DuckDB's own progress of the running query: a tqdm bar on a terminal, else a log line every LOG_EVERY_S."""

    def __init__(self, con, log: Callable[[str], None]):
        self.con, self.log, self.stop = con, log, threading.Event()
        self.thread = threading.Thread(target=self._poll, daemon=True)

    def __enter__(self):
        self.thread.start()
        return self

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join()

    def _poll(self) -> None:
        tty = sys.stderr.isatty()
        bar = tqdm(total=100, desc="r2s query", unit="%", file=sys.stderr, disable=not tty, leave=False)
        t0 = last = time.monotonic()
        while not self.stop.wait(0.5):
            pct = self.con.query_progress()
            if pct < 0:
                continue
            bar.n = int(pct)
            bar.refresh()
            if not tty and time.monotonic() - last >= LOG_EVERY_S:
                last = time.monotonic()
                self.log(f"r2s query: {pct:.0f}% after {last - t0:.0f} s")
        bar.close()


def _check_size(con, estimate: Callable[[bool], list[str]]) -> None:
    """Refuse (exit 2, one line) a pattern whose join may meet more candidate bindings than the bounds: the
    per-type product first (one scan), and only when it is over, the tighter product with pairwise fan-outs. An
    estimate is one query or one per chunk of frames (the largest of their products, the sum of their totals)."""
    for fanout in (False, True):
        parts = [con.execute(sql).fetchall()[0] for sql in estimate(fanout)]
        worst, frame, rows, _ = max(parts, key=lambda p: p[0] or 0.0)
        worst, total = worst or 0.0, sum(p[3] or 0.0 for p in parts)
        if worst <= MAX_FRAME_BINDINGS and total <= MAX_BINDINGS:
            return
    if worst > MAX_FRAME_BINDINGS:
        raise UserError(f"the pattern may meet {worst:.3g} candidate bindings in frame {frame} ({rows} entities), "
                        f"more than the bound of {MAX_FRAME_BINDINGS:.0e} a frame: relate its names to each other "
                        "or to ego (docs/cli.md, Inputs and their bounds)")
    raise UserError(f"the pattern may meet {total:.3g} candidate bindings over the frames, more than the bound of "
                    f"{MAX_BINDINGS:.0e}: relate its names to each other or to ego, or query fewer frames "
                    "(docs/cli.md, Inputs and their bounds)")


def estimate_bound(pattern: Pattern | TemporalPattern, largest_frame: int, rows: int) -> tuple[int, int] | None:
    """A bound on the estimate of _check_size (its largest product in a frame, its total) that needs no query, or
    None. A name binds at most the R non-ego rows of its frame (R: the largest frame's rows less ego's), so a step of
    n names meets at most R^n candidates in a frame and N R^(n - 1) over all (N: the rows); a temporal pattern's
    candidate bindings in a scene are at most the bindings there of a step that names every variable (None when no
    step does). Within the bounds, the estimate is too, and need not run: it costs a join of the frames (the steps'
    own, again), and a pattern of one name a step is never refused. The estimate adds each name's pairs with its
    anchor (sql.pairs_cte): at most R^2 in a frame, N R over all, for each of the n - 1 names after the first."""
    r = max(largest_frame - 1, 0)
    steps = [s.pattern for s in pattern.steps] if isinstance(pattern, TemporalPattern) else [pattern]
    sizes = [len(p.names) for p in steps]
    total = sum(rows * r ** (n - 1) + (n - 1) * rows * r for n in sizes)
    if isinstance(pattern, TemporalPattern):
        whole = [n for n in sizes if n == len(pattern.names)]
        if not whole:
            return None
        total += rows * r ** (min(whole) - 1)
    return max(r ** n + (n - 1) * r * r for n in sizes), total


def _surely_within(bound: tuple[int, int] | None) -> bool:
    return bound is not None and bound[0] <= MAX_FRAME_BINDINGS and bound[1] <= MAX_BINDINGS


def check_pattern_size(pattern: Pattern | TemporalPattern, steps: int) -> None:
    """The bound on a pattern's size, before any frame is read: each name is a join, each step a query."""
    if len(pattern.names) > MAX_PATTERN_NAMES:
        raise UserError(f"the pattern declares {len(pattern.names)} names, more than the bound of "
                        f"{MAX_PATTERN_NAMES} (docs/cli.md, Inputs and their bounds)")
    if steps > MAX_STEPS:
        raise UserError(f"the pattern has {steps} steps, more than the bound of {MAX_STEPS} "
                        "(docs/cli.md, Inputs and their bounds)")


def _parents(out: Path) -> list[Path]:
    """The folders above `out` that do not exist yet, outermost first."""
    missing = []
    for folder in out.parents:
        if folder.exists():
            break
        missing.append(folder)
    return missing[::-1]


def _is_interrupt(exc: BaseException) -> bool:
    return isinstance(exc, duckdb.InterruptException) or "interrupted" in str(exc).lower()[:100]


def query_frames(frames: str | os.PathLike, pattern: Pattern | TemporalPattern, out: str | os.PathLike, *,
                 all_bindings: bool = False, config: SynthConfig | None = None, threads: int | None = None,
                 memory_limit_mb: int | None = None, events: bool = False, min_duration_s: float | None = None,
                 log: Callable[[str], None] = lambda s: print(s, file=sys.stderr)) -> QuerySummary:
    """Write matches.parquet (atomically) for `pattern` over a frames file or dataset, or with events one row per
    event (pipeline.query.events; min_duration_s keeps the events at least that long, and needs every frame's
    timestamp); bad input is a FramesError, a pattern over the bounds or a query beyond its memory and spill a
    UserError. Whatever fails leaves nothing it made: no folder, spill or temporary file (and with
    pipeline.query.stop, not on a signal either)."""
    t0 = time.monotonic()
    config = config or SynthConfig()
    temporal = isinstance(pattern, TemporalPattern)  # the one place the two kinds of pattern part ways
    check_pattern_size(pattern, len(pattern.steps) if temporal else 1)
    dataset = FramesDataset.open(frames)
    if dataset.url:
        raise FramesError(f"{frames}: r2s query reads frames on a local filesystem (copy them here first)")
    has_speed = any("speed" in part.optional for part in dataset.parts)
    if pattern.uses_motion and not has_speed:
        raise FramesError(f"{frames} has no speed column: the pattern's motion clauses (or behaviours) need one")
    # The frames contract, as every verb checks it (one streaming pass; the same one-line messages).
    checked = dataset.check()
    n_frames = checked.frames
    quick = _surely_within(estimate_bound(pattern, checked.largest, sum(part.rows for part in dataset.parts)))
    if min_duration_s is not None and not events:
        raise UserError("--min-duration is a length of events: it needs --events")
    if events and all_bindings:
        raise UserError("--events and --all are two outputs: choose one")
    # Lane clauses (in any step) and `changing lanes` read the lane relations of the frames' maps.
    sets = _lane_sets(frames, dataset) if pattern.uses_lanes else None
    select = events_select(min_duration_s) if events else matches_select(all_bindings)
    out = output_place(out)  # a link is written through: the folders made and the spill are beside its file
    created = []
    try:
        for folder in _parents(out):
            folder.mkdir()
            created.append(folder)
        with ExitStack() as stack:
            for folder in created:
                stack.enter_context(leftover(folder, "folder"))
            n_events, matched, bindings, calls = _run(dataset, frames, pattern, temporal, config, select, events,
                                                      out, has_speed, threads, memory_limit_mb, min_duration_s, log,
                                                      sets, quick)
    except BaseException:
        for folder in reversed(created):  # only the folders this query made, and only while empty
            try:
                folder.rmdir()
            except OSError:
                pass
        raise
    return QuerySummary(n_frames, matched, bindings, calls, time.monotonic() - t0, n_events)


def _run(dataset, frames, pattern, temporal: bool, config: SynthConfig, select: str, events: bool, out: Path, has_speed: bool,
         threads, memory_limit_mb, min_duration_s, log, sets: pa.Table | None = None,
         quick: bool = False) -> tuple[int | None, int, int, int]:
    """The query in its DuckDB session, its spill folder beside `out`; returns (events, frames matched, bindings,
    exact checks). quick: the pattern is surely within the bounds (estimate_bound), no estimate runs."""
    # lane clauses are exact SQL (pipeline.query.lanes): the re-check decides the others
    check = _ExactCheck(without_lanes(pattern.steps[0].pattern if temporal else pattern), config)
    with tempfile.TemporaryDirectory(prefix=f".{out.name}.spill-", dir=out.parent) as spill, \
            leftover(spill, "tree"):
        world = temporal and pattern.uses_world_heading
        con = _open([part.path for part in dataset.parts], has_speed, threads, memory_limit_mb, spill, sets,
                    has_world=world and any("map_heading" in part.road for part in dataset.parts))
        try:
            if world:
                _require_world_heading(con, frames, pattern.behaving(TURNING))
            if min_duration_s is not None:
                _require_timestamps(con, frames, "--min-duration")
            if temporal and pattern.needs_timestamps:
                _require_timestamps(con, frames, "the pattern (its durations or behaviours)")
            _note_absent_types(con, [s.pattern for s in pattern.steps] if temporal else [pattern], frames, log)
            chunks = frame_chunks(con, pattern.uses_lanes)
            if not quick:
                if temporal:  # its candidates are bounded per scene, and a scene may span chunks
                    _check_size(con, lambda fanout: [temporal_estimate_query(pattern, config, fanout)])
                else:
                    _check_size(con, lambda fanout: [estimate_query(pattern, config, fanout, chunk=c) for c in chunks])
            con.create_function(EXACT_UDF, check, ["DOUBLE[]", "VARCHAR[]"], "BOOLEAN", type="arrow")
            with _Progress(con, log), atomic_path(out) as tmp, leftover(tmp, "file"):
                if temporal:
                    def register(step_pattern):
                        # each step's query runs alone, re-checked by its own statements but the lane clauses
                        check.pattern = without_lanes(step_pattern)
                    bindings = prepare(con, pattern, config, register, chunks)
                else:
                    materialize(con, pattern, config, chunks, BINDINGS_TABLE, "SELECT * FROM m")
                    bindings = f"WITH m AS (SELECT * FROM {BINDINGS_TABLE})"
                reader = _Named(con.sql(bindings + "\n" + select).to_arrow_reader(BATCH_ROWS), pattern.names)
                if events:
                    n_events, matched, bindings = _write_rows(reader, tmp), 0, 0
                else:
                    n_events, (matched, bindings) = None, _write_matches(reader, tmp)
        except duckdb.IOException as exc:  # the rows were checked, so this is a file that changed or broke since
            raise FramesError(f"{frames}: not a readable frames dataset ({str(exc).splitlines()[0][:160]})") from None
        except duckdb.OutOfMemoryException as exc:
            limit = (f"--memory-limit {memory_limit_mb} MB" if memory_limit_mb
                     else f"the default memory limit of {default_memory_limit_mb()} MB")
            raise UserError(f"the query ran out of memory under {limit} with at most {SPILL_LIMIT_MB} MB spilled to "
                            f"disk: raise the limit ({str(exc).splitlines()[0][:120]})") from None
        except duckdb.Error as exc:
            if _is_interrupt(exc):
                raise KeyboardInterrupt from None
            raise
        finally:
            con.close()
    return n_events, matched, bindings, check.calls


def _note_absent_types(con, patterns: list[Pattern], frames, log: Callable[[str], None]) -> None:
    """Say (a note on stderr, not an error) when the pattern names a type the frames never hold."""
    if all(matched_types(st.type) is None for p in patterns for st in p.statements):
        return  # only `Object`: any type binds, nothing to scan for
    present = [t for (t,) in con.execute(f"SELECT DISTINCT type FROM {ROWS} WHERE NOT is_ego").fetchall()]
    note = absent_types_note(patterns, present, frames)
    if note is not None:
        log(note)


def _lane_sets(frames, dataset: FramesDataset) -> pa.Table:
    """The lane relations of every map the frames name (pipeline.query.lanes), read from the maps beside them."""
    if not all(len(part.road) == len(ROAD_COLUMNS) for part in dataset.parts):
        raise FramesError(f"{frames} has no lane columns: the pattern's lane clauses (or changing lanes) need frames "
                          "extracted with a map (r2s extract of a source whose recordings carry one)")
    where = maps_dir(frames)
    with duckdb.connect() as con:  # the distinct map ids, streamed (a dataset names few maps over many rows)
        wanted = {m for (m,) in con.execute(f"SELECT DISTINCT map_id FROM read_parquet("
                                             f"{_sql_list([part.path for part in dataset.parts])}, union_by_name = true) "
                                             "WHERE map_id IS NOT NULL").fetchall()}
    if not wanted:  # lane columns, all null: a source without a map (MCAP, a log without one)
        raise FramesError(f"{frames}: no frame names a map (map_id): the pattern's lane clauses (or changing lanes) "
                          "need frames extracted with a map")
    roads = list(read_maps(where, wanted)) if where.exists() else []
    missing = sorted(wanted - {r.map_id for r in roads})
    if missing:
        raise FramesError(f"{frames}: the frames name map {missing[0]!r}, which is not in {where}")
    return lane_sets(roads)


def _require_world_heading(con, frames, turners: frozenset[str]) -> None:
    """Turning reads each track's heading in the world (map_heading), which frames carry where their source gives
    a map or a world pose; without any (on ego's rows for ego's turns, on the others' for a variable's), the
    behaviour is one line."""
    for ego in sorted({n == EGO_ID for n in turners}):
        (n,) = con.execute(f"SELECT count(*) FROM {ROWS} WHERE is_ego = {ego} AND isfinite(map_heading)").fetchall()[0]
        if not n:
            whose = "ego's" if ego else "each track's"
            raise FramesError(f"{frames}: turning needs {whose} heading in the world (map_heading), which these "
                              "frames do not carry: their source gave no map or world pose")


def _require_timestamps(con, frames, what: str) -> None:
    missing = con.execute(f"SELECT any_value(frame_id), count(*) FROM {ROWS} WHERE is_ego AND timestamp_us IS NULL").fetchall()[0]
    if missing[1]:
        raise FramesError(f"{frames}: {what} needs timestamps, and {missing[1]} frame(s) have none "
                          f"(e.g. {missing[0]!r})")


def query(frames, pattern, *, events: bool = False, min_duration_s: float | None = None, all_bindings: bool = False,
          config: SynthConfig | dict | None = None, threads: int | None = None,
          memory_limit_mb: int | None = None):
    """The Python API of `r2s query` (docs/api.md): frames (a frames file or dataset path, or a table of frames rows:
    a pandas DataFrame or a pyarrow Table, validated as a file is) and a pattern (text, or a parsed Pattern /
    TemporalPattern) in; the matches (one row per frame, per binding with all_bindings) or the events, as a pandas
    DataFrame with the columns of the file `r2s query` writes (docs/formats.md). Bad input raises an InputError."""
    if isinstance(pattern, str):
        pattern = parse_query_pattern(pattern)
    if isinstance(config, dict):
        config = SynthConfig(**config)
    with tempfile.TemporaryDirectory(prefix="r2s-query-") as tmp:
        if isinstance(frames, (pd.DataFrame, pa.Table)):
            path = Path(tmp) / "frames.parquet"
            write_frames(frames if isinstance(frames, pd.DataFrame) else frames.to_pandas(), path)
            frames = path
        out = Path(tmp) / "out.parquet"
        query_frames(frames, pattern, out, all_bindings=all_bindings, config=config, threads=threads,
                     memory_limit_mb=memory_limit_mb, events=events, min_duration_s=min_duration_s, log=lambda _: None)
        return pq.read_table(out).to_pandas()
