"""`r2s report` on window programs (r2s run --window): the Windows section's numbers against the same numbers
computed here with pandas from the files, and its options refused where they cannot apply."""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd
import pyarrow.parquet as pq
import pytest

from frames.rows import read_frames, write_frames
from tests.support import ROOT, assert_one_line_error, run_r2s

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> tuple[Path, Path, Path]:
    """(frames, window programs at 1 s, per-frame programs) for two nuScenes scenes' first 8 keyframes."""
    tmp = tmp_path_factory.mktemp("windows")
    df = pq.read_table(KEYFRAMES).to_pandas()
    df = df[df.scene.isin(["scene-0061", "scene-0757"]) & (df.frame_index < 8)]
    frames = tmp / "frames.parquet"
    write_frames(df, frames)
    for out, more in ((tmp / "windows", ("--window", "1")), (tmp / "frames-programs", ())):
        proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2", *more)
        assert proc.returncode == 0, proc.stderr
    return frames, tmp / "windows", tmp / "frames-programs"


def section_rows(report: Path, header_start: str) -> list[list[str]]:
    """The rows of the Windows section's table whose header starts with `header_start`, as cells."""
    text = report.read_text()
    section = text[text.index("## Windows"):]
    lines = section.splitlines()
    at = next(i for i, ln in enumerate(lines) if ln.startswith(f"| {header_start}"))
    rows = []
    for ln in lines[at + 2:]:
        if not ln.startswith("|"):
            break
        rows.append([c.strip() for c in ln.strip("|").split("|")])
    return rows


def test_the_windows_section_says_what_the_files_say(runs, tmp_path):
    frames, windows, singles = runs
    out = tmp_path / "report"
    proc = run_r2s("report", str(windows), "--out", str(out), "--frames", str(frames), "--frame-programs",
                   str(singles))
    assert proc.returncode == 0, proc.stderr
    w = pq.read_table(windows).to_pandas().sort_values(["scene", "first_timestamp_us"])
    pairs = same = shape = both = kept = 0
    for _, g in w.groupby("scene"):
        texts = g.program.tolist()
        shapes = [re.sub(r"Range\([^)]*\)", "Range", t) for t in texts]
        pairs += len(texts) - 1
        same += sum(a == b for a, b in zip(texts, texts[1:]))
        shape += sum(a == b for a, b in zip(shapes, shapes[1:]))
        statements = [{ln.split(" = new ")[0]: ln for ln in t.splitlines()} for t in shapes]
        for a, b in zip(statements, statements[1:]):
            common = a.keys() & b.keys()
            both += len(common)
            kept += sum(a[i] == b[i] for i in common)
    [row] = section_rows(out / "report.md", "window")
    assert row[2] == str(len(w)) and row[3] == f"{w.n_frames.mean():.1f}" and row[5] == f"{w.cost.mean():.2f}"
    assert row[6] == str(pairs)
    assert row[7] == f"{100 * same / pairs:.1f}% ({same})" and row[8] == f"{100 * shape / pairs:.1f}% ({shape})"
    assert row[10] == f"{100 * kept / both:.1f}% ({kept})" and 0 < kept < both
    # Costs: each window beside its frames' own optimal costs, placed by scene and timestamp.
    f = read_frames(frames).drop_duplicates("frame_id")[["frame_id", "scene", "timestamp_us"]]
    s = pq.read_table(singles).to_pandas().set_index("frame_id").cost
    dearest, means = [], []
    for _, win in w.iterrows():
        inside = f[(f.scene == win.scene) & f.timestamp_us.between(win.first_timestamp_us, win.last_timestamp_us)]
        assert len(inside) == win.n_frames
        dearest.append(s[inside.frame_id].max())
        means.append(s[inside.frame_id].mean())
    [row] = section_rows(out / "report.md", "window | config hash | windows compared")
    assert row[2] == str(len(w)) and row[3] == f"{w.cost.mean():.2f}"
    assert row[4] == f"{pd.Series(dearest).mean():.2f}" and row[5] == f"{pd.Series(means).mean():.2f}"
    assert row[6] == str(int((w.cost.to_numpy() > dearest).sum()))
    assert all(c >= d for c, d in zip(w.cost, dearest))  # a window never costs less than its dearest frame
    assert "Windows" in (out / "report.html").read_text()


def test_per_frame_programs_have_no_windows_section_and_refuse_frame_programs(runs, tmp_path):
    frames, windows, singles = runs
    proc = run_r2s("report", str(singles), "--out", str(tmp_path / "r"))
    assert proc.returncode == 0, proc.stderr
    assert "## Windows" not in (tmp_path / "r" / "report.md").read_text()
    assert_one_line_error(run_r2s("report", str(singles), "--out", str(tmp_path / "r2"), "--frames", str(frames),
                                  "--frame-programs", str(singles)), 2, "per-frame programs")
    assert not (tmp_path / "r2").exists()
    assert_one_line_error(run_r2s("report", str(windows), "--out", str(tmp_path / "r3"), "--frame-programs",
                                  str(singles)), 2, "needs --frames")
