"""Shared fixtures: real frames shipped with the tests, the optional ../shared data, hypothesis profiles.
Helpers the tests import are in tests/support."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import HealthCheck, settings

from synth.scene import Scene
from tests.support import ROOT, SHARED, run_r2s, shipped_frames

# CI runs derandomized (fixed seed) with bounded examples; R2S_HYPOTHESIS=dev explores more.
settings.register_profile("ci", derandomize=True, max_examples=60, deadline=None,
                          suppress_health_check=[HealthCheck.too_slow])
settings.register_profile("dev", max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile(os.environ.get("R2S_HYPOTHESIS", "ci"))


@pytest.fixture(scope="session")
def real_frames() -> list[Scene]:
    return shipped_frames()


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not (SHARED / "data").is_dir():
        pytest.skip(f"shared data not found at {SHARED} (set R2S_SHARED); shipped excerpts cover the rest")
    return SHARED


@pytest.fixture(scope="session")
def excerpt_frames(tmp_path_factory) -> Path:
    """The shipped ScenarioNet excerpt (nuScenes, with its maps) extracted once, every category, as `r2s extract`
    writes it (a dataset directory with _maps/); tests only read it."""
    out = tmp_path_factory.mktemp("excerpt") / "frames"
    proc = run_r2s("extract", "scenarionet", str(ROOT / "data" / "nuscenes-mini-excerpt" / "scenarionet"),
                   "--categories", "all", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out
