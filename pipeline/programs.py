"""The programs schema (docs/formats.md, "Programs Parquet"): one row per frame, written by `r2s run`, read by
`r2s report`, the benchmarks and users' pandas. Keep it stable: other tools read these columns."""

from __future__ import annotations

import os
from typing import Any

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from storage.parquet import check_column_types, dataset_files
from synth.errors import InputError
from synth.result import RESULT_FIELDS, ResultField
from synth.version import ROWS_VERSION

# The Parquet type of a result field's Python type; the counts of one frame's program (its cost, lower bound and
# entities, at most a few thousand) are int32, as every programs file since the first release has them.
_ARROW_TYPES = {str: pa.string(), int: pa.int64(), float: pa.float64(), bool: pa.bool_()}
_INT32 = frozenset({"cost", "lower_bound", "n_entities"})


def _arrow_type(result_field: ResultField) -> pa.DataType:
    return pa.int32() if result_field.name in _INT32 else _ARROW_TYPES[result_field.type]


# The columns are the result fields (synth.result.RESULT_FIELDS, the one declaration), in their order.
PROGRAMS_SCHEMA = pa.schema([(f.name, _arrow_type(f)) for f in RESULT_FIELDS])
PROGRAMS_COLUMNS = tuple(PROGRAMS_SCHEMA.names)
# Columns added after the first release: a file written before them lacks them, and readers take them as null
# (a row without a frame_hash is recomputed on resume: what it was computed from is unknown).
LATER_COLUMNS = ("frame_hash",)
STATUSES = ("optimal", "feasible", "timeout", "memout", "error")
# `r2s run --window`: one row per window (docs/formats.md, "Window programs"), the programs columns (frame_id: the
# window's first frame; frame_hash: the hash of all its frames' rows) and then these.
WINDOW_FIELDS = (("scene", pa.string()), ("last_frame", pa.string()), ("first_timestamp_us", pa.int64()),
                 ("last_timestamp_us", pa.int64()), ("n_frames", pa.int32()), ("window_s", pa.float64()))
WINDOW_SCHEMA = pa.schema(list(PROGRAMS_SCHEMA) + [pa.field(n, t) for n, t in WINDOW_FIELDS])
# `r2s run --clip`: one row per clip (docs/formats.md, "Clip programs"): the programs columns (program: the clip
# program; frame_hash: the hash of all its frames' rows and timestamps), the window columns but clip_s for window_s,
# and what `r2s synth --behaviours --format json` adds (boundaries: its JSON object as text) and every timestamp.
CLIP_FIELDS = (*WINDOW_FIELDS[:-1], ("clip_s", pa.float64()), ("duration_s", pa.float64()),
               ("relational_cost", pa.int32()), ("boundaries", pa.string()), ("behaviours_s", pa.float64()),
               ("timestamps_us", pa.list_(pa.int64())))
CLIP_SCHEMA = pa.schema(list(PROGRAMS_SCHEMA) + [pa.field(n, t) for n, t in CLIP_FIELDS])
# The column that tells each kind of rows apart (an output holds one kind), and what its rows are.
UNIT_COLUMNS = {"window_s": "window", "clip_s": "clip"}


class ProgramsError(InputError, ValueError):
    """A programs file that is not what the schema says. One line, fit for a user."""


def result_row(result: Any, frame_hash: str | None = None) -> dict[str, Any]:
    """A programs row from a synth.result.SynthResult (its config's hash is the row's config_hash);
    `frame_hash`: the hash of the frame's rows it was computed from (frames.frame_hash), None when it did not
    come from a frames file."""
    return {**{f.name: result.value(f) for f in RESULT_FIELDS if f.source != "run"},
            **_run_fields(None, result.config, frame_hash)}


def failure_row(frame_id: str, status: str, message: str, n_entities: int, config: Any, runtime_s: float = 0.0,
                peak_rss_mb: float = 0.0, frame_hash: str | None = None) -> dict[str, Any]:
    """A row for a frame that produced no program (error, or a worker killed at its memory limit)."""
    if status not in STATUSES:
        raise ValueError(f"unknown status {status!r}")
    row = dict.fromkeys(PROGRAMS_COLUMNS)  # null where there is no program
    row.update({f.name: getattr(config, f.name) for f in RESULT_FIELDS if f.source == "config"})
    row.update(frame_id=frame_id, status=status, n_entities=n_entities, certified=False, runtime_s=runtime_s,
               peak_rss_mb=peak_rss_mb, **_run_fields(message, config, frame_hash))
    return row


