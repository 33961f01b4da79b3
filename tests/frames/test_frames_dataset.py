"""Frames as a dataset (frames.dataset, storage.frame_index, pipeline.batch.rules.chunks) against plain
Python brute force: the streaming check, the frame runs and the worker's row reads must not depend on how the
rows are cut into row groups and files."""

from __future__ import annotations

import math
from collections import Counter
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given
from hypothesis import strategies as st

from frames.dataset import FramesDataset
from frames.rows import FRAMES_SCHEMA, FramesError, scene_to_rows, to_table
from pipeline.batch.rules import chunk_sizes, chunks
from storage.frame_index import FrameIndex, frame_hashes
from storage.parquet import read_rows
from synth.scene import ENTITY_TYPES, RESERVED_IDS
from tests.support import shipped_frames

# ------------------------------------------------------------------------------------------------ frame index

ids = st.text(alphabet="abc/-0123456789", min_size=0, max_size=6)


@given(st.lists(ids, max_size=40), st.lists(ids, max_size=40))
def test_frame_index_is_a_set(members, queries):
    index = FrameIndex(*frame_hashes(members))
    assert list(index.contains(*frame_hashes(queries))) == [q in set(members) for q in queries]
    dup_hi, _ = index.duplicated()
    assert len(dup_hi) == len(members) - len(set(members))


# ------------------------------------------------------------------------------------------------ chunks

@st.composite
def frame_runs(draw):
    """(part, starts, lengths, ids, todo) batches of consecutive frames, as FramesDataset.runs gives them."""
    batches, n = [], 0
    for part in range(draw(st.integers(1, 3))):
        row = 0
        for _ in range(draw(st.integers(0, 3))):
            lengths = np.array(draw(st.lists(st.integers(1, 5), min_size=1, max_size=6)), np.int64)
            starts = row + np.concatenate(([0], np.cumsum(lengths)[:-1]))
            row = int(starts[-1] + lengths[-1])
            names = np.array([f"f{n + i}" for i in range(len(lengths))], dtype=object)
            n += len(lengths)
            todo = np.array(draw(st.lists(st.booleans(), min_size=len(lengths), max_size=len(lengths))))
            batches.append((part, starts, lengths, names, todo))
    return batches


@given(frame_runs(), st.integers(1, 3), st.integers(1, 5), st.integers(1, 12))
def test_chunks_cover_the_frames_to_do_once_in_order(batches, slots, size, span):
    expected = [(k, (str(i), int(s), int(n))) for k, starts, lengths, names, todo in batches
                for s, n, i, t in zip(starts, lengths, names, todo) if t]
    got = list(chunks(iter(batches), chunk_sizes(slots, size), span))
    assert [(k, f) for k, frames in got for f in frames] == expected
    assert all(len(frames) == 1 for _, frames in got[:slots])  # every worker's first chunk is one frame
    for _, frames in got:
        assert 1 <= len(frames) <= size
        first, last = frames[0], frames[-1]
        assert last[1] + last[2] - first[1] <= max(span, first[2])  # a lone frame may exceed the span


# ------------------------------------------------------------------------------------------------ the check

FAULTS = ("none", "nan", "type", "no_ego", "bad_id", "reserved_id", "ego_named", "dup_entity", "split")
KIND = {"nan": "non-finite", "type": "unknown entity type", "no_ego": "exactly one ego",
        "bad_id": "not an identifier", "reserved_id": "reserved", "ego_named": "ego row only", "dup_entity": "twice",
        "split": "two places"}


def _brute_force(rows: list[dict]) -> str | None:
    """Which rule the rows break (the KIND words), by plain loops over the rows."""
    import re

    blocks: list[tuple[str, list[dict]]] = []
    for r in rows:
        if blocks and blocks[-1][0] == r["frame_id"]:
            blocks[-1][1].append(r)
        else:
            blocks.append((r["frame_id"], [r]))
    found = set()
    if len({b[0] for b in blocks}) < len(blocks):
        found.add("two places")
    by_id: dict[str, list[dict]] = {}
    for r in rows:
        by_id.setdefault(r["frame_id"], []).append(r)
    for frame in by_id.values():
        if any(not math.isfinite(r[c]) for r in frame for c in ("x", "y", "heading")):
            found.add("non-finite")
        if any(r["type"] not in ENTITY_TYPES for r in frame):
            found.add("unknown entity type")
        if sum(r["is_ego"] for r in frame) != 1:
            found.add("exactly one ego")
        for r in frame:
            if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", r["entity_id"]) or "__" in r["entity_id"]:
                found.add("not an identifier")
            elif r["entity_id"] in RESERVED_IDS and r["entity_id"] != "ego":
                found.add("reserved")
            if (r["entity_id"] == "ego") != r["is_ego"]:
                found.add("ego row only")
        names = [r["entity_id"] for r in frame]
        if len(set(names)) < len(names):
            found.add("twice")
    assert len(found) <= 1, found  # the generator plants one fault at a time
    return found.pop() if found else None


