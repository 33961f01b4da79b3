"""Argoverse 2 maps that are large or hostile, as a user meets them: the av2-api test log (../shared/data) with its
map archive edited. A lane boundary of many points extracts in memory bounded by the map (r2s as a real process
under a memory watchdog) with the facts of the map it densifies; an id or number beyond a float, a fractional id
and JSON nested past the parser's stack are one line and exit 2, nothing written."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.ipc  # noqa: F401 (pa.ipc)
import pytest

from tests.support import SHARED
from tests.support.bounded import run_bounded
from tests.support.extract import assert_refused, r2s

AV2_LOG = SHARED / "data" / "argoverse2" / "test_data" / "sensor_dataset_logs" / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"

pytestmark = pytest.mark.skipif(not AV2_LOG.is_dir(), reason="needs ../shared/data/argoverse2 (the av2-api test log)")

# The lane of the test log that holds the most boxes (42809424, 172 rows): its boundary densified, every box in it
# meets its 50,000-point centre line in the tie rule and its 50,000-edge polygon in the containment test.
BUSY_LANE = "42809424"
POINTS = 50_000


def _log_with_map(tmp_path: Path, edit) -> Path:
    """A copy of the test log whose map archive's JSON text is edit(text)."""
    log = tmp_path / "logs" / AV2_LOG.name
    shutil.copytree(AV2_LOG, log)
    for p in log.rglob("*"):  # the shared copy is read-only
        p.chmod(0o755 if p.is_dir() else 0o644)
    archive = next((log / "map").glob("log_map_archive_*.json"))
    text = archive.read_text()
    edited = edit(text)
    assert edited != text
    archive.write_text(edited)
    return log


def _densified(text: str) -> str:
    """The busy lane's left boundary as POINTS points along the same polyline (np.interp between its vertices)."""
    data = json.loads(text)
    lane = data["lane_segments"][BUSY_LANE]
    b = lane["left_lane_boundary"]
    t, k = np.linspace(0, len(b) - 1, POINTS), np.arange(len(b))
    lane["left_lane_boundary"] = [{"x": float(x), "y": float(y), "z": float(z)} for x, y, z in zip(
        *(np.interp(t, k, [p[c] for p in b]) for c in "xyz"))]
    return json.dumps(data)


def test_a_lane_boundary_of_50000_points_extracts_in_memory_bounded_by_the_map(tmp_path):
    dense = _log_with_map(tmp_path / "dense", _densified)
    out, want = tmp_path / "dense.parquet", tmp_path / "plain.parquet"
    # 3.8 MB of map. Before, every boundary was padded to the longest (398 x 50,000 running lengths) and every
    # box in the lane took all 50,000 segments in one pass: 670 MB at peak. Now about 215 MB (190 MB without the
    # edit: the interpreter, pyarrow, pandas), so 400 MB is the old blow-up's ceiling with room for noise.
    res = run_bounded("extract", "argoverse2", str(dense.parent), "--categories", "all", "--out", str(out),
                      timeout=120, max_rss_mb=400)
    assert res.killed is None and res.returncode == 0, (res.killed, res.peak_rss_mb, res.stderr[-500:])
    plain = run_bounded("extract", "argoverse2", str(AV2_LOG), "--categories", "all", "--out", str(want),
                        timeout=120)
    assert plain.returncode == 0, plain.stderr
    got, ref = pd.read_parquet(out), pd.read_parquet(want)
    # the densified boundary lies on the original one, so every box has the facts it has on the shipped map
    facts = ["frame_id", "entity_id", "lanes", "lane", "in_intersection", "on_crosswalk", "off_road"]
    assert got[facts].astype(str).equals(ref[facts].astype(str))
    assert (got.lane == BUSY_LANE).sum() > 100
    lanes = pd.read_parquet(tmp_path / "dense.maps")
    assert lanes.set_index("feature_id").line_x[BUSY_LANE].size == POINTS


@pytest.mark.parametrize("edit, message, repair", [
    (lambda t: t.replace(f'"id": {BUSY_LANE},', '"id": 1e400,', 1), "id inf is not an integer", "features breaking"),
    (lambda t: t.replace(f'"id": {BUSY_LANE},', '"id": 4.5,', 1), "id 4.5 is not an integer", "features breaking"),
    (lambda t: t.replace('"x": ', '"x": 1' + "0" * 400 + ', "was_x": ', 1), "not two finite numbers",
     "features breaking"),
    (lambda t: t.replace('"x": ', '"x": 1' + "0" * 5000 + ', "was_x": ', 1), "not two finite numbers",
     "features breaking"),
    (lambda t: t[:-1] + ', "deep": ' + "[" * 100_000 + "]" * 100_000 + "}", "nested too deeply", "maps unusable"),
])
def test_a_hostile_map_archive_is_one_line_exit_2_with_strict_maps_and_else_costs_no_track(tmp_path, capsys, edit,
                                                                                          message, repair):
    log = _log_with_map(tmp_path, edit)
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "argoverse2", str(log.parent), "--out", str(out), "--strict-maps")
    assert_refused(res, out, message)
    assert "log_map_archive_" in res.stderr and res.stderr.count("log_map_archive_") == 1  # the archive, once
    # without --strict-maps: the feature dropped and counted, or the map unusable: every frame extracted
    res = r2s(capsys, "extract", "argoverse2", str(log.parent), "--out", str(out))
    assert res.returncode == 0 and repair in res.stderr.splitlines()[-1], res.stderr
    stamps = pa.ipc.open_file(str(log / "annotations.feather")).read_all().column("timestamp_ns").unique()
    assert pd.read_parquet(out).frame_id.nunique() == len(stamps)
