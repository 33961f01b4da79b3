"""Only regular files are read (storage.regular_files): a path that is a FIFO or a symbolic link to /dev/zero,
given to any verb in any of its places, is refused with one line and exit 2, promptly and in little memory. On
real processes under a watchdog (tests.support.bounded): before, a FIFO hung the verb and /dev/zero was read until
memory ran out."""

from __future__ import annotations

import os
import shutil
import threading
from pathlib import Path

import pytest

from storage.regular_files import FileTooLarge, NotRegularFile, check_regular, open_regular, read_regular
from tests.support import DATA, ROOT
from tests.support.bounded import assert_refused, run_bounded

FRAMES = "data/nuscenes-mini-keyframes/frames.parquet"
PATTERN = "data/patterns/queue-of-three.dsl"
EXCERPT = ROOT / "data" / "nuscenes-mini-excerpt"
KINDS = ("fifo", "zero")
WORDS = {"fifo": "FIFO", "zero": "character device"}


def _special(where: Path, name: str, kind: str) -> Path:
    path = where / name
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
    else:
        path.symlink_to("/dev/zero")
    return path


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    """Valid inputs of every kind, so that each case has exactly one special path."""
    from tests.support import run_r2s

    d = tmp_path_factory.mktemp("valid")
    scene, program = d / "scene.json", d / "scene.dsl"
    assert run_r2s("scene", FRAMES, "scene-0103/0", "--out", str(scene)).returncode == 0
    assert run_r2s("synth", str(scene), "--out", str(program)).returncode == 0
    return {"scene": str(scene), "program": str(program)}


# verb arguments with {S} for the special path, {scene} / {program} for valid ones, {out} for a fresh output
VERB_CASES = {
    "synth scene": ("synth", "{S}"),
    "synth --config": ("synth", "{scene}", "--config", "{S}"),
    "check scene": ("check", "{S}", "{program}"),
    "check program": ("check", "{scene}", "{S}"),
    "scene frames": ("scene", "{S}", "scene-0103/0"),
    "run frames": ("run", "{S}", "--out", "{out}"),
    "query frames": ("query", "{S}", PATTERN, "--out", "{out}"),
    "query pattern": ("query", FRAMES, "{S}", "--out", "{out}"),
    "report programs": ("report", "{S}", "--out", "{out}"),
    "render scene": ("render", "{S}", "--out", "{out}.png"),
    "render --program": ("render", "{scene}", "--program", "{S}", "--out", "{out}.png"),
    "render --programs": ("render", "{scene}", "--programs", "{S}", "--out", "{out}.png"),
    "sample scenic": ("sample", "{S}", "--out", "{out}"),
    "sample --scene": ("sample", "--program", "{program}", "--scene", "{S}", "--out", "{out}"),
    "eval-frontend pred": ("eval-frontend", "{S}", FRAMES, "--out", "{out}"),
}


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("case", sorted(VERB_CASES))
def test_every_verb_refuses_a_special_file_in_every_place(case, kind, made, tmp_path):
    special = _special(tmp_path, "input", kind)
    args = [a.format(S=special, out=tmp_path / "out", **made) for a in VERB_CASES[case]]
    result = run_bounded(*args, timeout=30, max_rss_mb=1500)
    assert_refused(result, WORDS[kind])
    assert not (tmp_path / "out").exists() and not (tmp_path / "out.png").exists()


def test_report_refuses_special_frames_and_pattern(tmp_path):
    from tests.support import run_r2s

    programs = tmp_path / "programs"
    assert run_r2s("run", FRAMES, "--out", str(programs), "--time-limit", "30", "--jobs", "1").returncode == 0
    fifo = _special(tmp_path, "fifo", "fifo")
    for extra in (["--frames", str(fifo), "--query", PATTERN], ["--frames", FRAMES, "--query", str(fifo)]):
        result = run_bounded("report", str(programs), *extra, "--out", str(tmp_path / "report"), timeout=30)
        assert_refused(result, "FIFO")
        assert not (tmp_path / "report").exists()


def _scenarionet_dir(tmp_path: Path, kind: str) -> Path:
    d = tmp_path / "db"
    shutil.copytree(EXCERPT / "scenarionet", d)
    for f in ("dataset_summary.pkl", "dataset_mapping.pkl"):
        (d / f).unlink()  # a plain folder of scenario pickles, one of them special
    _special(d, "sd_special.pkl", kind)
    return d


def _nuscenes_root(tmp_path: Path, kind: str) -> Path:
    d = tmp_path / "nuscenes"
    shutil.copytree(EXCERPT / "v1.0-mini", d / "v1.0-mini")
    (d / "v1.0-mini" / "sample.json").unlink()
    _special(d / "v1.0-mini", "sample.json", kind)
    return d


