"""The numpy widening on the real Waymo maps (../shared/data/waymo; skipped without it): every lane polygon the
reader makes from a centre line and widths is GEOS's buffer of that line (the rule of docs/formats.md) within
the merged bevels' bound, and most lanes take the offset ring (the point of it: bench/results/maps.md)."""

from __future__ import annotations

import pickle
from unittest.mock import patch

import numpy as np
import pytest
import shapely

from extractors import scenarionet
from synth.road.lane_geometry import DEFAULT_LANE_WIDTH, dedup_packed, offset_rings
from synth.road.roadmap import MapRepairs
from tests.support import SHARED
from tests.support.widening import bound, geos_ring

WAYMO = SHARED / "data" / "waymo"


@pytest.mark.skipif(not WAYMO.is_dir(), reason="needs ../shared/data/waymo (CI has it)")
@pytest.mark.parametrize("path", sorted(WAYMO.glob("*.pkl"))[:4], ids=lambda p: p.stem[-6:])
def test_every_widened_waymo_lane_is_geos_s_buffer_within_the_bound(path):
    with open(path, "rb") as fh:
        sd = pickle.load(fh)
    calls = []
    real = scenarionet.lane_polygons

    def spy(lines, lefts, rights):
        rings = real(lines, lefts, rights)
        calls.append((lines, lefts, rights, rings))
        return rings

    with patch.object(scenarionet, "lane_polygons", spy):
        scenarionet.scenario_map("m", sd["map_features"], "waymo", MapRepairs())
    ((lines, lefts, rights, rings),) = calls
    half = DEFAULT_LANE_WIDTH / 2
    lefts = [half if w is None else w for w in lefts]
    rights = [half if w is None else w for w in rights]
    for line, left, right, ring in zip(lines, lefts, rights, rings):
        got, want = shapely.Polygon(ring), geos_ring(line, left, right)
        assert got.is_valid
        assert shapely.hausdorff_distance(got, want, densify=0.1) <= bound(left, right)
    xy, kept = dedup_packed(lines)
    fast, _, _ = offset_rings(xy, kept, np.array(lefts), np.array(rights), kept >= 2)
    assert len(fast) >= 0.9 * len(lines)  # 96% over the 12 scenarios
