"""What the tests share: the repository's paths, the real frames shipped with the tests, scenes that use every
relation kind, and the `r2s` command run as a user runs it. The other modules of this package hold the larger
helpers (independent brute forces, golden pins, crowd scenes, log and database writers)."""

from __future__ import annotations

import fcntl
import json
import os
import pty
import select
import struct
import subprocess
import sys
import termios
import time
from pathlib import Path

from synth.scene import Scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"
SHARED = Path(os.environ.get("R2S_SHARED", ROOT.parent / "shared"))


def shipped_frames() -> list[Scene]:
    """Real nuScenes-mini keyframes shipped in tests/data (see its NOTICE)."""
    return [scene_from_dict(d) for d in json.loads((DATA / "nuscenes_mini_frames.json").read_text())]


def all_relation_kinds():
    """(scene, program, config): every position and heading form of the DSL (a real frame's optimum rarely needs
    the absolute and relative ones), under non-default tolerances, with a program that contains the scene."""
    from synth.config import SynthConfig
    from synth.dsl import parse_program

    scene = scene_from_dict({"frame_id": "kinds", "entities": [
        {"id": "ego", "type": "Car", "x": 3.5, "y": -2.0, "heading": 200.0},
        {"id": "car1", "type": "Car", "x": 0.0, "y": 12.0, "heading": 359.0},
        {"id": "ped1", "type": "Pedestrian", "x": -12.0, "y": 12.3, "heading": 90.0},
        {"id": "cone1", "type": "TrafficCone", "x": -7.0, "y": -20.0, "heading": 10.0},
        {"id": "bus1", "type": "Bus", "x": 20.0, "y": 30.0, "heading": 330.0, "length": 12.5, "width": 3.0},
        {"id": "bike1", "type": "Bicycle", "x": -4.54, "y": -19.57, "heading": 100.0},
    ]})
    program = parse_program(
        "car1 = new Car on Range(-4, 1) @ Range(-17, -12) relative to ego, facing Range(356.5, 361.5) deg\n"
        "ped1 = new Pedestrian left of car1 by Range(9.5, 14.5), facing Range(-271.5, -266.5) deg relative to car1\n"
        "cone1 = new TrafficCone on Range(-9, -4) @ Range(-22, -17), facing toward ped1\n"
        "bus1 = new Bus on Range(18, 23) @ Range(28, 33), facing away from cone1\n"
        "bike1 = new Bicycle right of cone1 by Range(0, 4), facing Range(87, 92) deg relative to cone1\n")
    return scene, program, SynthConfig(delta1=4.0, delta2=2.0, oracle="closed-form")


def every_motion_clause():
    """(scene, program) with clauses a synthesized program rarely needs: like a moving reference, a relative Range
    wholly below the reference (the reference must then be fast enough), an absolute Range, a Range reaching
    below 0. The program contains the scene under SynthConfig(motion=True)."""
    from synth.dsl import parse_program

    scene = scene_from_dict({"frame_id": "kinds", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 2.0},
        {"id": "car1", "type": "Car", "x": 0, "y": 15, "heading": 0, "speed": 9.0},
        {"id": "car2", "type": "Car", "x": 0, "y": 30, "heading": 0, "speed": 8.5},
        {"id": "car3", "type": "Car", "x": 4, "y": 30, "heading": 0, "speed": 1.0},
        {"id": "car4", "type": "Car", "x": 8, "y": 30, "heading": 0, "speed": 0.3},
        {"id": "car5", "type": "Car", "x": 12, "y": 30, "heading": 0, "speed": 4.0}]})
    program = parse_program(
        "car1 = new Car ahead of ego by Range(12.5, 17.5), facing Range(-5, 5) deg, moving Range(6, 12) m/s\n"
        "car2 = new Car ahead of car1 by Range(12.5, 17.5), facing Range(-5, 5) deg, moving like car1\n"
        "car3 = new Car on Range(2, 6) @ Range(28, 32), facing Range(-5, 5) deg, moving Range(-8.5, -7) m/s relative to car2\n"
        "car4 = new Car on Range(6, 10) @ Range(28, 32), facing Range(-5, 5) deg, stationary\n"
        "car5 = new Car on Range(10, 14) @ Range(28, 32), facing Range(-5, 5) deg, moving Range(-3, 5) m/s relative to car4\n")
    return scene, program


def run_r2s(*args: str, input: str | None = None, cwd: Path | None = None, timeout: float = 300):
    """Run the `r2s` command as a user would; returns CompletedProcess (text)."""
    return subprocess.run(
        [sys.executable, "-m", "pipeline.cli", *args], input=input, capture_output=True, text=True,
        cwd=cwd or ROOT, timeout=timeout,
    )


def run_r2s_on_terminal(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `r2s` with its stderr on a pseudo-terminal, as in a user's shell (a progress bar is drawn there, not log
    lines); returns CompletedProcess with what the terminal showed as `stderr` (carriage returns and all)."""
    leader, follower = pty.openpty()
    fcntl.ioctl(follower, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 120, 0, 0))  # a terminal has a width
    proc = subprocess.Popen([sys.executable, "-m", "pipeline.cli", *args], cwd=ROOT, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=follower)
    os.close(follower)
    shown, deadline = bytearray(), time.monotonic() + timeout
    try:
        while time.monotonic() < deadline:
            ready, _, _ = select.select([leader], [], [], 0.2)
            if ready:
                try:
                    chunk = os.read(leader, 65536)
                except OSError:  # EIO: the child closed its end
                    chunk = b""
                if not chunk:
                    break
                shown += chunk
            elif proc.poll() is not None:
                break
        stdout = proc.communicate(timeout=max(1.0, deadline - time.monotonic()))[0]
    finally:
        if proc.poll() is None:
            proc.kill()
        os.close(leader)
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout.decode(), shown.decode(errors="replace"))


def wait_for_file(path: Path, timeout: float = 60) -> bool:
    """Whether `path` exists within `timeout` seconds (a process started in the background made it)."""
    deadline = time.monotonic() + timeout
    while not path.exists() and time.monotonic() < deadline:
        time.sleep(0.2)
    return path.exists()


def assert_one_line_error(proc, code: int = 2, contains: str | None = None) -> None:
    """Bad input: the given exit code, exactly one line on stderr, no traceback, nothing on stdout."""
    assert proc.returncode == code, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""
    if contains:
        assert contains.lower() in lines[0].lower(), lines[0]


def overlapping(scene) -> set[frozenset[str]]:
    """Pairs of ids whose boxes meet, by shapely (what Scenic's `intersects` uses for planar boxes): the collision
    rule's independent check."""
    import itertools

    import shapely

    from pipeline.variants.render import ego_frame

    polys = {b.id: shapely.Polygon(b.corners()) for b in ego_frame(scene).values()}
    return {frozenset((a, b)) for a, b in itertools.combinations(polys, 2) if polys[a].intersects(polys[b])}
