"""Frames files within their bounds (issue 22, item 7): a value is checked against its column chunk's size in the
footer before a byte of it is decoded, and frame ids are printable text of 1 to 256 characters in the frames
check every verb runs. Before: a 135 KB file with one 1 GiB frame_id cell made `r2s run` use 10.4 GB."""

from __future__ import annotations

import subprocess
import sys

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from tests.support import ROOT
from tests.support.bounded import assert_refused, run_bounded

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
HUGE = 100 * 10**6  # one cell of 100 MB: ~750 MB of memory for the verbs before, under 400 MB now

# Written in a child process: the writer needs several times the cell in memory, which the test process keeps.
MAKE = '''
import sys
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
src, out, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
t = pq.read_table(src).slice(0, 200)
fid = t.column("frame_id").to_pylist()
values = ["a" * n] + sorted(set(fid[1:]))  # the huge value once, in a dictionary
indices = np.array([0] + [values.index(f) for f in fid[1:]], dtype=np.int32)
column = pa.DictionaryArray.from_arrays(pa.array(indices), pa.array(values, pa.string()))
pq.write_table(t.set_column(t.schema.get_field_index("frame_id"), "frame_id", column), out, compression="zstd")
'''


@pytest.fixture(scope="module")
def huge_cell(tmp_path_factory):
    out = tmp_path_factory.mktemp("huge") / "frames.parquet"
    subprocess.run([sys.executable, "-c", MAKE, str(KEYFRAMES), str(out), str(HUGE)], check=True, timeout=300)
    assert out.stat().st_size < 200_000  # a small file: the size is in the cell, compressed away
    return out


@pytest.mark.parametrize("verb", [
    ("run", "{F}", "--out", "{D}/programs"),
    ("scene", "{F}", "scene-0061/1"),
    ("query", "{F}", "data/patterns/queue-of-three.dsl", "--out", "{D}/m.parquet"),
    ("eval-frontend", "{F}", str(KEYFRAMES), "--out", "{D}/eval"),
], ids=lambda v: v[0])
def test_a_huge_cell_is_refused_from_the_footer(verb, huge_cell, tmp_path):
    args = [a.format(F=huge_cell, D=tmp_path) for a in verb]
    result = run_bounded(*args, timeout=120, max_rss_mb=400)
    assert_refused(result, "column frame_id holds")
    assert len(result.stderr) < 400  # the value is never printed
    assert list(tmp_path.iterdir()) == []


def _with_frame_id(tmp_path, new_id: str):
    table = pq.read_table(KEYFRAMES)
    fid = table.column("frame_id").to_pylist()
    first = fid[0]
    fid = [new_id if f == first else f for f in fid]
    out = tmp_path / "frames.parquet"
    pq.write_table(table.set_column(table.schema.get_field_index("frame_id"), "frame_id", pa.array(fid, pa.string())),
                   out)
    return out


@pytest.mark.parametrize("new_id,shown", [("x" * 257, "x" * 40 + "'..."), ("bell\x07/0", r"'bell\x07/0'"),
                                          ("two\nlines/0", r"'two\nlines/0'"), ("", "''")],
                         ids=["257 characters", "control character", "newline", "empty"])
@pytest.mark.parametrize("verb", ["run", "scene", "query"])
def test_frame_ids_are_printable_and_at_most_256_characters(verb, new_id, shown, tmp_path):
    frames = _with_frame_id(tmp_path, new_id)
    args = {"run": ("run", str(frames), "--out", str(tmp_path / "programs")),
            "scene": ("scene", str(frames), new_id),  # scene reads the asked frame's rows only
            "query": ("query", str(frames), "data/patterns/queue-of-three.dsl", "--out", str(tmp_path / "m.parquet"))}
    result = run_bounded(*args[verb], timeout=120)
    assert_refused(result, "is not a printable string of 1 to 256 characters")
    assert shown in result.stderr
    assert not (tmp_path / "programs").exists() and not (tmp_path / "m.parquet").exists()


def test_ids_of_256_characters_are_fine(tmp_path):
    fid = "s" * 250 + "/0"
    frames = _with_frame_id(tmp_path, "s" * 250 + "/0")
    result = run_bounded("scene", str(frames), fid, timeout=120)
    assert result.returncode == 0, result.stderr


def _corrupt_category(tmp_path):
    """A frames file whose `category` (a column the frames check does not read, the workers do) holds one value that
    is not UTF-8: the bytes of a plain, uncompressed page patched in place, as a damaged disk or a hostile writer
    leaves them (the footer is intact)."""
    table = pq.read_table(KEYFRAMES).slice(0, 300)
    category = table.column("category").to_pylist()
    k = next(i for i, c in enumerate(category) if c and not table.column("is_ego")[i].as_py())
    category[k] = "ZZMARKERZZ"
    table = table.set_column(table.schema.get_field_index("category"), "category", pa.array(category, pa.string()))
    out = tmp_path / "frames.parquet"
    pq.write_table(table, out, compression="none", use_dictionary=False, write_statistics=False)
    data = out.read_bytes()
    assert data.count(b"ZZMARKERZZ") == 1
    out.write_bytes(data.replace(b"ZZMARKERZZ", b"ZZ\xff\xfeRKERZZ"))
    return out


def test_run_workers_read_frames_through_the_frames_checks(tmp_path):
    """Before: the workers decoded the bad value past every check (internal error, exit 1, the bytes printed). Now
    the run's own check decodes every column its workers read, and refuses the file before they start."""
    frames = _corrupt_category(tmp_path)
    out = tmp_path / "programs"
    result = run_bounded("run", str(frames), "--out", str(out), timeout=180)
    assert result.returncode == 2 and result.killed is None, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "holds corrupt values in column category" in lines[0], result.stderr
    assert "Traceback" not in result.stderr
    assert "resume" not in result.stderr and "\ufffd" not in result.stderr  # bad input, not a stop; no raw bytes
    assert not out.exists()


def test_the_workers_reader_checks_the_footer_of_the_file_as_it_is_now(huge_cell, tmp_path):
    """A file replaced after the run's check (a huge cell, a speed stored as text) is refused by the workers' own
    reader from its footer, before a value is decoded."""
    from frames.dataset import read_frame_rows
    from frames.schema import FramesError

    with pytest.raises(FramesError, match="column frame_id holds"):
        read_frame_rows("", str(huge_cell), 0, 10, ("frame_id", "x"))
    table = pq.read_table(KEYFRAMES).slice(0, 50)
    text = tmp_path / "speed.parquet"
    pq.write_table(table.append_column("speed", pa.array(["1.0"] * 50)), text)
    with pytest.raises(FramesError, match="column speed is string"):
        read_frame_rows("", str(text), 0, 10, ("frame_id", "speed"))
