"""Programs made on maps of the old lane polygons (GEOS's buffer for every lane, before the offset rings of
synth.road.lane_geometry) are recomputed once the maps hold the new ones, and only where a frame's map changed
(docs/cli.md, "When a stored program is reused": with --lanes the key covers the maps' content). Real Waymo
scenarios (../shared/data/waymo; skipped without it), `r2s run` as a real process."""

from __future__ import annotations

import pickle
import shutil
from unittest.mock import patch

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from extractors import scenarionet
from synth.road import lane_geometry
from synth.road.roadmap import MapRepairs
from tests.support import SHARED, run_r2s

WAYMO = SHARED / "data" / "waymo"
SCENARIOS = ["sd_waymo_v1.2_10810393add927f8.pkl", "sd_waymo_v1.2_259908d45db6249d.pkl"]
MEASURED = ["runtime_s", "search_s", "smt_s", "peak_rss_mb"]  # what a run measures, not computes


def _geos_polygons(path) -> dict[str, list]:
    """The lanes' polygons as the reader made them before the offset rings: every line widened by GEOS."""
    with open(path, "rb") as fh:
        sd = pickle.load(fh)
    none = (np.zeros(0, dtype=np.int64), np.empty((0, 2)), np.zeros(0, dtype=np.int64))
    with patch.object(lane_geometry, "offset_rings", lambda *a: none):
        road = scenarionet.scenario_map("m", sd["map_features"], "waymo", MapRepairs())
    return {f.feature_id: f.polygon for f in road.features if f.polygon_rule == "centre line"}


def _with_old_polygons(maps_part, old: dict[str, list]) -> None:
    """Rewrite a maps part with the old polygons of its centre-line lanes (what main's extract wrote)."""
    t = pq.read_table(maps_part)
    rows = t.to_pylist()
    changed = 0
    for r in rows:
        if r["feature_id"] in old and r["polygon_rule"] == "centre line":
            poly = old[r["feature_id"]]
            changed += [r["polygon_x"], r["polygon_y"]] != [[p[0] for p in poly], [p[1] for p in poly]]
            r["polygon_x"], r["polygon_y"] = [p[0] for p in poly], [p[1] for p in poly]
    assert changed  # the old polygons are not the new ones' floats
    pq.write_table(pa.Table.from_pylist(rows, schema=t.schema), maps_part)


def _programs(path) -> pd.DataFrame:
    p = pd.read_parquet(path)
    return p.drop(columns=[c for c in p.columns if c in MEASURED]).sort_values("frame_id").reset_index(drop=True)


@pytest.mark.skipif(not WAYMO.is_dir(), reason="needs ../shared/data/waymo (CI has it)")
def test_programs_made_on_the_old_polygons_are_recomputed_where_the_map_changed(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    for name in SCENARIOS:
        shutil.copy(WAYMO / name, src / name)
    new = tmp_path / "new"
    res = run_r2s("extract", "scenarionet", str(src), "--every", "45", "--out", str(new), "--strict-maps")
    assert res.returncode == 0, res.stderr
    frames = pd.read_parquet(new)
    ids = frames.drop_duplicates("frame_id").set_index("frame_id").map_id
    first = ids.iloc[0]  # the map made old below; the other map stays the new one
    assert ids.nunique() == 2
    old = tmp_path / "old"
    shutil.copytree(new, old)
    for part in sorted((old / "_maps").glob("part-*.parquet")):
        if first in set(pq.read_table(part, columns=["map_id"]).column(0).to_pylist()):
            _with_old_polygons(part, _geos_polygons(src / next(n for n in SCENARIOS if first in n)))

    out = tmp_path / "programs.parquet"
    run = ["run", str(old), "--lanes", "--jobs", "1", "--time-limit", "20", "--out", str(out)]
    assert run_r2s(*run).returncode == 0
    shutil.rmtree(old / "_maps")
    shutil.copytree(new / "_maps", old / "_maps")  # re-extracted: the new polygons
    res = run_r2s(*run)
    assert res.returncode == 0, res.stderr
    n_first = int((ids == first).sum())
    assert f"recomputing {n_first} frame(s) whose rows changed" in res.stderr, res.stderr
    assert f"resuming: {len(ids) - n_first} of {len(ids)} frames already done" in res.stderr, res.stderr

    fresh = tmp_path / "fresh.parquet"
    assert run_r2s("run", str(new), "--lanes", "--jobs", "1", "--time-limit", "20",
                   "--out", str(fresh)).returncode == 0
    assert _programs(out).equals(_programs(fresh))  # nothing stale survives: the rows a fresh run writes
