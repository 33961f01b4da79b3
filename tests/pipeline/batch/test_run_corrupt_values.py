"""A corrupt value in any column a run's workers read refuses `r2s run` in its up-front check, before anything is
written (docs/cli.md: exit 2 writes nothing). Before, the check decoded only the columns its rules read: a value of
`category` or `lane` that is not UTF-8 was found by the worker that read it, after the parts of the frames before
it were written.

The frames are the shipped excerpt as `r2s extract` writes it (part files of the EXTRACTED_SCHEMA, zstd,
dictionary-encoded, statistics, its maps in _maps/): the good parts as written, the last rewritten in three row
groups, one value of its last row group made invalid UTF-8 in the bytes of its dictionary page, as a damaged disk
or a hostile writer leaves it (that column is written uncompressed so its bytes can be patched, as in
tests/frames/test_frames_bounds.py, and without statistics so that the footer, which would hold the value as a
least or greatest, stays intact)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from frames.dataset import FramesDataset, read_frame_rows
from frames.frame_hash import FrameHasher
from frames.maps import maps_dir
from frames.schema import EXTRACTED_SCHEMA, FramesError
from tests.support import assert_one_line_error, run_r2s

TAIL = "~~ZQX~~"  # what makes the value unique in the file; its ZQX is patched into bytes that are not UTF-8
ROW_GROUP_ROWS = 40  # the last part (107 rows) in three row groups: the bad value is in its last


def _text(column: str) -> bool:
    t = EXTRACTED_SCHEMA.field(column).type
    return pa.types.is_string(t) or (pa.types.is_list(t) and pa.types.is_string(t.value_type))


def corrupted_copy(frames: Path, out: Path, column: str, damage: str = "utf-8") -> Path:
    """A copy of the frames dataset `frames` whose last part holds one corrupt value of `column` (a text column, or
    a list of text): with damage "utf-8" a value that is not UTF-8; with "index" (a text column) the last row
    group's values are two runs of two of the column's values, and the second run's dictionary index is made 5, past
    the dictionary's two values. Returns that part's path."""
    shutil.copytree(maps_dir(frames), maps_dir(out))
    parts = sorted(frames.glob("part-*.parquet"))
    for path in parts[:-1]:  # the good parts as written
        shutil.copyfile(path, out / path.name)
    table = pq.read_table(parts[-1])
    names = table.column_names
    start = (table.num_rows - 1) // ROW_GROUP_ROWS * ROW_GROUP_ROWS  # the last row group's first row
    values = table.column(column).to_pylist()
    if damage == "utf-8":
        row = next(i for i in range(start, table.num_rows) if values[i])  # a value (a list of some) to mark
        value = values[row][0] if isinstance(values[row], list) else values[row]
        values[row] = [value + TAIL, *values[row][1:]] if isinstance(values[row], list) else value + TAIL
        found = (value + TAIL).encode()
        patched = (value + TAIL.replace("ZQX", "\udcff\udcfe\udcfd")).encode("utf-8", "surrogateescape")
    else:
        a, b = list(dict.fromkeys(v for v in values if v is not None))[:2]
        n = table.num_rows - start
        values[start:] = [a] * (n // 2) + [b] * (n - n // 2)
        # The indices as an RLE/bit-packed hybrid of bit width 1: two RLE runs (a header of the run length
        # shifted left once, then the index), index 0 then index 1.
        found = bytes([1, (n // 2) << 1, 0, (n - n // 2) << 1, 1])
        patched = found[:-1] + b"\x05"
    table = table.set_column(names.index(column), column, pa.array(values, table.schema.field(column).type))
    target = out / parts[-1].name
    pq.write_table(table, target, row_group_size=ROW_GROUP_ROWS, write_statistics=[c for c in names if c != column],
                   compression={c: "none" if c == column else "zstd" for c in names})
    data = target.read_bytes()
    assert data.count(found) == 1  # once: in the dictionary page, or the data page, of the last row group
    target.write_bytes(data.replace(found, patched))
    assert pq.ParquetFile(target).metadata.num_row_groups == 3
    return target


def _refusal(fn) -> str | None:
    try:
        fn()
    except FramesError as exc:
        return str(exc)
    return None


CASES = [(c, "utf-8") for c in EXTRACTED_SCHEMA.names if _text(c)] + [("category", "index"), ("lane", "index")]


@pytest.mark.parametrize("column,damage", CASES, ids=[f"{c}-{d}" for c, d in CASES])
@pytest.mark.parametrize("road", [False, True], ids=["plain", "lanes"])
def test_the_check_refuses_what_a_worker_refuses(excerpt_frames, tmp_path, column, damage, road):
    """The check of a run refuses a dataset exactly when a worker of that run, reading every row of it, does, in one
    line naming the file (and the column: a worker reading text plainly meets a bad index as it decodes the page,
    and says the file is not readable Parquet): the road columns are read, and checked, only when the run gives
    frames their road."""
    bad = corrupted_copy(excerpt_frames, tmp_path / "frames", column, damage)
    dataset = FramesDataset.open(tmp_path / "frames")
    part = next(p for p in dataset.parts if p.path == str(bad))
    worker = _refusal(lambda: read_frame_rows("", part.path, 0, part.rows, part.read_columns(road)))
    check = _refusal(lambda: dataset.check(FrameHasher(), road=road))
    assert (check is None) == (worker is None), (check, worker)
    if worker is not None:
        said = f"{bad} holds corrupt values in column {column} ("
        assert check.startswith(said) and "\n" not in check, check
        assert ("out of bounds: 5 (should be in [0, 1])" in check) == (damage == "index"), check
        assert worker.startswith(said if damage == "utf-8" else f"{bad} is not a readable Parquet file ("), worker
    assert (worker is None) == (not road and column not in FramesDataset.open(excerpt_frames).parts[0].columns)


@pytest.mark.parametrize("column,damage,options", [
    ("category", "utf-8", ()),
    ("category", "index", ()),
    ("lane", "utf-8", ("--lanes",)),
    ("track_id", "utf-8", ("--window", "1")),
], ids=["category", "category-index", "lane", "window"])
def test_a_run_refuses_a_corrupt_value_before_writing_anything(excerpt_frames, tmp_path, column, damage, options):
    """Small parts, one frame a task, two workers: the good parts' frames come first. Before the check read every
    column, the parts of the good frames whose tasks finished before the bad one's were written (with category and
    lane: an output folder with parts, left behind by a refusal)."""
    bad = corrupted_copy(excerpt_frames, tmp_path / "frames", column, damage)
    out = tmp_path / "programs"
    proc = run_r2s("run", str(tmp_path / "frames"), "--out", str(out), "--part-rows", "1", "--chunk-size", "1",
                   "--jobs", "2", *options, timeout=600)
    assert_one_line_error(proc, 2, f"{bad} holds corrupt values in column {column}")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames"]  # no output, parts, lock or temporary
