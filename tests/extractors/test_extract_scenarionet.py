"""ScenarioNet extractor: real nuScenes-mini pickles against the flattened keyframes.csv of the same scenes.

The expected ego-frame values are computed here independently of extractors.base (complex rotation of the
global offset by -ego_yaw gives (forward, left); our frame is x = -left, y = forward).
"""

from __future__ import annotations

import cmath
import math

import pandas as pd

from extractors.base import ExtractOptions
from extractors.categories import ALL, CategorySelection
from extractors.scenarionet import extract
from frames.rows import read_frames
from tests.support import run_r2s
from tests.support.extract import EXCERPT, assert_refused, r2s


def _frames(path, **kw) -> pd.DataFrame:
    rows = [r for frame in extract(str(path), ExtractOptions(**kw)) for r in frame]
    return pd.DataFrame(rows)


def _expected(k: pd.DataFrame) -> pd.DataFrame:
    k = k[k.category_name != "vehicle.ego"].copy()
    local = [
        complex(x - ex, y - ey) * cmath.exp(-1j * eyaw)
        for x, y, ex, ey, eyaw in zip(k.x, k.y, k.ego_x, k.ego_y, k.ego_yaw)
    ]
    k["ex"] = [-z.imag for z in local]
    k["ey"] = [z.real for z in local]
    k["eh"] = [math.degrees(a - b) % 360.0 for a, b in zip(k.yaw, k.ego_yaw)]
    k["frame_id"] = k.scene_name + "/" + k.sample_index.astype(str)
    k = k.rename(columns={"length": "exp_length", "width": "exp_width"})
    return k[["frame_id", "instance_token", "category_name", "ex", "ey", "eh", "exp_length", "exp_width"]]


def _angle_gap(a, b):
    d = (pd.Series(a).to_numpy() - pd.Series(b).to_numpy()) % 360.0
    return pd.Series([min(v, 360.0 - v) for v in d])


def test_reproduces_every_keyframe_box_of_the_six_scenes(shared_dir):
    data = shared_dir / "data" / "nuscenes-mini"
    keyframes = pd.read_csv(data / "keyframes.csv")
    got = _frames(data / "scenarionet", radius=1e9, categories=ALL)
    exp = _expected(keyframes)

    # the same keyframes, each with the same set of boxes
    assert set(got.frame_id) == set(exp.frame_id)
    assert got.frame_id.nunique() == keyframes.groupby(["scene_name", "sample_index"]).ngroups
    others = got[~got.is_ego]
    m = exp.merge(others, left_on=["frame_id", "instance_token"], right_on=["frame_id", "track_id"], how="outer",
                  indicator=True)
    assert (m["_merge"] == "both").all(), m[m["_merge"] != "both"][["frame_id", "instance_token", "track_id"]].head()
    assert len(m) == len(exp)

    assert (m.ex - m.x).abs().max() < 0.01
    assert (m.ey - m.y).abs().max() < 0.01
    assert _angle_gap(m.eh, m.heading).max() < 0.01
    assert (m.exp_length - m.length).abs().max() < 1e-3 and (m.exp_width - m.width).abs().max() < 1e-3
    assert (m.category_name == m.category).all()

    # one ego per frame, at the origin facing +y
    egos = got[got.is_ego]
    assert len(egos) == got.frame_id.nunique()
    assert (egos[["x", "y", "heading"]] == 0).all().all()
    assert (egos.length > egos.width).all()


def test_radius_and_vehicle_selection_match_the_csv_counts(shared_dir):
    data = shared_dir / "data" / "nuscenes-mini"
    exp = _expected(pd.read_csv(data / "keyframes.csv"))
    exp["d"] = (exp.ex**2 + exp.ey**2) ** 0.5
    near = exp[exp.d <= 50.0]
    vehicles = near[near.category_name.str.startswith("vehicle.")]

    got = _frames(data / "scenarionet", categories=CategorySelection.parse("vehicles"))
    counts = got[~got.is_ego].groupby("frame_id").size()
    want = vehicles.groupby("frame_id").size()
    assert counts.reindex(want.index, fill_value=0).equals(want)
    assert set(got.type) <= {"Car", "Truck", "Bus", "Trailer", "ConstructionVehicle", "Motorcycle", "Bicycle"}


def test_frames_are_deterministic_with_rows_by_distance():
    a = _frames(EXCERPT / "scenarionet", categories=ALL)
    b = _frames(EXCERPT / "scenarionet", categories=ALL)
    assert a.equals(b)
    for _, f in a.groupby("frame_id"):
        f = f[~f.is_ego]
        dist = ((f.x**2 + f.y**2) ** 0.5).tolist()
        assert dist == sorted(dist)  # the ids themselves: tests/extractors/test_stable_ids.py
        assert all(e.startswith(t.lower()) for e, t in zip(f.entity_id, f.type))


def test_every_keeps_every_kth_keyframe():
    every1 = _frames(EXCERPT / "scenarionet", categories=ALL)
    every2 = _frames(EXCERPT / "scenarionet", categories=ALL, every=2)
    assert set(every2.frame_index) == {i for i in set(every1.frame_index) if i % 2 == 0}
    assert set(every2.frame_id) < set(every1.frame_id)


def test_cli_on_the_shipped_excerpt_yields_demo_frames(tmp_path):
    out = tmp_path / "frames.parquet"
    proc = run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(out), "--categories", "all")
    assert proc.returncode == 0, proc.stderr
    df = read_frames(out)
    sizes = df.groupby("frame_id").size()
    assert 4 <= len(sizes) <= 20
    assert ((sizes >= 20) & (sizes <= 60)).sum() >= 3  # what `make demo` synthesizes
    assert sizes.min() < 20

    proc = run_r2s("scene", str(out), sizes.index[0])
    assert proc.returncode == 0, proc.stderr
    assert '"id": "ego"' in proc.stdout


def test_cap_on_entities_refuses_the_frame(tmp_path, capsys):
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(out), "--categories",
              "all", "--max-entities", "10")
    assert_refused(res, out, "more than the cap of 10")
