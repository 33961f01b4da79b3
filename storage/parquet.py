"""Parquet datasets as files on a filesystem: where their files are, their footers, and rows read by range.

A dataset is one Parquet file or a directory of them, on a local path or a URL (s3://, gs://, any fsspec
protocol). Nothing here knows a schema: the frames and programs readers (frames.dataset,
pipeline.programs) say which columns they expect and which error class names a bad file.
"""

from __future__ import annotations

import os
from collections import OrderedDict

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from pyarrow import fs

from storage.regular_files import check_regular

# A column chunk's own bytes beside its values: page headers, statistics, a dictionary's offsets.
CHUNK_SLACK_BYTES = 64 * 1024


def filesystem(path: str):
    """(pyarrow filesystem, path inside it) for a local path or a URL (s3://, gs://, file://, or any fsspec
    protocol), so that a cluster's workers can read a path they all see."""
    if "://" not in str(path):
        return fs.LocalFileSystem(), os.path.abspath(path)
    try:
        return fs.FileSystem.from_uri(path)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, ValueError):
        import fsspec

        fsspec_fs, inner = fsspec.core.url_to_fs(path)
        return fs.PyFileSystem(fs.FSSpecHandler(fsspec_fs)), inner


def dataset_files(path: str, what: str, error: type[ValueError]) -> tuple[object, list[str]]:
    """The Parquet files of a dataset: the file itself, or every *.parquet under a directory (sorted, hidden and
    _-prefixed names skipped, as pyarrow.dataset, DuckDB globs and Spark skip them)."""
    try:
        pafs, inner = filesystem(str(path))
        info = pafs.get_file_info(inner)
    except (OSError, ValueError, ImportError) as exc:
        raise error(f"{path}: cannot open ({str(exc)[:120]})") from None
    if info.type == fs.FileType.NotFound:
        raise error(f"{path} does not exist")
    if info.type not in (fs.FileType.File, fs.FileType.Directory):  # a FIFO, a device (/dev/zero), a socket
        raise error(f"{path} {_not_regular(inner)}")
    if info.type == fs.FileType.File:
        return pafs, [inner]
    selector = fs.FileSelector(inner, recursive=True)
    files = sorted(
        f.path for f in pafs.get_file_info(selector)
        if f.type == fs.FileType.File and f.path.endswith(".parquet")
        and not any(part.startswith((".", "_")) for part in os.path.relpath(f.path, inner).split(os.sep))
    )
    if not files:
        raise error(f"{path} is a directory without {what} Parquet files (*.parquet)")
    return pafs, files


def _not_regular(path: str) -> str:
    try:
        check_regular(path)
    except OSError as exc:
        return exc.strerror
    return "is not a regular file"


def _kind(t: pa.DataType) -> str:
    if pa.types.is_dictionary(t):
        t = t.value_type
    if pa.types.is_string(t) or pa.types.is_large_string(t):
        return "string"
    if pa.types.is_integer(t):
        return "integer"
    if pa.types.is_floating(t):
        return "float"
    if pa.types.is_boolean(t):
        return "bool"
    return str(t)


def check_column_types(schema: pa.Schema, expected: pa.Schema, where: str, error: type[ValueError]) -> None:
    """Refuse a column of another kind than the schema's (text where a number belongs, ...); widths may differ
    (pandas writes int64 where the schema says int32), a float column may hold integers."""
    for field in expected:
        if field.name not in schema.names:
            continue
        want, got = _kind(field.type), _kind(schema.field(field.name).type)
        if got != want and not (want == "float" and got == "integer") and not pa.types.is_null(
                schema.field(field.name).type):
            raise error(f"{where}: column {field.name} is {schema.field(field.name).type}, not {field.type} "
                        "(a column does not have the schema's type)")


def check_value_sizes(meta: pq.FileMetaData, columns: tuple[str, ...], max_average: int, where: str,
                      error: type[ValueError]) -> None:
    """Refuse, from the footer alone, a file whose values of `columns` are far longer than `max_average` bytes on
    average in some row group: a column chunk's uncompressed size bounds the bytes its values decode to, and a few
    kilobytes of zstd can hold a gigabyte of one repeated character (a 135 KB file with one 1 GiB cell took 10 GB
    of memory to decode). A dictionary page counts too, so one huge distinct value is caught however encoded."""
    try:  # a corrupt footer's names may not even decode
        chunks = [(g, meta.row_group(g).num_rows, meta.row_group(g).column(c)) for g in range(meta.num_row_groups)
                  for c in range(meta.row_group(g).num_columns)]
        chunks = [(g, rows, chunk.path_in_schema, chunk.total_uncompressed_size) for g, rows, chunk in chunks]
    except (ValueError, pa.ArrowException) as exc:
        raise error(f"{where} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:100]})") from None
    for g, rows, name, size in chunks:
        if name in columns:
            if size > CHUNK_SLACK_BYTES + rows * max_average:
                raise error(f"{where}: column {name} holds {size:,} bytes in {rows:,} row(s) of row group {g}, more "
                            f"than {max_average:,} a value: a value is far longer than one may be")


