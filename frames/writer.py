"""Streaming frames.parquet writer: frames go out in row groups as they come, into a temporary file that is
renamed over the target only when the whole extraction succeeded (a failure leaves nothing behind)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from frames.rows import EXTRACTED_SCHEMA, FramesError, to_table
from storage.atomic import parquet_writer

ROW_GROUP_ROWS = 64_000


class FramesWriter:
    def __init__(self, writer: pq.ParquetWriter) -> None:
        self._writer = writer
        self._pending: list[dict[str, Any]] = []
        self.frames = 0
        self.rows = 0
        self._seen: set[str] = set()

    def write_frame(self, rows: list[dict[str, Any]]) -> None:
        fid = rows[0]["frame_id"]
        if fid in self._seen:  # two inputs that name the same scene would make frame ids ambiguous
            raise FramesError(f"frame id {fid!r} occurs twice in the input (the same scene given twice?)")
        self._seen.add(fid)
        self._pending.extend(rows)
        self.frames += 1
        self.rows += len(rows)
        if len(self._pending) >= ROW_GROUP_ROWS:
            self.flush()

    @property
    def frame_ids(self) -> frozenset[str]:
        return frozenset(self._seen)

    def flush(self) -> None:
        if self._pending:
            table = to_table(self._pending)
            # Columns no row of these frames has (the road columns of a frame without a map) are written null.
            for f in EXTRACTED_SCHEMA:
                if f.name not in table.column_names:
                    table = table.append_column(f, pa.nulls(table.num_rows, f.type))
            self._writer.write_table(table.select(EXTRACTED_SCHEMA.names))
            self._pending = []


@contextmanager
def frames_writer(path: str | os.PathLike) -> Iterator[FramesWriter]:
    with parquet_writer(path, EXTRACTED_SCHEMA) as pw:
        w = FramesWriter(pw)
        yield w
        w.flush()