def _frames_rows(scenes) -> list[dict]:
    return [r for i, s in enumerate(scenes) for r in scene_to_rows(s, frame_index=i)]


def _plant(rows: list[dict], fault: str, at: int) -> list[dict]:
    rows = [dict(r) for r in rows]
    frames = list(dict.fromkeys(r["frame_id"] for r in rows))
    fid = frames[at % len(frames)]
    mine = [i for i, r in enumerate(rows) if r["frame_id"] == fid]
    ego = next(i for i in mine if rows[i]["is_ego"])
    other = next((i for i in mine if not rows[i]["is_ego"]), None)
    if fault == "nan":
        rows[mine[-1]]["y"] = float("nan")
    elif fault == "type":
        rows[mine[-1]]["type"] = "Spaceship"
    elif fault == "no_ego":
        rows[ego]["is_ego"] = False
        rows[ego]["entity_id"] = "car999"
    elif fault == "bad_id" and other is not None:
        rows[other]["entity_id"] = "car1); import os; ("
    elif fault == "reserved_id" and other is not None:
        rows[other]["entity_id"] = "lambda"
    elif fault == "ego_named" and other is not None:
        rows[ego]["entity_id"] = "car997"
    elif fault == "dup_entity" and other is not None:
        rows.insert(other + 1, dict(rows[other], x=rows[other]["x"] + 1.0))
    elif fault == "split" and len(frames) > 1:
        moved = rows.pop(mine[-1]) if len(mine) > 1 else None
        if moved is not None:
            rows.append(moved)
    return rows


SCENES = shipped_frames()


@given(st.lists(st.sampled_from(range(len(SCENES))), min_size=1, max_size=5, unique=True),
       st.sampled_from(FAULTS), st.integers(0, 10), st.lists(st.integers(1, 60), min_size=1, max_size=4),
       st.integers(0, 3))
def test_streaming_check_agrees_with_brute_force_whatever_the_row_groups(tmp_path_factory, picks, fault, at,
                                                                         cuts, files):
    scenes = [SCENES[i] for i in picks]
    rows = _plant(_frames_rows(scenes), fault, at)
    expected = _brute_force(rows)
    table = pa.Table.from_pylist(rows, schema=FRAMES_SCHEMA)
    tmp = tmp_path_factory.mktemp("check")
    # Cut the rows into files at arbitrary points (a cut inside a frame splits it: two places) and each file
    # into row groups of arbitrary sizes.
    bounds = sorted({0, table.num_rows, *(min(c * 7, table.num_rows) for c in cuts[:files])})
    for k, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        pq.write_table(table.slice(lo, hi - lo), tmp / f"part-{k:03d}.parquet", row_group_size=cuts[k % len(cuts)])
    path = tmp if len(bounds) > 2 else tmp / "part-000.parquet"
    split_by_files = any(rows[b - 1]["frame_id"] == rows[b]["frame_id"] for b in bounds[1:-1])
    try:
        checked = FramesDataset.open(path).check()
        n, index = checked.frames, checked.index
        verdict = None
    except FramesError as exc:
        verdict = str(exc)
    if split_by_files:  # a frame cut by a file boundary is refused: it is a frame id in two places
        assert verdict is not None and (expected in (None, "two places", "exactly one ego") or expected in verdict)
        assert "two places" in verdict or expected in verdict
    elif expected is None:
        assert verdict is None
        assert n == len({r["frame_id"] for r in rows}) == len(index)
        # the largest frame, however the row groups cut it
        assert checked.largest == max(Counter(r["frame_id"] for r in rows).values())
    else:
        assert verdict is not None and expected in verdict, (expected, verdict)
    # The in-memory check of a writer refuses the same rows for the same reason.
    try:
        to_table(rows)
        direct = None
    except FramesError as exc:
        direct = str(exc)
    assert (direct is None) == (expected is None) and (expected is None or expected in direct)


