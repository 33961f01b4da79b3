"""`r2s run` as a user runs it: real frames, real worker processes, real kills. No timed assertions: limits are
checked through the statuses they produce, resume through rows that keep their measured values."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from frames.rows import frame_to_scene, read_frames, scene_to_rows, write_frames
from pipeline.batch import pool as run_pool
from pipeline.batch.pool import LokyPool, compute
from pipeline.batch.rules import PartBuffer, summarize
from pipeline.batch.task import ChunkTask
from pipeline.programs import failure_row, programs_table, read_programs
from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.semantics import check
from synth.version import ROWS_VERSION
from tests.support import ROOT, assert_one_line_error, run_r2s, wait_for_file
from tests.support.faults import fault, r2s_with_fault

EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"


# ---------------------------------------------------------------------------------------------------- helpers

def _write_scenes(scenes, path: Path) -> Path:
    rows = [r for i, s in enumerate(scenes) for r in scene_to_rows(s, source="test", frame_index=i)]
    write_frames(rows, path)
    return path


def _frame_ids(path: Path) -> list[str]:
    return list(dict.fromkeys(read_frames(path)["frame_id"]))


def _programs(out: Path):
    """One row per frame, indexed by frame id, in frame-id order (rows come in the order frames finished)."""
    df = read_programs(out)
    assert df["frame_id"].is_unique, df["frame_id"][df["frame_id"].duplicated()].tolist()
    return df.set_index("frame_id", drop=False).sort_index()


def _summary(stderr: str) -> str:
    lines = [ln for ln in stderr.splitlines() if " frames (" in ln and " computed, " in ln]
    assert len(lines) == 1, stderr
    return lines[0]


def _assert_programs_contain_scenes(frames: Path, out: Path, config: SynthConfig) -> None:
    df = read_frames(frames)
    programs = _programs(out)
    for fid, rows in df.groupby("frame_id", sort=False):
        row = programs.loc[fid]
        assert row["program"] is not None, (fid, row["status"], row["error"])
        result = check(parse_program(row["program"]), frame_to_scene(rows), config)
        assert result.ok, (fid, [str(v) for v in result.violations])


def _assert_nothing_written(out: Path) -> None:
    assert not out.exists()
    assert not Path(f"{out}.parts").exists()
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(f".{out.name}")] == []


@pytest.fixture(scope="module")
def json_frames(tmp_path_factory, real_frames) -> Path:
    """The 18 shipped nuScenes-mini keyframes (4 to 141 entities) as a frames file."""
    return _write_scenes(real_frames, tmp_path_factory.mktemp("frames") / "frames.parquet")


@pytest.fixture(scope="module")
def small_frames(tmp_path_factory, real_frames) -> Path:
    """Six small real frames: fast enough to run several times."""
    scenes = sorted(real_frames, key=lambda s: len(s.entities))[:6]
    return _write_scenes(scenes, tmp_path_factory.mktemp("small") / "frames.parquet")


# ---------------------------------------------------------------------------------------------- the pipeline

def test_extract_then_run_with_two_jobs(tmp_path):
    frames, out = tmp_path / "frames.parquet", tmp_path / "programs.parquet"
    proc = run_r2s("extract", "scenarionet", str(EXCERPT), "--out", str(frames), "--categories", "all")
    assert proc.returncode == 0, proc.stderr
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    order = _frame_ids(frames)
    df = read_programs(out)
    assert sorted(df["frame_id"]) == sorted(order)  # every frame once
    assert set(df["status"]) == {"optimal"}
    assert set(df["config_hash"]) == {SynthConfig().semantic_hash()}
    assert (df["cost"] == df["lower_bound"]).all()
    _assert_programs_contain_scenes(frames, out, SynthConfig())
    assert not Path(f"{out}.parts").exists()
    assert f"{len(order)} frames ({len(order)} computed, 0 kept), 100.0% optimal" in _summary(proc.stderr)


def test_a_frame_whose_rows_changed_is_recomputed_never_kept(tmp_path):
    """The stale resume of issue 22: extract vehicles, run, extract every category into the same path, run again
    into the same output: every frame gained entities, so every program is recomputed and declares them; then
    one entity of one frame moves, and only that frame is recomputed."""
    frames, out = tmp_path / "frames.parquet", tmp_path / "programs"
    extract = ("extract", "scenarionet", str(EXCERPT), "--out", str(frames))
    assert run_r2s(*extract, "--categories", "vehicles").returncode == 0
    assert run_r2s("run", str(frames), "--out", str(out), "--jobs", "2").returncode == 0
    before = _programs(out)
    assert not before["program"].str.contains("Pedestrian").any()
    assert run_r2s(*extract, "--categories", "all").returncode == 0
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    n = len(_frame_ids(frames))
    assert f"({n} computed, 0 kept)" in _summary(proc.stderr)
    assert _summary(proc.stderr).endswith(f"; {n} recomputed because their rows changed -> {out}")
    assert f"recomputing {n} frame(s) whose rows changed since their program was made" in proc.stderr
    after = _programs(out)
    assert after["program"].str.contains("Pedestrian").any()
    assert (after["n_entities"] > before["n_entities"]).all()
    _assert_programs_contain_scenes(frames, out, SynthConfig())

    df = read_frames(frames)
    victim = df["frame_id"].iloc[-1]
    row = df.index[(df["frame_id"] == victim) & ~df["is_ego"]][0]
    df.loc[row, "x"] += 3.0
    write_frames(df, frames)
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    assert f"(1 computed, {n - 1} kept)" in _summary(proc.stderr) and "; 1 recomputed because" in proc.stderr
    again = _programs(out)
    kept = [f for f in again.index if f != victim]
    assert list(again.loc[kept, "runtime_s"]) == list(after.loc[kept, "runtime_s"])
    assert again.loc[victim, "frame_hash"] != after.loc[victim, "frame_hash"]
    _assert_programs_contain_scenes(frames, out, SynthConfig())


def test_rows_without_a_frame_hash_are_recomputed_and_still_read(small_frames, tmp_path):
    """A programs file of a version before frame_hash: its rows are read (report, merge) but never reused, since
    what they were computed from is unknown."""
    out = tmp_path / "programs.parquet"
    assert run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2").returncode == 0
    old = pq.read_table(out)
    pq.write_table(old.drop_columns(["frame_hash"]), out)
    assert read_programs(out)["frame_hash"].isna().all()
    proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    assert "recomputing 6 frame(s) whose rows were written without a frame_hash" in proc.stderr
    assert "(6 computed, 0 kept)" in _summary(proc.stderr)
    assert read_programs(out)["frame_hash"].notna().all()


def test_rerun_keeps_rows_and_a_new_config_replaces_them(small_frames, tmp_path):
    out = tmp_path / "programs.parquet"
    assert run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2").returncode == 0
    first = _programs(out)
    proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    assert "(0 computed, 6 kept)" in _summary(proc.stderr)
    again = _programs(out)
    assert list(again["runtime_s"]) == list(first["runtime_s"])  # not recomputed: the measured values stay

    proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2", "--strategy", "astar-cpa")
    assert proc.returncode == 0, proc.stderr
    assert "recomputing 6 frame(s) whose rows have another config hash" in proc.stderr
    replaced = _programs(out)
    assert list(replaced["frame_id"]) == list(first["frame_id"])
    assert set(replaced["strategy"]) == {"astar-cpa"}
    assert set(replaced["config_hash"]) == {SynthConfig(strategy="astar-cpa").semantic_hash()}
    assert list(replaced["cost"]) == list(first["cost"])  # both strategies are exact


def test_killed_run_resumes_without_duplicates_or_recomputation(json_frames, tmp_path):
    out = tmp_path / "programs.parquet"
    parts = Path(f"{out}.parts")
    proc = subprocess.Popen(  # every frame slowed down, so that the kill lands mid-run
        r2s_with_fault("sleep=0.4@*", "run", str(json_frames), "--out", str(out), "--jobs", "2", "--part-rows", "1"),
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 240
        while not list(parts.glob("part-*.parquet")) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        assert proc.poll() is None, "the run ended before it could be killed"
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the run and its workers
        proc.wait()
    assert not out.exists()
    saved = {r["frame_id"]: r for p in sorted(parts.glob("part-*.parquet")) for r in pq.read_table(p).to_pylist()}
    order = _frame_ids(json_frames)
    assert 1 <= len(saved) < len(order)

    proc = run_r2s("run", str(json_frames), "--out", str(out), "--jobs", "2", "--part-rows", "1")
    assert proc.returncode == 0, proc.stderr
    assert f"({len(order) - len(saved)} computed, {len(saved)} kept)" in _summary(proc.stderr)
    done = _programs(out)  # complete, no duplicate
    assert sorted(done["frame_id"]) == sorted(order)
    for fid, row in saved.items():  # the rows of the killed run, untouched
        assert done.loc[fid, "runtime_s"] == row["runtime_s"]
        assert done.loc[fid, "peak_rss_mb"] == row["peak_rss_mb"]
    assert not parts.exists()
    _assert_programs_contain_scenes(json_frames, out, SynthConfig())


def test_a_second_run_on_the_same_out_is_refused_and_sigterm_stops_the_first(json_frames, tmp_path):
    """Two runs on one output would overwrite each other's parts: the second is refused while the first holds
    the lock. A scheduler's stop must not wait for slow frames: their workers are killed, none is left behind."""
    out = tmp_path / "programs.parquet"
    proc = subprocess.Popen(  # every frame would take two minutes
        r2s_with_fault("sleep=120@*", "run", str(json_frames), "--out", str(out), "--jobs", "2"),
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True,
    )
    try:
        time.sleep(4)  # workers started and sleeping in their first frames
        assert proc.poll() is None
        # Another TMPDIR, another working directory and a relative --out: the lock is with the output, not in /tmp.
        other_tmp = tmp_path / "other-tmp"
        other_tmp.mkdir()
        second = subprocess.run([sys.executable, "-m", "pipeline.cli", "run", str(json_frames), "--out", out.name,
                                 "--jobs", "1"], cwd=tmp_path, capture_output=True, text=True, timeout=300,
                                env={**os.environ, "TMPDIR": str(other_tmp), "PYTHONPATH": str(ROOT)})
        assert_one_line_error(second, 2, contains=f"another r2s run (pid {proc.pid} on ")
        assert f"is writing {out.name} (lock {tmp_path / ('.' + out.name + '.lock')})" in second.stderr
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)  # far less than the frames in flight would take
        assert proc.returncode == 128 + signal.SIGTERM
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            try:
                os.killpg(proc.pid, 0)  # anyone left in the run's process group?
            except ProcessLookupError:
                break
            time.sleep(0.2)
        else:
            pytest.fail("worker processes outlived the run")
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other-tmp"]  # the lock file went with the run


