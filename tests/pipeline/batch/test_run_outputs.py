"""What `r2s run` leaves behind when things go wrong (issue 22 items 9 and 12), on real processes: a killed run's
workers end with it and its folders go with the next run; an output that cannot be written is refused before
any frame is computed, and a disk that fills up mid-run ends it with one line, whole files only."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from frames.rows import scene_to_rows, write_frames
from tests.support import ROOT, assert_one_line_error, run_r2s
from tests.support.faults import r2s_with_fault, small_filesystem


@pytest.fixture(scope="module")
def small_frames(tmp_path_factory, real_frames) -> Path:
    scenes = sorted(real_frames, key=lambda s: len(s.entities))[:6]
    path = tmp_path_factory.mktemp("small") / "frames.parquet"
    write_frames([r for i, s in enumerate(scenes) for r in scene_to_rows(s, source="test", frame_index=i)], path)
    return path


def _children(pid: int) -> list[int]:
    """Every process whose parent is `pid`, from /proc."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


def _alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc")
def test_kill_9_of_the_run_ends_its_workers_and_the_next_run_removes_its_progress_folder(small_frames, tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = {**os.environ, "TMPDIR": str(tmp)}
    out = tmp_path / "programs"
    proc = subprocess.Popen(r2s_with_fault("sleep=300@*", "run", str(small_frames), "--out", str(out), "--jobs", "2"),
                            cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    workers: list[int] = []
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and not (len(workers) >= 2 and list(tmp.glob("*progress*/*"))):
            time.sleep(0.3)
            workers = [p for p in _children(proc.pid) if "loky" in Path(f"/proc/{p}/cmdline").read_text()]
        assert len(workers) >= 2, "the workers did not start"
        proc.kill()  # kill -9: no handler runs, nothing is cleaned up by the run itself
        proc.wait(timeout=30)
        deadline = time.monotonic() + 15  # the workers poll their parent every 0.5 s
        while time.monotonic() < deadline and any(_alive(w) for w in workers):
            time.sleep(0.2)
        assert not any(_alive(w) for w in workers), "worker processes outlived a kill -9 of their run"
    finally:
        for w in workers:
            try:
                os.kill(w, signal.SIGKILL)
            except ProcessLookupError:
                pass
    left = [p.name for p in tmp.iterdir() if "progress" in p.name]
    assert len(left) == 1  # a kill -9 leaves it; the next run, on any output, removes it
    proc = subprocess.run([sys.executable, "-m", "pipeline.cli", "run", str(small_frames), "--out",
                           str(tmp_path / "other"), "--jobs", "1"], cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert [p.name for p in tmp.iterdir() if "progress" in p.name] == []
    assert run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "1").returncode == 0


def test_an_unwritable_output_is_refused_before_any_frame_is_computed(small_frames, tmp_path):
    """Read-only for root too (a read-only mount): the output directory itself (its parent is writable), or the
    folder it would be made in. One line, before even the input's check."""
    with small_filesystem(tmp_path / "programs", read_only=True) as ro:
        for out in (ro, ro / "programs.parquet", ro / "new" / "programs"):
            proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "1")
            assert_one_line_error(proc, 2, contains=f"cannot write in {ro}: read-only file system")


def test_a_full_disk_mid_run_ends_it_with_one_line_and_whole_files(small_frames, tmp_path):
    """Parts of one row each: the first fit on the 64 KB disk, a later one does not."""
    with small_filesystem(tmp_path / "full", size_kb=64) as disk:
        out = disk / "programs"
        proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "1", "--part-rows", "1",
                       "--chunk-size", "1")
        assert proc.returncode == 2, proc.stderr
        last = proc.stderr.strip().splitlines()[-1]
        assert "No space left on device" in last and "Traceback" not in proc.stderr
        names = sorted(p.name for p in out.iterdir()) if out.exists() else []
        assert all(n.startswith("part-") and n.endswith(".parquet") for n in names), names  # no temporaries
        for n in names:
            assert pq.read_table(out / n).num_rows == 1  # whole files, readable
        assert [p.name for p in disk.iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")] == []