def _run_fields(error: str | None, config: Any, frame_hash: str | None) -> dict[str, Any]:
    """The batch stage's own fields of a row (RESULT_FIELDS' "run" source)."""
    return {"error": error, "config_hash": config.hash, "version": ROWS_VERSION, "frame_hash": frame_hash}


def programs_table(rows: list[dict[str, Any]], schema: pa.Schema = PROGRAMS_SCHEMA) -> pa.Table:
    return pa.Table.from_pylist([{c: r.get(c) for c in schema.names} for r in rows], schema=schema)


def check_programs_schema(schema: pa.Schema, where: str) -> None:
    """Refuse a file that lacks a programs column or has one of another kind (text where a number belongs)."""
    missing = [c for c in PROGRAMS_COLUMNS if c not in schema.names and c not in LATER_COLUMNS]
    if missing:
        raise ProgramsError(f"{where} is not a programs file: it lacks column(s) {', '.join(missing)}")
    check_column_types(schema, PROGRAMS_SCHEMA, where, ProgramsError)


def as_programs(table: pa.Table | pa.RecordBatch, schema: pa.Schema = PROGRAMS_SCHEMA) -> pa.Table | pa.RecordBatch:
    """A programs table or batch in exactly `schema` (PROGRAMS_SCHEMA, or WINDOW_SCHEMA for window rows): the
    columns in order, an older writer's int64 where the schema has int32, null for a column added later
    (LATER_COLUMNS) that the file lacks."""
    for name in LATER_COLUMNS:
        if name not in table.schema.names:
            field = schema.field(name)
            table = table.append_column(field, pa.nulls(table.num_rows, field.type))
    return table.select(schema.names).cast(schema)


def check_programs_values(table: pa.Table, where: str) -> None:
    for column in ("frame_id", "status", "config_hash"):
        if column in table.column_names and table.column(column).null_count:
            raise ProgramsError(f"{where}: column {column} has a missing value")
    if "status" in table.column_names:
        bad = sorted(set(pc.unique(table.column("status")).to_pylist()) - set(STATUSES))
        if bad:
            raise ProgramsError(f"{where}: unknown status value(s) {', '.join(map(repr, bad[:5]))}")


def programs_files(path: str | os.PathLike) -> list[str]:
    """The Parquet files of a programs file or dataset directory (ProgramsError if there are none)."""
    return dataset_files(str(path), "programs", ProgramsError)[1]


def read_programs_table(path: str | os.PathLike) -> pa.Table:
    """Read and validate a programs file or dataset directory, whole, as a table of exactly PROGRAMS_SCHEMA; any
    problem (a column of another type, a missing frame id or status, an unknown status) is a ProgramsError naming
    the file. For small data and tests: the report and the runner stream instead."""
    files = programs_files(path)
    tables = []
    for f in files:
        where = f if len(files) > 1 else str(path)
        try:
            pf = pq.ParquetFile(f)
            check_programs_schema(pf.schema_arrow, where)
            table = as_programs(pf.read(columns=[c for c in PROGRAMS_COLUMNS if c in pf.schema_arrow.names]))
        except ProgramsError:
            raise
        except (pa.ArrowException, OSError, ValueError) as exc:
            raise ProgramsError(f"{where} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:120]})") from None
        check_programs_values(table, where)
        tables.append(table)
    return pa.concat_tables(tables) if len(tables) > 1 else tables[0]


def program_of_frame(path: str | os.PathLike, frame_id: str) -> str | None:
    """The DSL program of one frame in a programs file or dataset (its cheapest, when several configs ran it),
    read with a filter on frame_id (row-group statistics skip the rest); None if it has none."""
    return _of_frame(path, frame_id, "program")


def scenic_of_frame(path: str | os.PathLike, frame_id: str) -> str | None:
    """The Scenic text of one frame's program (the row program_of_frame picks), or None if it has none."""
    return _of_frame(path, frame_id, "scenic")


def _of_frame(path: str | os.PathLike, frame_id: str, column: str) -> str | None:
    files = programs_files(path)
    try:
        table = ds.dataset(files, format="parquet").to_table(
            columns=["frame_id", "program", "cost", column] if column != "program" else ["frame_id", "program", "cost"],
            filter=ds.field("frame_id") == frame_id)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ProgramsError(f"{path} is not a readable programs dataset ({str(exc)[:120]})") from None
    rows = sorted((r for r in table.to_pylist() if r["program"] is not None), key=lambda r: r["cost"] is None or r["cost"])
    return rows[0][column] if rows else None


def read_programs(path: str | os.PathLike):
    """read_programs_table as a DataFrame (for users' pandas and the tests)."""
    return read_programs_table(path).to_pandas()