def _av2_dir(tmp_path: Path, kind: str) -> Path:
    _special(tmp_path / "av2" / "log-1", "annotations.feather", kind)
    return tmp_path / "av2"


def _mcap_dir(tmp_path: Path, kind: str) -> Path:
    _special(tmp_path / "logs", "drive.mcap", kind)
    return tmp_path / "logs"


def _ros1_dir(tmp_path: Path, kind: str) -> Path:
    _special(tmp_path / "bags", "drive.bag", kind)
    return tmp_path / "bags"


def _ros2_dir(tmp_path: Path, kind: str) -> Path:
    _special(tmp_path / "bag2", "metadata.yaml", kind)
    return tmp_path / "bag2"


EXTRACT_CASES = {
    "scenarionet": _scenarionet_dir,
    "nuscenes": _nuscenes_root,
    "argoverse2": _av2_dir,
    "mcap": _mcap_dir,
    "rosbag": _ros1_dir,
    "rosbag2": _ros2_dir,
}


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("source", sorted(EXTRACT_CASES))
def test_extract_refuses_a_special_file_inside_its_input(source, kind, tmp_path):
    if source == "nuscenes":
        pytest.importorskip("nuscenes")
    where = EXTRACT_CASES[source](tmp_path, kind)
    result = run_bounded("extract", source.rstrip("2") if source == "rosbag2" else source, str(where),
                         "--out", str(tmp_path / "frames.parquet"), timeout=60, max_rss_mb=1500)
    assert_refused(result, WORDS[kind])
    assert not (tmp_path / "frames.parquet").exists()


def test_a_wrong_source_hint_does_not_open_a_fifo(tmp_path):
    """The hint for a wrong SOURCE reads the first bytes of files that look like logs: never a FIFO's."""
    d = _mcap_dir(tmp_path, "fifo")
    result = run_bounded("extract", "scenarionet", str(d), "--out", str(tmp_path / "f.parquet"), timeout=30)
    assert_refused(result)


# ------------------------------------------------------------------------------------------- the helper itself

def test_read_regular_reads_at_most_the_limit(tmp_path):
    f = tmp_path / "f"
    f.write_bytes(b"x" * 100)
    assert read_regular(f, 100) == b"x" * 100
    with pytest.raises(FileTooLarge):
        read_regular(f, 99)
    link = tmp_path / "link"
    link.symlink_to(f)
    assert read_regular(link, 100) == b"x" * 100  # a link to a regular file is that file


def test_a_file_that_grows_past_the_limit_while_read_is_refused(tmp_path, monkeypatch):
    """The size from fstat is checked first, but the read itself stops at limit + 1 bytes."""
    f = tmp_path / "f"
    f.write_bytes(b"x" * 10)
    real_fstat = os.fstat

    def small(fd):  # the file looked small when it was opened
        st = real_fstat(fd)
        return os.stat_result((st.st_mode, *st[1:6], 0, *st[7:]))

    monkeypatch.setattr(os, "fstat", small)
    with pytest.raises(FileTooLarge):
        read_regular(f, 5)


@pytest.mark.parametrize("kind", KINDS)
def test_open_regular_never_blocks_and_names_what_it_found(kind, tmp_path):
    special = _special(tmp_path, "s", kind)
    done = threading.Event()
    errors = []

    def attempt():
        try:
            open_regular(special)
        except NotRegularFile as exc:
            errors.append(exc)
        done.set()

    threading.Thread(target=attempt, daemon=True).start()
    assert done.wait(5), "open_regular blocked"
    assert WORDS[kind] in errors[0].strerror
    with pytest.raises(NotRegularFile):
        check_regular(special)
    with pytest.raises(NotRegularFile, match="directory"):
        read_regular(tmp_path, 10)


def test_shipped_inputs_are_regular():
    assert check_regular(DATA.parent.parent / FRAMES).st_size > 0


def test_a_small_file_under_a_large_limit_reserves_no_more_than_its_size(tmp_path):
    """read(n) allocates n bytes up front: under a 1 GiB address-space cap, reading 10 bytes with a limit of
    4 GiB must not ask for 4 GiB (a child process, so the cap is its own)."""
    import subprocess
    import sys

    f = tmp_path / "f"
    f.write_bytes(b"0123456789")
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (2**30, 2**30)); "
            "from storage.regular_files import read_regular; "
            f"print(read_regular({str(f)!r}, 4 * 2**30).decode())")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert proc.returncode == 0 and proc.stdout == "0123456789\n", proc.stderr[-300:]
