"""What the export tests share: the shipped ScenarioNet excerpt's frames, a recorded frame of each of its scenes
(r2s scene: world and road) with 5 variants (r2s sample), made once per session; and MetaDrive's own format check."""

from __future__ import annotations

import importlib.util
import sys
import types
from pathlib import Path

import pytest

from tests.support import run_r2s
from tests.support.extract import EXCERPT

FRAMES = ("scene-0061/0", "scene-0103/0", "scene-0796/1")


def _ok(res) -> None:
    assert res.returncode == 0, res.stderr


@pytest.fixture(scope="session")
def recorded(tmp_path_factory) -> dict[str, tuple[Path, Path]]:
    """frame id -> (scene JSON, directory of 5 variants), for one frame of each shipped scene with a map."""
    root = tmp_path_factory.mktemp("export-inputs")
    frames = root / "frames.parquet"
    _ok(run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--categories", "all", "--out", str(frames)))
    out = {}
    for fid in FRAMES:
        d = root / fid.replace("/", "_")
        d.mkdir()
        _ok(run_r2s("scene", str(frames), fid, "--out", str(d / "scene.json")))
        _ok(run_r2s("synth", str(d / "scene.json"), "--format", "scenic", "--out", str(d / "scene.scenic")))
        _ok(run_r2s("sample", str(d / "scene.scenic"), "--n", "5", "--seed", "0", "--out", str(d / "variants")))
        out[fid] = (d / "scene.json", d / "variants")
    return out


@pytest.fixture(scope="session")
def metadrive_format_check():
    """metadrive-simulator's ScenarioDescription.sanity_check, the format's own check. Importing `metadrive`
    starts its engine's imports (pygame, panda3d: not installed, and its assets download at start), so the
    package and its utils package are registered empty and only the modules the check needs run: the real code
    of scenario_description.py, type.py and utils/math.py."""
    spec = importlib.util.find_spec("metadrive")
    if spec is None or not spec.submodule_search_locations:
        pytest.skip("metadrive-simulator is not installed (pip install --no-deps metadrive-simulator==0.4.3)")
    root = spec.submodule_search_locations[0]
    saved = {n: sys.modules.get(n) for n in ("metadrive", "metadrive.utils")}
    for name, path in (("metadrive", root), ("metadrive.utils", str(Path(root) / "utils"))):
        if name not in sys.modules:
            module = types.ModuleType(name)
            module.__path__ = [path]
            sys.modules[name] = module
    from metadrive.scenario.scenario_description import ScenarioDescription

    yield ScenarioDescription.sanity_check
    for name, module in saved.items():
        if module is None:
            sys.modules.pop(name, None)
