"""`r2s run --window` within its bounds (issue 35, items 8 and 15): the frames over all windows are counted on the
windows' (first, last) pairs and refused past MAX_WINDOW_FRAMES before any window is gathered; windows are
planned by bisection (O(n log n)); --max-gap, like --window and --stride, is at most MAX_WINDOW_S. Real processes
under the watchdog (tests.support.bounded): before, one scene of 20,000 frames with --window 3600 --stride
0.000001 printed nothing in 60 s, its memory rising past 800 MB; --max-gap 1e308 was an OverflowError (exit 1)."""

from __future__ import annotations

import sys
from pathlib import Path

import pandas as pd
import pytest

from frames.dataset import FramesDataset
from frames.frame_hash import FrameHasher
from frames.rows import read_frames, write_frames
from pipeline.batch import windows
from pipeline.batch.windows import WindowSpec, plan_windows
from pipeline.errors import UserError
from tests.support import ROOT
from tests.support.bounded import assert_refused, run_bounded

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"


def _one_long_scene(path: Path, frames: int) -> Path:
    """`frames` frames of one scene, 10 Hz, each ego and one car, from a real frame's two first rows."""
    rows = read_frames(KEYFRAMES)
    pair = rows[rows.frame_id == rows.frame_id.iloc[0]].head(2)
    df = pd.concat([pair] * frames, ignore_index=True)
    k = df.index // 2
    df["frame_id"] = "long/" + k.astype(str)
    df["scene"] = "long"
    df["frame_index"] = k.astype("int32")
    df["timestamp_us"] = k * 100_000
    write_frames(df, path)
    return path


@pytest.fixture(scope="module")
def long_scene(tmp_path_factory) -> Path:
    return _one_long_scene(tmp_path_factory.mktemp("long") / "frames.parquet", 20_000)


def test_windows_holding_too_many_frames_are_refused_before_they_are_gathered(long_scene, tmp_path):
    out = tmp_path / "w"
    result = run_bounded("run", str(long_scene), "--window", "3600", "--stride", "0.000001", "--out", str(out),
                         timeout=30, max_rss_mb=800)
    assert_refused(result, f"would hold 200,010,000 frames in all (10,000 per frame of the input), more than the "
                           f"bound of {windows.MAX_WINDOW_FRAMES:,}")
    assert result.seconds < 20, result.seconds
    assert list(tmp_path.iterdir()) == []  # no output, part or lock file


@pytest.mark.parametrize("option", ["--max-gap", "--stride", "--window"])
def test_window_durations_past_an_hour_are_one_line(long_scene, tmp_path, option):
    args = ["--window", "1", option, "1e308"] if option != "--window" else ["--window", "1e308"]
    result = run_bounded("run", str(long_scene), *args, "--out", str(tmp_path / "w"), timeout=30)
    assert_refused(result, "--window, --stride and --max-gap are at most 3600 s")
    assert list(tmp_path.iterdir()) == []


def test_the_bound_is_the_frames_over_all_windows(tmp_path, monkeypatch):
    """At the bound the run is planned; one frame more is refused. 30 frames, windows of 1 s every 0.5 s: every
    window holds 10 frames but the last two (10 and 5)."""
    path = _one_long_scene(tmp_path / "frames.parquet", 30)
    dataset = FramesDataset.open(path)
    hasher = FrameHasher(keep_lanes=True)
    dataset.check(hasher, road=False)
    spec = WindowSpec(1.0, 0.5)
    total = 5 * 10 + 5
    monkeypatch.setattr(windows, "MAX_WINDOW_FRAMES", total)
    units, hashes = plan_windows(dataset, hasher, spec)
    assert sum(len(u.frames) for u in units) == total and len(hashes) == len(units) == 6
    monkeypatch.setattr(windows, "MAX_WINDOW_FRAMES", total - 1)
    with pytest.raises(UserError, match=f"would hold {total} frames in all"):
        plan_windows(dataset, hasher, spec)


def test_tiling_is_bisection():
    """200,000 frames, one window over them all, a new one at every frame: 2e10 steps frame by frame, under a
    second by bisection."""
    code = ("from synth.window.program import tile\n"
            "w = tile(list(range(0, 20_000_000_000, 100_000)), 3_600_000_000, 1)\n"
            "assert len(w) == 200_000 and w[0] == (0, 35_999) and w[-1] == (199_999, 199_999)\n")
    result = run_bounded(command=[sys.executable, "-c", code], timeout=15, max_rss_mb=800)
    assert result.killed is None and result.returncode == 0, (result.killed, result.stderr[-400:])
