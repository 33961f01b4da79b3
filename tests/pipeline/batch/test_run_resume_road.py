"""Resume never keeps a stale program (issue 35 items 2 and 3, issue 34 item 4), as a user meets it: `r2s run --lanes`
on the shipped excerpt (extracted with its maps), per frame and per window, rerun after the road a frame reads
changed (a map's lanes moved by 0.5 m, a lane fact flipped) or by another synthesis revision of r2s. Whatever changed
is recomputed, and the output is then the one a fresh run writes; what did not change is kept."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from frames.maps import maps_dir
from synth.version import SYNTHESIS_REVISION, __version__
from tests.support import ROOT, assert_one_line_error, run_r2s

MOVED_MAP = "scene-0061"  # its 2 frames (1 window of 1 s) read it; the other 7 frames (4 windows) do not
FLIPPED_FRAME = "scene-0796/1"  # one entity's off_road flipped: this frame, and the window holding it
MODES = {"frames": ((), 9, 2, "frame"), "windows": (("--window", "1"), 5, 1, "window")}


def _run(frames: Path, out: Path, mode: str, tree: Path = ROOT) -> tuple[int, int, str]:
    """(computed, kept, stderr) of `r2s run --lanes` as the r2s of `tree` runs it."""
    proc = run_r2s("run", str(frames), "--lanes", "--out", str(out), "--jobs", "1", *MODES[mode][0], cwd=tree)
    assert proc.returncode == 0, proc.stderr
    computed, kept = re.search(r"\((\d+) computed, (\d+) kept\)", proc.stderr).groups()
    return int(computed), int(kept), proc.stderr


def _rows(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out).set_index("frame_id").sort_index()


def _same_as_fresh(frames: Path, out: Path, fresh: Path, mode: str) -> None:
    assert _run(frames, fresh, mode)[:2] == (MODES[mode][1], 0)
    got, want = _rows(out), _rows(fresh)
    for column in ("program", "scenic", "cost", "status", "frame_hash", "version", "config_hash"):
        assert got[column].tolist() == want[column].tolist(), column


def _move_lanes(frames: Path, map_id: str, dx: float) -> None:
    """Every lane of one map moved by dx metres along x (its polygon and centre line), as stored beside the frames."""
    for f in sorted(maps_dir(frames).glob("*.parquet")):
        table = pq.read_table(f)
        mine = pc.and_(pc.equal(table.column("map_id"), map_id), pc.equal(table.column("kind"), "lane")).to_pylist()
        for name in ("polygon_x", "line_x"):
            values = [[x + dx for x in v] if hit and v is not None else v
                      for v, hit in zip(table.column(name).to_pylist(), mine)]
            table = table.set_column(table.schema.get_field_index(name), name, pa.array(values, table.schema.field(name).type))
        pq.write_table(table, f)


def _flip_off_road(frames: Path, frame_id: str) -> None:
    """One non-ego entity of one frame said off road where it was not (or on it where it was)."""
    for f in sorted(frames.glob("part-*.parquet")):
        df = pq.read_table(f).to_pandas()
        rows = df.index[(df.frame_id == frame_id) & ~df.is_ego]
        if len(rows):
            df.loc[rows[0], "off_road"] = not df.loc[rows[0], "off_road"]
            pq.write_table(pa.Table.from_pandas(df, preserve_index=False), f)
            return
    raise AssertionError(f"no frame {frame_id}")


def _other_revision(tmp_path: Path) -> Path:
    """This tree's r2s at another synthesis revision: its packages copied, synth/version.py's revision changed."""
    tree = tmp_path / "other-revision"
    for package in ("synth", "extractors", "pipeline", "storage"):
        shutil.copytree(ROOT / package, tree / package, ignore=shutil.ignore_patterns("__pycache__"))
    version = tree / "synth" / "version.py"
    text = version.read_text()
    assert f"SYNTHESIS_REVISION = {SYNTHESIS_REVISION}\n" in text
    version.write_text(text.replace(f"SYNTHESIS_REVISION = {SYNTHESIS_REVISION}\n",
                                    f"SYNTHESIS_REVISION = {SYNTHESIS_REVISION + 1}\n"))
    return tree


@pytest.mark.parametrize("mode", list(MODES))
def test_resume_recomputes_what_another_revision_or_another_road_made_and_keeps_the_rest(excerpt_frames, tmp_path,
                                                                                         mode):
    frames, out = tmp_path / "frames", tmp_path / "programs"
    shutil.copytree(excerpt_frames, frames)
    n, moved, unit = MODES[mode][1:]

    # Rows another synthesis revision wrote are recomputed, whatever else is the same.
    assert _run(frames, out, mode, _other_revision(tmp_path))[:2] == (n, 0)
    assert set(_rows(out).version) == {f"{__version__}+synthesis.{SYNTHESIS_REVISION + 1}"}
    computed, kept, log = _run(frames, out, mode)
    assert (computed, kept) == (n, 0)
    assert f"recomputing {n} {unit}(s) whose rows another r2s version or synthesis revision wrote" in log
    assert set(_rows(out).version) == {f"{__version__}+synthesis.{SYNTHESIS_REVISION}"}

    # Nothing changed: everything kept, measured values and all.
    before = _rows(out)
    assert _run(frames, out, mode)[:2] == (0, n)
    assert _rows(out).runtime_s.tolist() == before.runtime_s.tolist()

    # One map's lanes 0.5 m away: exactly the frames (windows) that read that map are recomputed.
    _move_lanes(frames, MOVED_MAP, 0.5)
    computed, kept, log = _run(frames, out, mode)
    assert (computed, kept) == (moved, n - moved)
    assert "their road columns or the maps they name included" in log
    after = _rows(out)
    reads = after.index.str.startswith(MOVED_MAP)
    assert (after.frame_hash[reads] != before.frame_hash[reads]).all()
    assert after.runtime_s[~reads].tolist() == before.runtime_s[~reads].tolist()

    # One lane fact of one entity flipped (of another scene): its frame (its window) alone is recomputed.
    _flip_off_road(frames, FLIPPED_FRAME)
    assert _run(frames, out, mode)[:2] == (1, n - 1)
    # Every row, the moved map's and the flipped frame's included, is the one a fresh run writes.
    _same_as_fresh(frames, out, tmp_path / "fresh", mode)


def test_a_maps_file_that_cannot_be_read_refuses_a_lanes_run_before_anything_is_written(excerpt_frames, tmp_path):
    """The run's check reads every map once (to key each frame by the road it reads): an unreadable one is bad
    input, one line and exit 2, where it was an error row for each frame naming the map."""
    frames, out = tmp_path / "frames", tmp_path / "programs"
    shutil.copytree(excerpt_frames, frames)
    bad = sorted(maps_dir(frames).glob("*.parquet"))[1]
    bad.write_bytes(b"not parquet")
    proc = run_r2s("run", str(frames), "--lanes", "--out", str(out), "--jobs", "1")
    assert_one_line_error(proc, contains=f"{bad} is not a readable maps Parquet file")
    assert not out.exists()
