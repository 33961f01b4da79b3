"""Shared fixtures: real frames shipped with the tests, the optional ../shared data, hypothesis profiles."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from synth.scene import Scene, scene_from_dict

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(__file__).resolve().parent / "data"
SHARED = Path(os.environ.get("R2S_SHARED", ROOT.parent / "shared"))

# CI runs derandomized (fixed seed) with bounded examples; R2S_HYPOTHESIS=dev explores more.
settings.register_profile("ci", derandomize=True, max_examples=60, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("R2S_HYPOTHESIS", "ci"))


def shipped_frames() -> list[Scene]:
    """Real nuScenes-mini keyframes shipped in tests/data (see its NOTICE)."""
    return [scene_from_dict(d) for d in json.loads((DATA / "nuscenes_mini_frames.json").read_text())]


@pytest.fixture(scope="session")
def real_frames() -> list[Scene]:
    return shipped_frames()


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not (SHARED / "data").is_dir():
        pytest.skip(f"shared data not found at {SHARED} (set R2S_SHARED); shipped excerpts cover the rest")
    return SHARED


def run_r2s(*args: str, input: str | None = None, cwd: Path | None = None, timeout: float = 300):
    """Run the `r2s` command as a user would; returns CompletedProcess (text)."""
    return subprocess.run(
        [sys.executable, "-m", "pipeline.cli", *args], input=input, capture_output=True, text=True,
        cwd=cwd or ROOT, timeout=timeout,
    )


def assert_one_line_error(proc, code: int = 2, contains: str | None = None) -> None:
    """Bad input: the given exit code, exactly one line on stderr, no traceback, nothing on stdout."""
    assert proc.returncode == code, (proc.returncode, proc.stderr)
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    assert proc.stdout == ""
    if contains:
        assert contains.lower() in lines[0].lower(), lines[0]