def null_count(meta: pq.FileMetaData, column: str) -> int | None:
    """The nulls of a column over a file's row groups from the footer's statistics; None where a row group has
    none (a writer may leave them out: the column must then be read to know)."""
    total = 0
    try:
        for g in range(meta.num_row_groups):
            group = meta.row_group(g)
            chunk = next((group.column(c) for c in range(group.num_columns)
                          if group.column(c).path_in_schema == column), None)
            stats = chunk.statistics if chunk is not None else None
            if stats is None or not stats.has_null_count:
                return None
            total += stats.null_count
    except (ValueError, pa.ArrowException):  # a corrupt footer: the column is read instead, and refused there
        return None
    return total


def footer(pafs, path: str, where: str, error: type[ValueError]) -> pq.FileMetaData:
    """The footer of one Parquet file (schema, row groups) without reading its data."""
    try:
        with pafs.open_input_file(path) as f:
            return pq.ParquetFile(f).metadata
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise error(f"{where} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:120]})") from None


# Per process: open files and the row groups read last. Workers take neighbouring chunks one after another,
# so a row group (64,000 rows) is decoded about once per worker, not once per chunk. Keyed by the file's identity
# (size, modification time and inode, besides its path): a worker lives on between runs of one Python process,
# and a file rewritten in between must be read again, never served from the cache of its former contents.
_FILES: OrderedDict = OrderedDict()
_GROUPS: OrderedDict = OrderedDict()
_CACHED_FILES, _CACHED_GROUPS = 8, 4


def open_file(url: str, path: str, dictionary: tuple[str, ...] = ()) -> pq.ParquetFile:
    """A Parquet file opened for reading, kept open per process (see _FILES)."""
    return _open_with_bounds(url, path, dictionary)[0]


def _open_with_bounds(url: str, path: str, dictionary: tuple[str, ...] = ()) -> tuple[pq.ParquetFile, np.ndarray, tuple]:
    """An open file, the first row of each of its row groups (plus the row count at the end), and its identity."""
    pafs, _ = filesystem(url) if url else filesystem(path)
    info = pafs.get_file_info(path)
    inode = None if url else os.stat(path).st_ino  # an atomic rewrite is a new inode, even within one mtime tick
    key = (url, path, dictionary, info.size, info.mtime_ns, inode)
    hit = _FILES.get(key)
    if hit is None:
        pf = pq.ParquetFile(pafs.open_input_file(path), read_dictionary=list(dictionary) or None)
        sizes = [pf.metadata.row_group(i).num_rows for i in range(pf.metadata.num_row_groups)]
        hit = _FILES[key] = (pf, np.concatenate(([0], np.cumsum(sizes, dtype=np.int64))), key)
        while len(_FILES) > _CACHED_FILES:
            _FILES.popitem(last=False)
    else:
        _FILES.move_to_end(key)
    return hit


def read_rows(url: str, path: str, start: int, stop: int, columns: tuple[str, ...]) -> pa.Table:
    """Rows [start, stop) of one file, read through the row groups that hold them."""
    pf, bounds, identity = _open_with_bounds(url, path)
    first = int(np.searchsorted(bounds, start, side="right") - 1)
    tables = []
    for g in range(first, len(bounds) - 1):
        if bounds[g] >= stop:
            break
        key = (identity, g, columns)
        table = _GROUPS.get(key)
        if table is None:
            table = pf.read_row_group(g, columns=list(columns))
            _GROUPS[key] = table
            while len(_GROUPS) > _CACHED_GROUPS:
                _GROUPS.popitem(last=False)
        else:
            _GROUPS.move_to_end(key)
        lo, hi = max(start - bounds[g], 0), min(stop, bounds[g + 1]) - bounds[g]
        tables.append(table.slice(lo, hi - lo))
    return pa.concat_tables(tables) if len(tables) > 1 else tables[0]
