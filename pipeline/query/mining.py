"""Scenario mining: every frame of a frames dataset that matches a pattern (synth.pattern), through DuckDB.

The pattern becomes one query (pipeline.query.sql); this module owns the I/O around it: the input (a frames file or
dataset, checked by extractors.frames_dataset as every verb checks it), the DuckDB session (threads, memory limit,
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
from dataclasses import dataclass
from pathlib import Path

import duckdb
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
from tqdm import tqdm

from extractors.frames import FramesError, write_frames
from extractors.frames_dataset import FramesDataset
from pipeline.errors import UserError
from pipeline.query.events import events_select
from pipeline.query.sql import (
    EXACT_UDF,
    MACROS,
    ROW_COLUMNS,
    ROWS,
    WILD_HEADING,
    WILD_XY,
    bindings_query,
    matches_select,
)
from pipeline.query.temporal import prepare
from storage.atomic import atomic_path
from synth.config import SynthConfig
from synth.pattern import Pattern, binding_holds
from synth.scene import EGO_ID, Entity
from synth.temporal import TemporalPattern, parse_query_pattern

BATCH_ROWS = 65536
LOG_EVERY_S = 30.0


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


def _open(files: Sequence[str], has_speed: bool, threads: int | None, memory_limit_mb: int | None, spill_dir: str):
    """A DuckDB session with the rows view of the files."""
    con = duckdb.connect(config={"threads": threads or os.cpu_count() or 1, "temp_directory": spill_dir,
                                 **({"memory_limit": f"{memory_limit_mb}MB"} if memory_limit_mb else {})})
    # Progress is tracked for _Progress, never printed by DuckDB itself (it would write to stdout).
    con.execute("SET enable_progress_bar = true")
    con.execute("SET enable_progress_bar_print = false")
    source = f"read_parquet({_sql_list(files)}, file_row_number = true, union_by_name = true)"
    # ord, the row ordinal (file number, then row in the file), orders frames and bindings deterministically.
    # speed is optional (frames of sources without velocities lack it): unknown is NULL, as in a file that has it.
    con.execute(
        f"CREATE TEMP VIEW {ROWS} AS SELECT hash(frame_id) AS fk, frame_id, scene, frame_index, timestamp_us, "
        f"entity_id, track_id, type, "
        f"x, y, heading, {'speed' if has_speed else 'NULL::DOUBLE AS speed'}, is_ego, "
        f"file_index::BIGINT * 1099511627776 + file_row_number AS ord, {ROW_COLUMNS}, "
        f"NOT (abs(x) <= {WILD_XY} AND abs(y) <= {WILD_XY} AND abs(heading) <= {WILD_HEADING}) AS wild FROM {source}")
    for macro in MACROS:
        con.execute(macro)
    return con


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


def query_frames(frames: str | os.PathLike, pattern: Pattern | TemporalPattern, out: str | os.PathLike, *, all_bindings: bool = False,
                 config: SynthConfig | None = None, threads: int | None = None, memory_limit_mb: int | None = None,
                 events: bool = False, min_duration_s: float | None = None,
                 log: Callable[[str], None] = lambda s: print(s, file=sys.stderr)) -> QuerySummary:
    """Write matches.parquet (atomically) for `pattern` over a frames file or dataset, or with events one row per
    event (pipeline.query.events; min_duration_s keeps the events at least that long, and needs every frame's
    timestamp); bad input is a FramesError."""
    t0 = time.monotonic()
    config = config or SynthConfig()
    dataset = FramesDataset.open(frames)
    if dataset.url:
        raise FramesError(f"{frames}: r2s query reads frames on a local filesystem (copy them here first)")
    has_speed = any("speed" in part.optional for part in dataset.parts)
    if pattern.uses_motion and not has_speed:
        raise FramesError(f"{frames} has no speed column: the pattern's motion clauses (or behaviours) need one")
    # The frames contract, as every verb checks it (one streaming pass; the same one-line messages).
    n_frames, _ = dataset.check()
    if min_duration_s is not None and not events:
        raise UserError("--min-duration is a length of events: it needs --events")
    if events and all_bindings:
        raise UserError("--events and --all are two outputs: choose one")
    temporal = isinstance(pattern, TemporalPattern)  # the one place the two kinds of pattern part ways
    select = events_select(min_duration_s) if events else matches_select(all_bindings)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    check = _ExactCheck(pattern.steps[0].pattern if isinstance(pattern, TemporalPattern) else pattern, config)
    with tempfile.TemporaryDirectory(prefix=f".{out.name}.spill-", dir=out.parent) as spill:
        con = _open([part.path for part in dataset.parts], has_speed, threads, memory_limit_mb, spill)
        try:
            if min_duration_s is not None:
                _require_timestamps(con, frames, "--min-duration")
            if temporal and pattern.needs_timestamps:
                _require_timestamps(con, frames, "the pattern (its durations or behaviours)")
            with _Progress(con, log), atomic_path(out) as tmp:
                if temporal:
                    def register(step_pattern):
                        check.pattern = step_pattern  # each step's query runs alone, re-checked by its own statements
                    con.create_function(EXACT_UDF, check, ["DOUBLE[]", "VARCHAR[]"], "BOOLEAN", type="arrow")
                    bindings = prepare(con, pattern, config, register)
                else:
                    con.create_function(EXACT_UDF, check, ["DOUBLE[]", "VARCHAR[]"], "BOOLEAN", type="arrow")
                    bindings = bindings_query(pattern, config)
                reader = con.sql(bindings + "\n" + select).to_arrow_reader(BATCH_ROWS)
                if events:
                    n_events, matched, bindings = _write_rows(reader, tmp), 0, 0
                else:
                    n_events, (matched, bindings) = None, _write_matches(reader, tmp)
        except duckdb.IOException as exc:  # the rows were checked, so this is a file that changed or broke since
            raise FramesError(f"{frames}: not a readable frames dataset ({str(exc).splitlines()[0][:160]})") from None
        finally:
            con.close()
    return QuerySummary(n_frames, matched, bindings, check.calls, time.monotonic() - t0, n_events)


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
