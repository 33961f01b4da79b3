"""Temporaries of atomic writes: named by host and pid, so that the next write of a target removes what a crashed
or killed writer left (issue 22 item 12), and never what a live writer, or another host's, is writing."""

from __future__ import annotations

import os
import subprocess
import sys

from storage.atomic import HOST_TAG, remove_stale, temp_prefix, write_text_atomic
from tests.support import ROOT, run_r2s


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(proc.stdout)


def test_a_dead_writers_temporaries_go_and_a_live_or_foreign_ones_stay(tmp_path):
    target = tmp_path / "scene.json"
    dead = _dead_pid()
    stale_file = tmp_path / f".scene.json.{HOST_TAG}-{dead}.abc123.tmp"
    stale_dir = tmp_path / f".scene.json.{HOST_TAG}-{dead}.def456.tmp"
    stale_old = tmp_path / f".scene.json.{HOST_TAG}-{dead}.def456.tmp.old"
    live = tmp_path / f".scene.json.{HOST_TAG}-{os.getppid()}.aaa.tmp"  # our parent: alive
    foreign = tmp_path / f".scene.json.0badc0de-{dead}.bbb.tmp"  # another host: its pid means nothing here
    other = tmp_path / f".other.json.{HOST_TAG}-{dead}.ccc.tmp"  # another target's
    user = tmp_path / ".scene.json.notes.tmp"  # not our naming
    for p in (stale_file, live, foreign, other, user):
        p.write_text("x")
    for d in (stale_dir, stale_old):
        d.mkdir()
        (d / "part-000000.parquet").write_text("x")
    write_text_atomic(target, "{}")
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == sorted(p.name for p in (target, live, foreign, other, user))
    assert temp_prefix(target) == f".scene.json.{HOST_TAG}-{os.getpid()}."
    assert remove_stale(target) == []


def test_the_next_run_of_a_verb_removes_what_a_crash_left(tmp_path):
    out = tmp_path / "scene.json"
    stale = tmp_path / f".scene.json.{HOST_TAG}-{_dead_pid()}.xyz.tmp"
    stale.write_text("half a scene")
    frames = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
    proc = run_r2s("scene", str(frames), "scene-0103/0", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]
