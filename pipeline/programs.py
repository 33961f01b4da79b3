"""The programs schema (docs/formats.md, "Programs Parquet"): one row per frame, written by `r2s run`, read by
`r2s report`, the benchmarks and users' pandas. Keep it stable: other tools read these columns."""

from __future__ import annotations

import os
from typing import Any

import pyarrow as pa

PROGRAMS_SCHEMA = pa.schema(
    [
        ("frame_id", pa.string()),
        ("status", pa.string()),  # optimal | feasible | timeout | memout | error
        ("cost", pa.int32()),  # null when status is error (or memout before any program)
        ("lower_bound", pa.int32()),
        ("n_entities", pa.int32()),
        ("program", pa.string()),  # DSL text
        ("scenic", pa.string()),  # Scenic 3 text
        ("certified", pa.bool_()),
        ("strategy", pa.string()),
        ("oracle", pa.string()),
        ("solver", pa.string()),
        ("runtime_s", pa.float64()),
        ("search_s", pa.float64()),
        ("smt_s", pa.float64()),
        ("smt_queries", pa.int64()),
        ("nodes_expanded", pa.int64()),
        ("peak_rss_mb", pa.float64()),
        ("error", pa.string()),
        ("config_hash", pa.string()),
        ("version", pa.string()),
    ]
)
PROGRAMS_COLUMNS = tuple(PROGRAMS_SCHEMA.names)
STATUSES = ("optimal", "feasible", "timeout", "memout", "error")


class ProgramsError(ValueError):
    """A programs file that is not what the schema says. One line, fit for a user."""


def result_row(result: Any, config_hash: str) -> dict[str, Any]:
    """A programs row from a synth.synthesize.SynthResult."""
    from synth import __version__

    s, c = result.stats, result.config
    return {
        "frame_id": result.frame_id, "status": result.status, "cost": result.cost,
        "lower_bound": result.lower_bound, "n_entities": result.n_entities, "program": str(result.program),
        "scenic": result.scenic, "certified": result.certified, "strategy": c.strategy, "oracle": c.oracle,
        "solver": c.solver, "runtime_s": s.runtime_s, "search_s": s.search_s, "smt_s": s.smt_s,
        "smt_queries": s.smt_queries, "nodes_expanded": s.nodes_expanded, "peak_rss_mb": s.peak_rss_mb,
        "error": None, "config_hash": config_hash, "version": __version__,
    }


def failure_row(frame_id: str, status: str, message: str, n_entities: int, config: Any, config_hash: str,
                runtime_s: float = 0.0, peak_rss_mb: float = 0.0) -> dict[str, Any]:
    """A row for a frame that produced no program (error, or a worker killed at its memory limit)."""
    from synth import __version__

    if status not in STATUSES:
        raise ValueError(f"unknown status {status!r}")
    return {
        "frame_id": frame_id, "status": status, "cost": None, "lower_bound": None, "n_entities": n_entities,
        "program": None, "scenic": None, "certified": False, "strategy": config.strategy, "oracle": config.oracle,
        "solver": config.solver, "runtime_s": runtime_s, "search_s": None, "smt_s": None, "smt_queries": None,
        "nodes_expanded": None, "peak_rss_mb": peak_rss_mb, "error": message, "config_hash": config_hash,
        "version": __version__,
    }


def programs_table(rows: list[dict[str, Any]]) -> pa.Table:
    return pa.Table.from_pylist([{c: r.get(c) for c in PROGRAMS_COLUMNS} for r in rows], schema=PROGRAMS_SCHEMA)


def check_programs_schema(schema: pa.Schema, where: str) -> None:
    """Refuse a file that lacks a programs column or has one of another kind (text where a number belongs)."""
    from extractors.frames_dataset import check_column_types

    missing = [c for c in PROGRAMS_COLUMNS if c not in schema.names]
    if missing:
        raise ProgramsError(f"{where} is not a programs file: it lacks column(s) {', '.join(missing)}")
    check_column_types(schema, PROGRAMS_SCHEMA, where, ProgramsError)


def check_programs_values(table: pa.Table, where: str) -> None:
    for column in ("frame_id", "status", "config_hash"):
        if column in table.column_names and table.column(column).null_count:
            raise ProgramsError(f"{where}: column {column} has a missing value")
    if "status" in table.column_names:
        import pyarrow.compute as pc

        bad = sorted(set(pc.unique(table.column("status")).to_pylist()) - set(STATUSES))
        if bad:
            raise ProgramsError(f"{where}: unknown status value(s) {', '.join(map(repr, bad[:5]))}")


def programs_files(path: str | os.PathLike) -> list[str]:
    """The Parquet files of a programs file or dataset directory (ProgramsError if there are none)."""
    from extractors.frames_dataset import dataset_files

    return dataset_files(str(path), "programs", ProgramsError)[1]


def read_programs_table(path: str | os.PathLike) -> pa.Table:
    """Read and validate a programs file or dataset directory, whole, as a table of exactly PROGRAMS_SCHEMA; any
    problem (a column of another type, a missing frame id or status, an unknown status) is a ProgramsError naming
    the file. For small data and tests: the report and the runner stream instead."""
    import pyarrow.parquet as pq

    files = programs_files(path)
    tables = []
    for f in files:
        where = f if len(files) > 1 else str(path)
        try:
            pf = pq.ParquetFile(f)
            check_programs_schema(pf.schema_arrow, where)
            table = pf.read(columns=list(PROGRAMS_COLUMNS)).select(list(PROGRAMS_COLUMNS)).cast(PROGRAMS_SCHEMA)
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
    import pyarrow.dataset as ds

    files = programs_files(path)
    try:
        table = ds.dataset(files, format="parquet").to_table(
            columns=["frame_id", "program", "cost"], filter=ds.field("frame_id") == frame_id)
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ProgramsError(f"{path} is not a readable programs dataset ({str(exc)[:120]})") from None
    rows = sorted((r for r in table.to_pylist() if r["program"] is not None), key=lambda r: r["cost"] is None or r["cost"])
    return rows[0]["program"] if rows else None


def read_programs(path: str | os.PathLike):
    """read_programs_table as a DataFrame (for users' pandas and the tests)."""
    return read_programs_table(path).to_pandas()