def test_the_lock_dies_with_its_run_and_the_next_run_takes_it(small_frames, tmp_path):
    """kill -9 leaves the lock file but not the lock: the kernel drops it with the process."""
    out = tmp_path / "programs"
    proc = subprocess.Popen(r2s_with_fault("sleep=120@*", "run", str(small_frames), "--out", str(out), "--jobs", "1"),
                            cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    try:
        lock = tmp_path / ".programs.lock"
        assert wait_for_file(lock) and f'"pid": {proc.pid}' in lock.read_text()
        proc.kill()
        proc.wait(timeout=30)
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    assert "(6 computed, 0 kept)" in _summary(proc.stderr)
    assert not lock.exists()


def test_the_lock_without_record_locks_uses_its_holder(tmp_path, monkeypatch):
    """A filesystem without record locks (ENOLCK): the file's host and pid decide; a dead holder here is stale."""
    import errno
    import fcntl
    import json
    import socket

    from pipeline.batch.lock import OutputLock
    from pipeline.errors import UserError

    def no_locks(*_args):
        raise OSError(errno.ENOLCK, "No locks available")

    monkeypatch.setattr(fcntl, "lockf", no_locks)
    out = tmp_path / "programs"
    lock = OutputLock(out)
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    for host, pid, refused in ((socket.gethostname(), int(dead.stdout), False),
                               (socket.gethostname(), os.getppid(), True), ("elsewhere", os.getpid(), True)):
        lock.path.write_text(json.dumps({"host": host, "pid": pid, "since": "then"}))
        if refused:
            with pytest.raises(UserError, match=f"pid {pid} on {host}"):
                lock.acquire()
            assert json.loads(lock.path.read_text())["pid"] == pid
        else:
            lock.acquire()
            assert json.loads(lock.path.read_text())["pid"] == os.getpid()
            with pytest.raises(UserError, match="another r2s run"):
                OutputLock(out).acquire()
            lock.release()
            assert not lock.path.exists()


# --------------------------------------------------------------------------------------------------- limits

def test_time_limit_gives_the_best_program_and_a_lower_bound(real_frames, tmp_path):
    scenes = [min(real_frames, key=lambda s: len(s.entities)), max(real_frames, key=lambda s: len(s.entities))]
    frames = _write_scenes(scenes, tmp_path / "frames.parquet")
    out = tmp_path / "programs.parquet"
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2", "--strategy", "bfs", "--time-limit", "0.2")
    assert proc.returncode == 0, proc.stderr
    small, big = (_programs(out).loc[s.frame_id] for s in scenes)
    assert small["status"] == "optimal"
    assert big["status"] in ("feasible", "timeout")
    assert big["lower_bound"] < big["cost"]
    config = SynthConfig(strategy="bfs", time_limit=0.2)
    _assert_programs_contain_scenes(frames, out, config)


def test_memory_limit_below_the_baseline_is_memout(real_frames, tmp_path):
    # 1 MB is below any Python process: the Budget's RSS poll (every 4096 nodes) stops BFS on the large frame;
    # the small one finishes before its first poll.
    scenes = [min(real_frames, key=lambda s: len(s.entities)), max(real_frames, key=lambda s: len(s.entities))]
    frames = _write_scenes(scenes, tmp_path / "frames.parquet")
    out = tmp_path / "programs.parquet"
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2", "--strategy", "bfs",
                   "--memory-limit", "1")
    assert proc.returncode == 0, proc.stderr
    small, big = (_programs(out).loc[s.frame_id] for s in scenes)
    assert small["status"] == "optimal"
    assert big["status"] == "memout"
    assert big["program"] is not None  # anytime: the best program found so far is kept
    assert "1 memout" in _summary(proc.stderr)


