"""A corrupt value in any column a run's workers read refuses `r2s run` in its up-front check, before anything is
written (docs/cli.md: exit 2 writes nothing). Before, the check decoded only the columns its rules read: a value of
`category` or `lane` that is not UTF-8 was found by the worker that read it, after the parts of the frames before
it were written.

The frames are the shipped excerpt as `r2s extract` writes it (part files of the EXTRACTED_SCHEMA, zstd,
dictionary-encoded, statistics, its maps in _maps/): the good parts as written, the last rewritten in three row
groups, one value of its last row group made invalid UTF-8 in the bytes of its dictionary page, as a damaged disk
or a hostile writer leaves it (that column is written uncompressed so its bytes can be patched, as in
tests/extractors/test_frames_bounds.py, and without statistics so that the footer, which would hold the value as a
least or greatest, stays intact)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from extractors.frame_hash import FrameHasher
from extractors.frames_dataset import FramesDataset, read_frame_rows
from extractors.frames_schema import EXTRACTED_SCHEMA, FramesError
from extractors.maps import maps_dir
from tests.support import assert_one_line_error, run_r2s

TAIL = "~~ZQX~~"  # what makes the value unique in the file; its ZQX is patched into bytes that are not UTF-8
ROW_GROUP_ROWS = 40  # the last part (107 rows) in three row groups: the bad value is in its last


def _text(column: str) -> bool:
    t = EXTRACTED_SCHEMA.field(column).type
    return pa.types.is_string(t) or (pa.types.is_list(t) and pa.types.is_string(t.value_type))


def corrupted_copy(frames: Path, out: Path, column: str) -> Path:
    """A copy of the frames dataset `frames` whose last part holds one value of `column` (a text column, or a list
    of text) that is not UTF-8. Returns that part's path."""
    shutil.copytree(maps_dir(frames), maps_dir(out))
    parts = sorted(frames.glob("part-*.parquet"))
    for path in parts[:-1]:  # the good parts as written
        shutil.copyfile(path, out / path.name)
    table = pq.read_table(parts[-1])
    names = table.column_names
    start = (table.num_rows - 1) // ROW_GROUP_ROWS * ROW_GROUP_ROWS  # the last row group's first row
    values = table.column(column).to_pylist()
    row = next(i for i in range(start, table.num_rows) if values[i])  # a value (a list of some) to mark
    value = values[row][0] if isinstance(values[row], list) else values[row]
    marked = value + TAIL
    values[row] = [marked, *values[row][1:]] if isinstance(values[row], list) else marked
    table = table.set_column(names.index(column), column, pa.array(values, table.schema.field(column).type))
    target = out / parts[-1].name
    pq.write_table(table, target, row_group_size=ROW_GROUP_ROWS, write_statistics=[c for c in names if c != column],
                   compression={c: "none" if c == column else "zstd" for c in names})
    data = target.read_bytes()
    assert data.count(marked.encode()) == 1  # once, in the dictionary page of the last row group
    target.write_bytes(data.replace(marked.encode(), (value + TAIL.replace("ZQX", "\udcff\udcfe\udcfd")).encode(
        "utf-8", "surrogateescape")))
    assert pq.ParquetFile(target).metadata.num_row_groups == 3
    return target


def _refusal(fn) -> str | None:
    try:
        fn()
    except FramesError as exc:
        return str(exc)
    return None


@pytest.mark.parametrize("column", [c for c in EXTRACTED_SCHEMA.names if _text(c)])
@pytest.mark.parametrize("road", [False, True], ids=["plain", "lanes"])
def test_the_check_refuses_what_a_worker_refuses(excerpt_frames, tmp_path, column, road):
    """The check of a run refuses a dataset exactly when a worker of that run, reading every row of it, does, with
    the worker's message: the road columns are read (and checked) only when the run gives frames their road."""
    bad = corrupted_copy(excerpt_frames, tmp_path / "frames", column)
    dataset = FramesDataset.open(tmp_path / "frames")
    part = next(p for p in dataset.parts if p.path == str(bad))
    worker = _refusal(lambda: read_frame_rows("", part.path, 0, part.rows, part.read_columns(road)))
    check = _refusal(lambda: dataset.check(FrameHasher(), road=road))
    assert (check is None) == (worker is None), (check, worker)
    if worker is not None:
        said = f"{bad} holds corrupt values in column {column} ("
        assert worker.startswith(said) and check.startswith(said), (check, worker)
        assert "\n" not in check
    assert (worker is None) == (not road and column not in FramesDataset.open(excerpt_frames).parts[0].columns)


@pytest.mark.parametrize("column,options", [
    ("category", ()),
    ("lane", ("--lanes",)),
    ("track_id", ("--window", "1")),
], ids=["category", "lane", "window"])
def test_a_run_refuses_a_corrupt_value_before_writing_anything(excerpt_frames, tmp_path, column, options):
    """Small parts, one frame a task, two workers: the good parts' frames come first. Before the check read every
    column, the parts of the good frames whose tasks finished before the bad one's were written (with category and
    lane: an output folder with parts, left behind by a refusal)."""
    bad = corrupted_copy(excerpt_frames, tmp_path / "frames", column)
    out = tmp_path / "programs"
    proc = run_r2s("run", str(tmp_path / "frames"), "--out", str(out), "--part-rows", "1", "--chunk-size", "1",
                   "--jobs", "2", *options, timeout=600)
    assert_one_line_error(proc, 2, f"{bad} holds corrupt values in column {column}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames"]  # no output, parts, lock or temporary