@given(st.lists(st.sampled_from(range(len(SCENES))), min_size=1, max_size=6, unique=True),
       st.integers(1, 80), st.data())
def test_runs_and_row_reads_do_not_depend_on_row_groups(tmp_path_factory, picks, group, data):
    rows = _frames_rows([SCENES[i] for i in picks])
    table = pa.Table.from_pylist(rows, schema=FRAMES_SCHEMA)
    path = tmp_path_factory.mktemp("runs") / "frames.parquet"
    pq.write_table(table, path, row_group_size=group)
    dataset = FramesDataset.open(path)
    got = [(str(i), int(s), int(n)) for r in dataset.runs() for i, s, n in zip(r.ids, r.starts, r.lengths)]
    expected, start = [], 0
    for fid in dict.fromkeys(r["frame_id"] for r in rows):
        n = sum(r["frame_id"] == fid for r in rows)
        expected.append((fid, start, n))
        start += n
    assert got == expected
    lo = data.draw(st.integers(0, table.num_rows - 1))
    hi = data.draw(st.integers(lo + 1, table.num_rows))
    assert read_rows("", str(path), lo, hi, ("frame_id", "entity_id", "x")).equals(
        table.select(["frame_id", "entity_id", "x"]).slice(lo, hi - lo))


def test_a_directory_of_parts_is_one_dataset(tmp_path):
    rows = _frames_rows(SCENES[:4])
    table = to_table(rows)
    cut = next(i for i, r in enumerate(rows) if r["frame_id"] == SCENES[2].frame_id)
    (tmp_path / "d" / "sub").mkdir(parents=True)
    pq.write_table(table.slice(0, cut), tmp_path / "d" / "a.parquet")
    pq.write_table(table.slice(cut), tmp_path / "d" / "sub" / "b.parquet")
    (tmp_path / "d" / "NOTICE").write_text("not data")  # other files are not parts
    pq.write_table(table.slice(0, 3), tmp_path / "d" / ".hidden.parquet")  # nor hidden ones
    dataset = FramesDataset.open(tmp_path / "d")
    assert [Path(p.path).name for p in dataset.parts] == ["a.parquet", "b.parquet"]
    n = dataset.check().frames
    assert n == 4
    assert dataset.read_all().equals(table)
    assert dataset.find(SCENES[3].frame_id).num_rows == len(SCENES[3].entities)
    assert dataset.find("no/such") is None


@pytest.mark.parametrize("kind", ["missing", "empty-dir", "not-parquet", "wrong-type"])
def test_bad_datasets_are_refused_in_one_line(tmp_path, kind):
    path = tmp_path / "frames"
    if kind == "empty-dir":
        path.mkdir()
    elif kind == "not-parquet":
        path.mkdir()
        (path / "x.parquet").write_bytes(b"PAR1 nope")
    elif kind == "wrong-type":
        table = to_table(_frames_rows(SCENES[:1]))
        table = table.set_column(table.schema.get_field_index("x"), "x", table.column("x").cast(pa.string()))
        path = tmp_path / "frames.parquet"
        pq.write_table(table, path)
    with pytest.raises(FramesError) as err:
        FramesDataset.open(path).check()
    assert "\n" not in str(err.value) and str(path) in str(err.value)


def test_a_rewritten_file_is_read_again_not_served_from_the_cache(tmp_path):
    """Workers cache open files and row groups; a file rewritten in place (atomically, same size: only the values
    differ) between two reads of one process must give its new rows (issue 22: stale results)."""
    from frames.rows import write_frames

    path = tmp_path / "frames.parquet"
    rows = scene_to_rows(shipped_frames()[0], source="test")
    write_frames(rows, path)
    before = read_rows("", str(path), 0, len(rows), ("frame_id", "x"))
    write_frames([dict(r, x=r["x"] + 1.0) for r in rows], path)
    after = read_rows("", str(path), 0, len(rows), ("frame_id", "x"))
    assert after.column("x").to_pylist() == [x + 1.0 for x in before.column("x").to_pylist()]