@pytest.mark.parametrize(
    ("hook", "limit", "status", "message"),
    [
        ("kill", None, "memout", "worker died (exit code SIGKILL(-9))"),  # as the OOM killer does
        ("exit", None, "error", "worker died (exit code"),
        ("alloc=4000", "300", "memout", "hard cap"),  # the RLIMIT_AS cap turns it into a MemoryError
        ("raise", None, "error", "RuntimeError: fault injected in frame"),
    ],
)
def test_a_failing_frame_is_recorded_and_the_run_goes_on(small_frames, tmp_path, hook, limit, status, message):
    order = _frame_ids(small_frames)
    victim = order[2]
    out = tmp_path / "programs.parquet"
    args = ["run", str(small_frames), "--out", str(out), "--jobs", "2"] + (["--memory-limit", limit] if limit else [])
    proc = subprocess.run(r2s_with_fault(f"{hook}@{victim}", *args), cwd=ROOT, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    df = _programs(out)
    assert sorted(df["frame_id"]) == sorted(order)
    assert df.loc[victim, "status"] == status
    assert message in df.loc[victim, "error"]
    assert "\n" not in df.loc[victim, "error"]
    assert set(df.drop(index=victim)["status"]) == {"optimal"}  # the innocent frames in flight got programs


def _chunk_tasks(frames: Path, size: int, hook: str | None = None, progress: Path | None = None,
                 config: SynthConfig | None = None) -> list[ChunkTask]:
    """The run's own chunking of a frames file into tasks of `size` frames (progress markers in `progress`)."""
    from frames.dataset import FramesDataset
    from pipeline.batch.rules import chunks

    config = config or SynthConfig()
    dataset = FramesDataset.open(frames)
    runs = ((r.part, r.starts, r.lengths, r.ids, r.lengths > 0) for r in dataset.runs())
    return [ChunkTask(f"t{n}", "", dataset.parts[k].path, tuple(fr), dataset.parts[k].columns, config,
                      hard_cap=True, synthesizer=hook and fault(hook), progress_dir=None if progress is None else str(progress))
            for n, (k, fr) in enumerate(chunks(runs, size, 10**6))]


def _rows_of(tables) -> dict[str, dict]:
    rows = [r for t in tables if t is not None for r in t.to_pylist()]
    by_id = {r["frame_id"]: r for r in rows}
    assert len(by_id) == len(rows), "a frame came back twice"
    return by_id


@pytest.mark.parametrize(("hook", "status", "message"), [
    ("kill", "memout", "SIGKILL"),
    ("exit", "error", "worker died (exit code"),
])
def test_a_death_inside_a_chunk_blames_only_the_frame_it_was_running(small_frames, tmp_path, hook, status,
                                                                      message):
    """Chunks of three frames on two workers: the dead chunk's marker names the frame it was running; its other
    frames, and the other chunk's, are innocent and get their programs."""
    order = _frame_ids(small_frames)
    victim = order[4]  # the middle of the second chunk
    tasks = _chunk_tasks(small_frames, 3, f"{hook}@{victim}", tmp_path)
    assert [len(t.frames) for t in tasks] == [3, 3]
    log: list[str] = []
    rows = _rows_of(compute(LokyPool(2), tasks, log.append))
    assert sorted(rows) == sorted(order)
    assert rows[victim]["status"] == status and message in rows[victim]["error"]
    assert all(rows[f]["status"] == "optimal" for f in order if f != victim)
    blamed = [line for line in log if "recorded as" in line]
    assert len(blamed) == 1 and victim in blamed[0]
    # At most one suspect per chunk in flight (two), never the six frames of both chunks.
    assert not any("6 frames in flight" in line or "3 frames in flight" in line for line in log)
    assert list(tmp_path.iterdir()) == []  # no marker left behind


def test_wall_clock_guard_kills_a_hung_frame(small_frames, tmp_path):
    order = _frame_ids(small_frames)
    hung = order[1]
    tasks = _chunk_tasks(small_frames, 2, f"hang@{hung}", tmp_path)
    log: list[str] = []
    # The guard is timed from a frame's start, which for a cold worker includes importing the core: 6 s keeps a
    # loaded machine (a quarter core a worker) from blaming a healthy frame.
    rows = _rows_of(compute(LokyPool(2, guard_s=6.0), tasks, log.append))
    assert sorted(rows) == sorted(order)
    assert rows[hung]["status"] == "timeout"
    assert "wall-clock guard" in rows[hung]["error"]
    assert all(rows[f]["status"] == "optimal" for f in order if f != hung)
    assert any(hung in line for line in log)


def test_heartbeats_while_no_frame_finishes(small_frames, tmp_path, monkeypatch):
    # The run writes a waiting part on a heartbeat, so a slow frame does not hold finished rows back.
    monkeypatch.setattr(run_pool, "HEARTBEAT_S", 0.1)
    (task, *_) = _chunk_tasks(small_frames, 1, "sleep=1.5@*", tmp_path)
    out = list(compute(LokyPool(1), [task], print))
    assert out[-1].column("frame_id").to_pylist() == [task.frames[0][0]]
    assert None in out[:-1]


def test_a_frame_that_is_not_a_scene_is_an_error_row(small_frames, tmp_path):
    df = read_frames(small_frames)
    # The file as a whole is valid (bad ids or types refuse it whole, see test_extract_untrusted); this frame has an
    # entity beyond the coordinates a scene supports (2e6 m away), which only the frame's own validation sees.
    bad = df["frame_id"].iloc[-1]
    df.loc[(df["frame_id"] == bad) & ~df["is_ego"], "x"] = 2e6
    frames, out = tmp_path / "frames.parquet", tmp_path / "programs.parquet"
    write_frames(df, frames)
    proc = run_r2s("run", str(frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    programs = _programs(out)
    assert programs.loc[bad, "status"] == "error"
    assert "supported range" in programs.loc[bad, "error"]
    assert (programs.drop(index=bad)["status"] == "optimal").all()


# ------------------------------------------------------------------------------------------------ bad input

@pytest.mark.parametrize("kind", ["missing", "corrupt", "wrong-schema", "directory", "empty"])
def test_bad_frames_file_exits_2_and_writes_nothing(tmp_path, small_frames, kind):
    frames, out = tmp_path / "frames.parquet", tmp_path / "programs.parquet"
    if kind == "corrupt":
        frames.write_bytes(small_frames.read_bytes()[: 300] + b"\x00garbage")
    elif kind == "wrong-schema":
        pq.write_table(pq.read_table(small_frames).drop(["heading", "is_ego"]), frames)
    elif kind == "directory":
        frames.mkdir()
    elif kind == "empty":
        write_frames(read_frames(small_frames).iloc[:0], frames)
    proc = run_r2s("run", str(frames), "--out", str(out))
    assert_one_line_error(proc, 2)
    _assert_nothing_written(out)


@pytest.mark.parametrize(
    ("extra", "contains"),
    [
        (["--jobs", "0"], "--jobs"),
        (["--chunk-size", "0"], "--chunk-size"),
        (["--time-limit", "-1"], "time_limit"),
        (["--scheduler", "tcp://127.0.0.1:8786"], "--backend dask"),
        (["--strategy", "nope"], "strategy"),
    ],
)
def test_bad_options_exit_2_and_write_nothing(small_frames, tmp_path, extra, contains):
    out = tmp_path / "programs.parquet"
    proc = run_r2s("run", str(small_frames), "--out", str(out), *extra)
    assert_one_line_error(proc, 2, contains)
    _assert_nothing_written(out)


def test_an_output_that_is_not_a_programs_file_is_not_overwritten(small_frames, tmp_path):
    out = tmp_path / "programs.parquet"
    out.write_text("my notes\n")
    proc = run_r2s("run", str(small_frames), "--out", str(out))
    assert_one_line_error(proc, 2, "not a readable parquet")
    assert out.read_text() == "my notes\n"
    assert not Path(f"{out}.parts").exists()
    proc = run_r2s("run", str(small_frames), "--out", str(small_frames))
    assert_one_line_error(proc, 2, "is the input frames")


# ------------------------------------------------------------------------------------------------------ dask

def test_dask_backend_on_a_running_scheduler(small_frames, tmp_path):
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install '.[dask]')")
    import logging

    out = tmp_path / "programs.parquet"
    # Threads in this process: the worker imports r2sgen as the tests do, and the run connects over TCP.
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        proc = run_r2s("run", str(small_frames), "--out", str(out), "--backend", "dask",
                       "--scheduler", cluster.scheduler_address)
    assert proc.returncode == 0, proc.stderr
    df = _programs(out)
    assert sorted(df["frame_id"]) == sorted(_frame_ids(small_frames))
    assert set(df["status"]) == {"optimal"}
    _assert_programs_contain_scenes(small_frames, out, SynthConfig())


def test_dask_scheduler_that_does_not_answer_exits_2(small_frames, tmp_path):
    pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install '.[dask]')")
    out = tmp_path / "programs.parquet"
    proc = run_r2s("run", str(small_frames), "--out", str(out), "--backend", "dask", "--scheduler", "tcp://127.0.0.1:9")
    assert_one_line_error(proc, 2, "cannot reach the dask scheduler")
    _assert_nothing_written(out)


def test_dask_local_cluster_replaces_a_dead_worker(small_frames, tmp_path):
    pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install '.[dask]')")
    order = _frame_ids(small_frames)
    victim = order[1]
    out = tmp_path / "programs.parquet"
    # No --scheduler: r2s run starts its own LocalCluster. Dask gives up on the task at its first worker death.
    env = dict(os.environ, DASK_DISTRIBUTED__SCHEDULER__ALLOWED_FAILURES="0")
    proc = subprocess.run(r2s_with_fault(f"kill@{victim}", "run", str(small_frames), "--out", str(out),
                                         "--backend", "dask", "--jobs", "2"), cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    df = _programs(out)
    assert sorted(df["frame_id"]) == sorted(order)
    assert df.loc[victim, "status"] == "error"
    assert df.loc[victim, "error"].startswith("worker died")
    assert set(df.drop(index=victim)["status"]) == {"optimal"}


# -------------------------------------------------------------------------------------------- pure logic

SAME, OTHER = "0123456789abcdef" * 2, "fedcba9876543210" * 2  # frame hashes: the input's, and other rows'


CONFIGS = {"h1": SynthConfig(), "h0": SynthConfig(strategy="astar-cpa")}  # the run's config, and another


def _row(fid: str, h: str = "h1", status: str = "optimal", runtime: float = 1.0, rows: str | None = SAME) -> dict:
    return dict(failure_row(fid, "error", "x", 1, CONFIGS[h], runtime_s=runtime, frame_hash=rows), status=status)


def _input(ids: list[str]):
    """The frame-id index and the content index of an input whose frames all have the rows hashed as SAME."""
    import pyarrow as pa

    from frames.frame_hash import frame_keys, from_hex
    from storage.frame_index import FrameIndex, frame_hashes

    lane0, lane1, _ = from_hex(pa.array([SAME] * len(ids)))
    return FrameIndex(*frame_hashes(ids)), FrameIndex(*frame_keys(*frame_hashes(ids), lane0, lane1))


def test_resume_plan_keeps_same_rows_and_hash_recomputes_the_others_and_drops_foreign_frames(tmp_path):
    from pipeline.batch.store import RunStore
    from storage.frame_index import frame_hashes

    store = RunStore(tmp_path / "programs")
    store.write_part(programs_table([_row("a"), _row("b", "h0"), _row("z"), _row("c", "h0"), _row("e", rows=OTHER),
                                     _row("f", rows=None), _row("g", "h0", rows=OTHER)]))
    store.write_part(programs_table([_row("c", "h1", runtime=2.0)]))
    ids = ["a", "b", "c", "d", "e", "f", "g"]
    plan = RunStore(tmp_path / "programs").plan(*_input(ids), CONFIGS["h1"].hash, ROWS_VERSION)
    done = plan.done.contains(*frame_hashes(ids + ["z"]))
    assert list(done) == [True, False, True, False, False, False, False, False]
    assert (plan.stale, plan.stale_example, plan.foreign, plan.superseded) == (1, "b", 1, 1)
    assert (plan.changed, plan.unhashed) == (2, 1) and plan.changed_example in ("e", "g")  # g: config changed too
    fresh = RunStore(tmp_path / "programs")
    fresh.plan(*_input(ids), CONFIGS["h1"].hash, ROWS_VERSION)
    fresh.apply(plan)
    left = read_programs(tmp_path / "programs").set_index("frame_id")
    assert sorted(left.index) == ["a", "c"]
    assert left.loc["c", "runtime_s"] == 2.0  # the later row of c (a later part) wins
    assert fresh.write_part(programs_table([_row("d")])).name == "part-000002.parquet"  # numbering goes on


def test_part_buffer_flushes_by_size_and_by_age():
    buf = PartBuffer(rows=2, max_age_s=10.0)
    buf.add(programs_table([_row("a")]), now=0.0)
    assert not buf.due(now=5.0)
    assert buf.due(now=10.0)
    buf.add(programs_table([_row("b")]), now=1.0)
    assert buf.due(now=1.0)
    assert buf.take().column("frame_id").to_pylist() == ["a", "b"]
    assert not buf.due(now=100.0) and buf.count == 0


def test_summary_line():
    line = summarize({"optimal": 2, "memout": 1, "error": 1}, computed=3, seconds=2.04).line()
    assert line == "4 frames (3 computed, 1 kept), 50.0% optimal, 0 feasible, 0 timeout, 1 memout, 1 errors, 2.0 s"
    line = summarize({"optimal": 4}, computed=3, seconds=1.0, changed=2).line()
    assert line.endswith("1.0 s; 2 recomputed because their rows changed")


def test_uncertainty_reaches_every_frame_and_its_config_hash(tmp_path):
    """`r2s run --uncertainty` gives each frame the robust program `r2s synth --uncertainty` gives it."""
    import pandas as pd

    from frames.rows import iter_scenes, read_frames
    from synth.config import SynthConfig
    from synth.synthesize import synthesize

    frames = tmp_path / "frames.parquet"
    proc = run_r2s("extract", "scenarionet", str(ROOT / "data/nuscenes-mini-excerpt/scenarionet"), "--out", str(frames),
                   "--categories", "vehicles")  # few entities a frame: the frames are synthesized twice more here
    assert proc.returncode == 0, proc.stderr
    plain, robust = tmp_path / "plain.parquet", tmp_path / "robust.parquet"
    assert run_r2s("run", str(frames), "--out", str(plain), "--jobs", "1").returncode == 0
    proc = run_r2s("run", str(frames), "--out", str(robust), "--jobs", "1", "--uncertainty", "0.3,2")
    assert proc.returncode == 0, proc.stderr
    a, b = (pd.read_parquet(p).sort_values("frame_id", ignore_index=True) for p in (plain, robust))
    assert list(a["frame_id"]) == list(b["frame_id"])
    assert (a["config_hash"] != b["config_hash"]).all()
    config = SynthConfig(pos_uncertainty=0.3, heading_uncertainty=2.0)
    scenes = {s.frame_id: s for s in iter_scenes(read_frames(frames))}
    for row in b.itertuples():
        assert row.program == str(synthesize(scenes[row.frame_id], config).program)
    assert (b["cost"].to_numpy() >= a["cost"].to_numpy()).all()
    bad = run_r2s("run", str(frames), "--out", str(tmp_path / "x.parquet"), "--uncertainty", "-1,2")
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1


# ---------------------------------------------------------------------------------------- datasets in and out

def _split_into_files(frames: Path, directory: Path, cuts: int) -> list[str]:
    """The frames file as `cuts` part files of whole frames (as `r2s extract --jobs` writes them)."""
    table = pq.read_table(frames)
    ids = table.column("frame_id").to_pylist()
    starts = [i for i in range(len(ids)) if i == 0 or ids[i] != ids[i - 1]]
    bounds = [starts[round(k * len(starts) / cuts)] for k in range(cuts)] + [len(ids)]
    directory.mkdir()
    for k, (lo, hi) in enumerate(zip(bounds, bounds[1:])):
        pq.write_table(table.slice(lo, hi - lo), directory / f"part-{k:05d}.parquet")
    return list(dict.fromkeys(ids))


def test_a_dataset_directory_in_and_out_reads_as_one_table_everywhere(small_frames, tmp_path):
    """Frames split over files in, a programs directory out: pandas, pyarrow.dataset, DuckDB and polars read the
    output as one table with every frame exactly once."""
    import duckdb
    import pandas as pd
    import polars as pl
    import pyarrow.dataset as ds

    order = _split_into_files(small_frames, tmp_path / "frames", 3)
    out = tmp_path / "programs"
    # One frame a chunk: with larger chunks two tables of three rows would make two parts, not three.
    proc = run_r2s("run", str(tmp_path / "frames"), "--out", str(out), "--jobs", "2", "--part-rows", "2",
                   "--chunk-size", "1")
    assert proc.returncode == 0, proc.stderr
    assert "6 frames in 3 files checked" in proc.stderr
    parts = sorted(p.name for p in out.iterdir())
    assert len(parts) >= 3 and all(p.startswith("part-") and p.endswith(".parquet") for p in parts)
    readers = {
        "pandas": lambda: pd.read_parquet(out)["frame_id"].tolist(),
        "pyarrow.dataset": lambda: ds.dataset(out, format="parquet").to_table(columns=["frame_id"])
        .column("frame_id").to_pylist(),
        "duckdb": lambda: [r[0] for r in duckdb.sql(f"SELECT frame_id FROM read_parquet('{out}/*.parquet')").fetchall()],
        "polars": lambda: pl.read_parquet(out / "*.parquet")["frame_id"].to_list(),
    }
    for name, read in readers.items():
        assert sorted(read()) == sorted(order), name
    _assert_programs_contain_scenes(small_frames, out, SynthConfig())
    again = run_r2s("run", str(tmp_path / "frames"), "--out", str(out), "--jobs", "2")
    assert again.returncode == 0 and "(0 computed, 6 kept)" in _summary(again.stderr)
    assert sorted(p.name for p in out.iterdir()) == parts  # nothing rewritten, nothing added


def test_a_frame_split_over_two_places_is_refused(small_frames, tmp_path):
    table = pq.read_table(small_frames)
    ids = table.column("frame_id").to_pylist()
    first = ids[0]
    n = ids.count(first)
    # The first frame's last row moved to the end of the file: a foreign writer that interleaves frames.
    rows = list(range(n - 1)) + list(range(n, len(ids))) + [n - 1]
    interleaved = tmp_path / "interleaved.parquet"
    pq.write_table(table.take(rows), interleaved)
    out = tmp_path / "programs"
    proc = run_r2s("run", str(interleaved), "--out", str(out))
    assert_one_line_error(proc, 2, "two places")
    assert first in proc.stderr
    _assert_nothing_written(out)


def test_a_dataset_output_drops_rows_of_another_config_and_of_frames_not_in_the_input(small_frames, tmp_path):
    out = tmp_path / "programs"
    assert run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2", "--part-rows", "2").returncode == 0
    fewer = tmp_path / "fewer.parquet"
    df = read_frames(small_frames)
    keep = _frame_ids(small_frames)[:4]
    write_frames(df[df["frame_id"].isin(keep)], fewer)
    proc = run_r2s("run", str(fewer), "--out", str(out), "--jobs", "2", "--strategy", "astar-cpa")
    assert proc.returncode == 0, proc.stderr
    assert "recomputing 4 frame(s) whose rows have another config hash" in proc.stderr
    assert "dropping 2 row(s) of frames that are not in" in proc.stderr
    df = _programs(out)
    assert sorted(df["frame_id"]) == sorted(keep)
    assert set(df["strategy"]) == {"astar-cpa"}


def test_an_old_single_file_output_resumes_and_stays_one_file(small_frames, tmp_path):
    """A programs.parquet written by an earlier version (one file, rows in input order) is resumed into."""
    out = tmp_path / "programs.parquet"
    assert run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2").returncode == 0
    first = _programs(out)
    rows = read_programs(out)
    pq.write_table(programs_table(rows.iloc[:3].to_dict("records")), out)  # as if only 3 frames were done
    proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0, proc.stderr
    assert "(3 computed, 3 kept)" in _summary(proc.stderr)
    again = _programs(out)
    assert list(again.index) == list(first.index)
    kept = list(rows["frame_id"][:3])
    assert list(again.loc[kept, "runtime_s"]) == list(first.loc[kept, "runtime_s"])
    assert pq.ParquetFile(out).metadata.num_rows == 6 and not Path(f"{out}.parts").exists()


def test_progress_lines_without_a_terminal_and_a_stop_says_how_to_resume(small_frames, tmp_path):
    out = tmp_path / "programs"
    proc = subprocess.Popen(  # a second a frame: four frames (4 s) are left when it is stopped
        r2s_with_fault("sleep=1@*", "run", str(small_frames), "--out", str(out), "--jobs", "1", "--chunk-size", "1",
                       "--part-rows", "1", "--log-every", "0.5"),
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while len(list(out.glob("part-*.parquet"))) < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be stopped"
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 128 + signal.SIGTERM
    lines = stderr.splitlines()
    progress = [ln for ln in lines if " of 6 frames (" in ln]
    assert progress and all("frames/s, ETA" in ln for ln in progress)
    assert any("optimal" in ln for ln in progress)  # counts by status once frames are done
    saved = len(read_programs(out))
    assert 2 <= saved < 6
    assert f"r2s run: stopped: {saved} of 6 frames are saved in {out}; run the same command again to resume" in lines
    proc = run_r2s("run", str(small_frames), "--out", str(out), "--jobs", "2")
    assert proc.returncode == 0 and f"({6 - saved} computed, {saved} kept)" in _summary(proc.stderr)
    assert sorted(_programs(out)["frame_id"]) == sorted(_frame_ids(small_frames))


def test_the_python_api_is_what_the_cli_runs(small_frames, tmp_path):
    from pipeline import run_frames

    lines: list[str] = []
    summary = run_frames(small_frames, tmp_path / "programs", SynthConfig(strategy="astar-cpa"), jobs=2,
                         log=lines.append, terminal=False)
    assert (summary.frames, summary.computed, summary.kept) == (6, 6, 0)
    assert dict(summary.statuses) == {"optimal": 6}
    assert summary.first_result_s is not None and summary.first_result_s <= summary.seconds
    assert lines[-1].startswith(summary.line())
    assert set(_programs(tmp_path / "programs")["strategy"]) == {"astar-cpa"}


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_a_dask_cluster_of_real_processes_loses_a_worker_mid_run(small_frames, tmp_path):
    """`dask scheduler` and two `dask worker` processes on localhost; the workers read their chunks from the
    frames file themselves. One worker is killed while it runs a chunk: every frame still ends up once."""
    pytest.importorskip("distributed", reason="dask.distributed is not installed (pip install '.[dask]')")
    dask = Path(sys.executable).with_name("dask")
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    # The tasks name the fault by its module (tests/faults.py): the scheduler (which unpickles the graph) and the
    # workers find it as a cluster finds any code a task names, on their path.
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    quiet = dict(stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT, start_new_session=True,
                 env=dict(os.environ, PYTHONPATH=path))
    procs = [subprocess.Popen([str(dask), "scheduler", "--host", "127.0.0.1", "--port", str(port),
                               "--no-dashboard"], **quiet)]
    try:
        for _ in range(2):
            procs.append(subprocess.Popen([str(dask), "worker", address, "--nthreads", "1", "--no-nanny",
                                           "--no-dashboard", "--host", "127.0.0.1"], **quiet))
        out = tmp_path / "programs"
        run = subprocess.Popen(r2s_with_fault("sleep=1@*", "run", str(small_frames), "--out", str(out), "--backend",
                                              "dask", "--scheduler", address, "--part-rows", "1"),
                               cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        deadline = time.monotonic() + 120
        while not list(out.glob("part-*.parquet")) and run.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert run.poll() is None, "the run ended before a worker could be killed"
        os.killpg(procs[1].pid, signal.SIGKILL)  # mid-run: the other chunks of its worker are in flight
        _, stderr = run.communicate(timeout=180)
        assert run.returncode == 0, stderr
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            p.wait()
    df = _programs(out)  # asserts every frame once
    assert sorted(df["frame_id"]) == sorted(_frame_ids(small_frames))
    assert set(df["status"]) == {"optimal"}
    _assert_programs_contain_scenes(small_frames, out, SynthConfig())


def test_dask_workers_that_cannot_see_the_frames_are_refused_before_anything_is_written(small_frames, tmp_path):
    distributed = pytest.importorskip("distributed", reason="dask.distributed is not installed")
    import logging

    frames = tmp_path / "frames.parquet"
    shutil.copy(small_frames, frames)
    out = tmp_path / "programs"
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp",
                                  dashboard_address=None, silence_logs=logging.ERROR) as cluster:
        from pipeline.batch.pool import DaskPool
        from pipeline.batch.stage import run_frames
        from pipeline.errors import UserError

        original = DaskPool.check_readable

        def blind(self, url, path):  # as a worker on another machine would see it: no such file
            return original(self, url, str(tmp_path / "elsewhere" / "frames.parquet"))

        DaskPool.check_readable = blind
        try:
            with pytest.raises(UserError, match="cannot read the frames"):
                run_frames(frames, out, backend="dask", scheduler=cluster.scheduler_address, terminal=False,
                           log=lambda line: None)
        finally:
            DaskPool.check_readable = original
    _assert_nothing_written(out)


def test_a_stop_held_back_during_a_part_write_still_counts_that_part(tmp_path):
    """SIGTERM during a write is delivered as the write returns; the rows it saved are counted all the same, so the
    stop line's "N of M saved" is what a resume keeps (it once said one part less)."""
    from pipeline.batch.stage import _write_part
    from pipeline.batch.store import RunStore

    class Stop(Exception):
        pass

    class Stopping(RunStore):
        def write_part(self, table):
            os.kill(os.getpid(), signal.SIGTERM)  # arrives while the stage holds SIGTERM back
            return super().write_part(table)

    def handler(signum, frame):
        raise Stop

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        store = Stopping(tmp_path / "programs")
        with pytest.raises(Stop):
            _write_part(store, programs_table([_row("a"), _row("b")]))
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert store.rows_written == 2 == len(read_programs(tmp_path / "programs"))
