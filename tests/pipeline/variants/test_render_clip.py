"""`r2s render A.json B.json ... [--simulated DIR]`: a clip's recorded trajectories over its road, and the simulated
variants of r2s simulate overlaid, run as a user runs them on the shipped Argoverse 2 log (frames 100..105). The
SVG holds one recorded path per entity that is in two or more frames and one dashed path per simulated entity per
variant, counted here from the scene files and the simulated frames themselves; bad input is one line, exit 2."""

from __future__ import annotations

import json
import re
import shutil
from collections import Counter
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from pipeline.cli import main as cli_main
from pipeline.variants.clip_picture import RECORDED_GID, SIMULATED_GID
from tests.support import ROOT, assert_one_line_error, run_r2s

LOG = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"
LOG_ID = "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"


def _ok(res):
    assert res.returncode == 0, res.stderr
    return res


@pytest.fixture(scope="module")
def clip(tmp_path_factory) -> tuple[list[Path], Path]:
    """Frames 100..105 of the log (r2s scene) and one simulated variant of their clip program (r2s simulate)."""
    root = tmp_path_factory.mktemp("clip")
    files = []
    for k in range(100, 106):
        files.append(root / f"f{k}.json")
        args = ("scene", str(LOG), f"{LOG_ID}/{k}", "--out", str(files[-1]))
        # The first a real r2s scene process, the rest in process: 5 interpreter start-ups fewer.
        if k == 100:
            _ok(run_r2s(*args))
        else:
            assert cli_main(list(args)) == 0, args
    program = root / "clip.json"
    _ok(run_r2s("synth", *map(str, files), "--behaviours", "--motion", "--lanes", "--format", "json", "--out",
                str(program)))
    _ok(run_r2s("simulate", str(program), *map(str, files), "--motion", "--lanes", "--n", "1", "--seed", "0",
                "--time-limit", "60", "--out", str(root / "sim")))
    return files, root / "sim"


def _drawn(svg: Path, kind: str) -> Counter:
    """Paths of the kind drawn in the SVG (matplotlib writes an artist's gid as its group's id), by clip."""
    ids = re.findall(rf'<g id="{kind}-(.+?)-([A-Za-z_][A-Za-z0-9_]*)"', svg.read_text())
    return Counter(scene for scene, _ in ids)


def test_a_clip_and_its_simulated_variant_are_drawn_path_by_path(clip, tmp_path):
    files, sim = clip
    out = tmp_path / "clip.svg"
    _ok(run_r2s("render", *map(str, files), "--simulated", str(sim), "--out", str(out)))
    frames = Counter(e["id"] for f in files for e in json.loads(f.read_text())["entities"])
    rows = pq.read_table(sim / "part-000000.parquet", columns=["scene", "entity_id"]).to_pylist()
    per_variant = Counter((r["scene"], r["entity_id"]) for r in rows)
    simulated = Counter(scene for (scene, _), n in per_variant.items() if n >= 2)
    assert _drawn(out, RECORDED_GID) == {LOG_ID: sum(n >= 2 for n in frames.values())}
    assert _drawn(out, SIMULATED_GID) == simulated and sum(simulated.values()) > 10
    png = tmp_path / "clip.png"
    _ok(run_r2s("render", *map(str, files), "--out", str(png)))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("case", ["simulated alone", "program", "another clip", "unordered"])
def test_bad_clip_pictures_are_one_line_exit_2_and_nothing_written(case, clip, tmp_path):
    files, sim = clip
    other = tmp_path / "other.parquet"
    args = {
        "simulated alone": lambda: [str(files[0]), "--simulated", str(sim)],
        "program": lambda: [*map(str, files), "--program", str(files[0])],
        "another clip": lambda: [*map(str, files[:3]), "--simulated", str(_other(other))],
        "unordered": lambda: [str(files[1]), str(files[0])],
    }[case]()
    out = tmp_path / "out.png"
    assert_one_line_error(run_r2s("render", *args, "--out", str(out)), 2)
    assert not out.exists()


def _other(path: Path) -> Path:
    """The log's frames 0..3 as a frames file of one scene (its maps beside it): entities the clip at 100.. never
    had."""
    t = pq.read_table(LOG)
    keep = pa.array([f"{LOG_ID}/{k}" for k in range(4)])
    pq.write_table(t.filter(pc.is_in(t.column("frame_id"), value_set=keep)), path)
    shutil.copytree(LOG.with_suffix(".maps"), path.with_suffix(".maps"))
    return path
