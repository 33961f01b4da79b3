"""Argoverse 2 extractor: boxes already in the ego frame (x forward, y left) come out as ours (x right,
y forward, heading CCW from +y), one frame per timestamp, on the shipped excerpt and the shared logs."""

from __future__ import annotations

import math
from pathlib import Path
from unittest.mock import patch

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.ipc as ipc
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from extractors import argoverse2
from extractors.argoverse2 import extract
from extractors.categories import ALL, CategorySelection
from tests.support.extract import assert_refused, frames_of, r2s

EXCERPT = Path(__file__).resolve().parents[1] / "data" / "argoverse2"


def _expected(path: Path) -> pd.DataFrame:
    """Each annotation row by the textbook formulas (rotation matrix of the quaternion)."""
    t = ipc.open_file(pa.memory_map(str(path))).read_all().to_pandas()
    yaw = [math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)) for w, x, y, z in zip(t.qw, t.qx, t.qy, t.qz)]
    t["ex"], t["ey"] = -t.ty_m, t.tx_m
    t["eh"] = np.degrees(yaw) % 360.0
    t["index"] = t.timestamp_ns.rank(method="dense").astype(int) - 1
    return t


def _check_log(path: Path, radius: float = 1e9) -> None:
    exp = _expected(path)
    got = frames_of(extract, path, categories=ALL, radius=radius)
    log = path.parent.name
    exp = exp[(exp.category != "EGO_VEHICLE") & (np.hypot(exp.ex, exp.ey) <= radius)]
    others = got[~got.is_ego]
    m = exp.assign(frame_id=log + "/" + exp["index"].astype(str)).merge(
        others, left_on=["frame_id", "track_uuid"], right_on=["frame_id", "track_id"], how="outer", indicator=True)
    assert (m["_merge"] == "both").all() and len(m) == len(exp)
    assert np.allclose(m.ex, m.x, atol=1e-9) and np.allclose(m.ey, m.y, atol=1e-9)
    gap = (m.eh - m.heading) % 360.0
    assert np.minimum(gap, 360.0 - gap).max() < 1e-9
    assert np.allclose(m.length_m, m.length, atol=1e-5) and np.allclose(m.width_m, m.width, atol=1e-5)
    assert (m.category_x == m.category_y).all()
    assert (got.groupby("frame_id").is_ego.sum() == 1).all()
    assert set(got.timestamp_us) == set(exp.timestamp_ns // 1000)


@pytest.mark.parametrize("path", sorted(p for p in EXCERPT.rglob("*.feather") if p.name.startswith("annotations")),
                         ids=lambda p: p.parent.name[:8])
def test_excerpt_logs(path):
    _check_log(path)
    _check_log(path, radius=30.0)


def test_ego_row_gives_the_ego_box():
    got = frames_of(extract, EXCERPT / "3b3570b4-7b0b-3268-a571-b0889dbf40b6", categories=ALL)
    ego = got[got.is_ego]
    assert len(ego) == 2 and (ego.category == "EGO_VEHICLE").all()
    assert np.allclose(ego.length, 4.877, atol=1e-5) and np.allclose(ego.width, 2.0)
    assert "EGO_VEHICLE" not in set(got[~got.is_ego].category)


def test_a_directory_of_logs_and_vehicle_selection():
    got = frames_of(extract, EXCERPT, categories=CategorySelection.parse("vehicles"))
    assert got.scene.nunique() == 2 and got.frame_id.nunique() == 5
    assert set(got[~got.is_ego].type) <= {"Car", "Truck", "Bus", "Trailer", "Motorcycle", "Bicycle"}


def test_shared_logs(shared_dir):
    logs = sorted((shared_dir / "data" / "argoverse2").rglob("annotations*.feather"))
    assert len(logs) >= 4
    for path in logs:
        _check_log(path, radius=50.0)


def test_unknown_category_is_typed_object_and_counted_and_foreign_files_exit_2(tmp_path, capsys):
    src = EXCERPT / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede" / "annotations.feather"
    t = ipc.open_file(pa.memory_map(str(src))).read_all()
    cats = t.column("category").to_pylist()
    cats[5] = "HOVERCRAFT"
    bad = tmp_path / "log1" / "annotations.feather"
    bad.parent.mkdir()
    with ipc.new_file(str(bad), t.schema) as w:
        w.write_table(t.set_column(t.column_names.index("category"), "category", pa.array(cats)))
    out = tmp_path / "out" / "frames.parquet"
    # a category no map knows is the generic Object under "all", left out under "vehicles", and counted by name
    for categories, typed, note in [("all", "Object", "1 typed Object (HOVERCRAFT x1)"),
                                    ("Car,Object", "Object", "1 typed Object (HOVERCRAFT x1)"),
                                    ("vehicles", None, "1 left out (HOVERCRAFT x1)")]:
        res = r2s(capsys, "extract", "argoverse2", str(bad.parent), "--out", str(out), "--radius", "1000",
                  "--categories", categories)
        assert res.returncode == 0, res.stderr
        assert res.stderr.strip().endswith(f"objects of unknown type: {note}"), res.stderr
        got = pd.read_parquet(out)
        assert list(got[got.category == "HOVERCRAFT"].type) == ([typed] if typed else [])
        out.unlink()
    # naming it in --categories is a typo as far as anyone can tell
    res = r2s(capsys, "extract", "argoverse2", str(bad.parent), "--out", str(out), "--categories", "Car,HOVERCRAFT")
    assert_refused(res, out, "unknown category 'HOVERCRAFT' in --categories")

    bad.write_bytes(b"ARROW1 but not really")
    assert_refused(r2s(capsys, "extract", "argoverse2", str(bad.parent), "--out", str(out)), out, "not a readable")
    foreign = pa.table({"a": [1]})
    with ipc.new_file(str(bad), foreign.schema) as w:
        w.write_table(foreign)
    assert_refused(r2s(capsys, "extract", "argoverse2", str(bad.parent), "--out", str(out)), out, "lacks")


def _boundary(values):
    return [(float(x), float(y)) for x, y in values]


_coord = st.one_of(st.floats(-1e4, 1e4, allow_nan=False, allow_infinity=False), st.sampled_from([0.0, 1.0, 5e-324]))


@given(st.lists(st.tuples(st.lists(st.tuples(_coord, _coord), min_size=2, max_size=9),
                          st.lists(st.tuples(_coord, _coord), min_size=2, max_size=40)), min_size=1, max_size=6),
       st.booleans())
@settings(max_examples=300, deadline=None)
def test_centres_of_many_lanes_are_each_lane_s_resampled_midpoints_bit_for_bit(lanes, one_matrix):
    # repeated points (zero-length segments), lines of no length and subnormal steps take np.interp's and
    # np.linspace's rarer paths: the batched centres must equal the one-lane-at-a-time definition exactly, whether
    # the running lengths are summed in one padded matrix or in one per power of two of the lines' point counts
    # (what a map with one very long boundary takes: a slack below 0 forces it here)
    lanes = [(left + left[-1:], right) if i % 2 else (left, right) for i, (left, right) in enumerate(lanes)]
    with patch.object(argoverse2, "ROW_SLACK", argoverse2.ROW_SLACK if one_matrix else -1 << 40):
        got = argoverse2._centres([_boundary(left) for left, _ in lanes], [_boundary(right) for _, right in lanes])
    for (left, right), centre in zip(lanes, got):
        a, b = np.array(_boundary(left)), np.array(_boundary(right))
        n = max(len(a), len(b))
        want = (argoverse2._resample(a, n) + argoverse2._resample(b, n)) / 2
        assert np.array_equal(np.array(centre), want) or (np.isnan(want).any() and np.array_equal(
            np.array(centre), want, equal_nan=True))
