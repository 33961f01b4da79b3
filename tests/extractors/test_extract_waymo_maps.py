"""Waymo maps as ScenarioNet's Waymo converter writes them (issue 34), and what else a ScenarioNet map may hold
(issue 35: 35.5, 35.12, 35.15), as a user runs `r2s extract` and the verbs after it.

On CI without the real files: a scenario made here the way the converter writes one (tests/support/waymo_maps.py)
and that scenario broken in each way a pickle can break it. With ../shared: the 12 real Waymo scenarios extract
with their maps, every box's lane facts agree with the lanes' own centre lines and widths (an independent
computation in plain numpy from the pickles, not our polygons), the lane graph is the file's, and the verbs run on
them. No Waymo data is in the repository (its licence): the tests read ../shared and skip without it.
"""

from __future__ import annotations

import json
import pickle
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import shapely

from extractors.scenarionet import scenario_map
from synth.road.lane_geometry import DEFAULT_LANE_WIDTH, MAX_HALF_WIDTH, MIN_HALF_WIDTH
from synth.road.roadmap import MapRepairs
from tests.support import SHARED, assert_one_line_error, run_r2s
from tests.support.bounded import run_bounded
from tests.support.waymo_maps import SCENE, waymo_scenario

WAYMO = SHARED / "data" / "waymo"
needs_waymo = pytest.mark.skipif(not WAYMO.is_dir(), reason="needs ../shared/data/waymo (CI has it)")


def _write(sd: dict, folder: Path, name: str = "sd_waymo_v1.2_synth.pkl") -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    with open(path, "wb") as fh:
        pickle.dump(sd, fh, protocol=4)
    return path


def _summary(res) -> str:
    return res.stderr.strip().splitlines()[-1]


# ------------------------------------------------------------------------------ the converter's layout, on CI


def test_a_map_as_the_waymo_converter_writes_it_extracts_with_every_repair_counted(tmp_path):
    path = _write(waymo_scenario(), tmp_path / "in")
    for strict in ((), ("--strict-maps",)):  # what the converter writes is no broken rule
        out = tmp_path / f"out{len(strict)}"
        res = run_r2s("extract", "scenarionet", str(path), "--out", str(out), *strict)
        assert res.returncode == 0, res.stderr
        # 103 has no boundary (0 throughout), 106 meets its boundary at one vertex; 105 and 303 are one point
        assert _summary(res).endswith("map repairs: 2 lane widths from the default, 2 one-point features dropped")
    maps = pd.read_parquet(out / "_maps").set_index("feature_id")
    assert sorted(maps.index) == ["101", "102", "103", "104", "106", "201", "202", "203", "301", "302", "401"]
    lanes = maps[maps.kind == "lane"]
    assert sorted(lanes.index) == ["101", "102", "103", "104", "106"]
    assert lanes.loc["104", "source_type"] == "UNKNOWN"  # Waymo's undefined lane type, a lane that 102 names
    assert lanes.loc["102", "left_neighbour"] == "104" and lanes.loc["104", "right_neighbour"] == "102"
    assert list(lanes.loc["101", "successors"]) == ["106"]  # 999 is outside the converter's crop
    assert list(lanes.loc["106", "predecessors"]) == ["101"]
    assert maps.loc["401", "kind"] == "crosswalk"

    def width(fid):  # the polygon's area over its centre line's length
        poly = shapely.Polygon(zip(lanes.loc[fid, "polygon_x"], lanes.loc[fid, "polygon_y"]))
        return poly.area / shapely.LineString(zip(lanes.loc[fid, "line_x"], lanes.loc[fid, "line_y"])).length

    assert width("101") == pytest.approx(3.6, abs=1e-3)  # its boundaries, 1.8 m to each side
    assert width("103") == pytest.approx(DEFAULT_LANE_WIDTH, abs=1e-6)  # unknown: the default
    frames = pd.read_parquet(out)
    assert (frames.map_id == SCENE).all()
    on = frames.set_index(["frame_index", "track_id"]).lane  # as_waymo's ids: ego 0, car_a 1, car_b 2
    assert set(on.xs("0", level=1)) == {"101"} and set(on.xs("2", level=1)) == {"104"}
    assert set(on.xs("1", level=1)) == {"102"}


def _set(feature: str, **values):
    return lambda sd: sd["map_features"][feature].update(values)


def _rename(old: str, new: str):
    return lambda sd: sd["map_features"].__setitem__(new, sd["map_features"].pop(old))


# (how the pickle is broken, the repair it is counted as, whether --strict-maps refuses it)
BROKEN = {
    "width 1e-300 (35.12)": (_set("101", width=np.full((201, 2), 1e-300)), "3 lane widths from the default", False),
    "width 1e300 a vertex (35.15)": (_set("101", width=np.full((201, 2), 1e300)), "3 lane widths from the default",
                                     False),
    "width 1e300 (35.15)": (_set("101", width=1e300), "3 lane widths from the default", True),
    "width 'abc' (35.15)": (_set("101", width="abc"), "3 lane widths from the default", True),
    "width NaN": (_set("101", width=np.full((201, 2), np.nan)), "3 lane widths from the default", True),
    "left_neighbor = 5 (35.15)": (_set("101", left_neighbor=5), "1 lane links to no lane dropped", True),
    "neighbour id a lone surrogate (35.15)": (_set("101", left_neighbor=[{"feature_id": "\udc00"}]),
                                              "1 lane links to no lane dropped", True),
    "feature id a lone surrogate (35.15)": (_rename("203", "\ud800"), "1 features breaking a map rule dropped", True),
    "type a lone surrogate (35.15)": (_set("203", type="ROAD_LINE_\ud800"), "1 features breaking a map rule dropped",
                                      True),
    "polyline of strings": (_set("203", polyline=[["a", "b"], ["c", "d"]]), "1 features breaking a map rule dropped",
                            True),
    "crosswalk without polygon": (lambda sd: sd["map_features"]["401"].pop("polygon"),
                                  "1 features breaking a map rule dropped", True),
    "exit_lanes = {}": (_set("101", exit_lanes={}), "1 lane links to no lane dropped", True),
}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_a_broken_map_feature_is_repaired_or_dropped_and_counted_and_refused_with_strict_maps(tmp_path, case):
    break_it, counted, strict_refuses = BROKEN[case]
    sd = waymo_scenario()
    break_it(sd)
    path = _write(sd, tmp_path / "in")
    res = run_r2s("extract", "scenarionet", str(path), "--out", str(tmp_path / "out"))
    assert res.returncode == 0, res.stderr
    assert counted in _summary(res), _summary(res)
    assert len(pd.read_parquet(tmp_path / "out")) == 143  # a map never costs the tracks
    res = run_r2s("extract", "scenarionet", str(path), "--out", str(tmp_path / "strict"), "--strict-maps")
    if strict_refuses:
        assert_one_line_error(res, 2, "map 'wmsynthwaymo'")
        assert not (tmp_path / "strict").exists()
    else:
        assert res.returncode == 0, res.stderr


def test_a_width_of_1e_300_gives_a_map_every_verb_reads(tmp_path):
    """35.12: extract wrote a lane polygon of width 1e-300, which `r2s scene` / `run --lanes` then refused (a
    self-intersecting polygon once moved into the ego frame)."""
    sd = waymo_scenario()
    sd["map_features"]["101"]["width"] = np.full((201, 2), 1e-300, dtype=float)
    path = _write(sd, tmp_path / "in")
    out = tmp_path / "frames"
    assert run_r2s("extract", "scenarionet", str(path), "--out", str(out), "--every", "10").returncode == 0
    for k in (0, 10, 20):
        res = run_r2s("scene", str(out), f"{SCENE}/{k}", "--out", str(tmp_path / f"s{k}.json"))
        assert res.returncode == 0, res.stderr
        road = json.loads((tmp_path / f"s{k}.json").read_text())["road"]
        assert "101" in {f["id"] for f in road["features"]}
    res = run_r2s("run", str(out), "--lanes", "--motion", "--jobs", "1", "--out", str(tmp_path / "p.parquet"))
    assert res.returncode == 0, res.stderr
    programs = pd.read_parquet(tmp_path / "p.parquet")
    assert len(programs) == 3 and (programs.status == "optimal").all()
    assert programs.program.str.contains("in lane").any()


def test_a_zigzag_centre_line_is_dropped_within_bounded_memory(tmp_path):
    """35.5: a lane without polygon whose centre line zigzags with 10^4 points (a 264 KB pickle) took 1.5 GB, then
    exit 1 (GEOSException: std::bad_alloc) from the buffer that widens it."""
    sd = waymo_scenario()
    n = 10_000
    zigzag = np.stack([np.arange(n) * 0.01, (np.arange(n) % 2) * 1.0, np.zeros(n)], axis=1).astype("float32")
    sd["map_features"]["103"].update(polyline=zigzag, width=np.zeros((n, 2), dtype="float32"))
    path = _write(sd, tmp_path / "in")
    res = run_bounded("extract", "scenarionet", str(path), "--out", str(tmp_path / "out"), timeout=60,
                      max_rss_mb=600)
    assert res.returncode == 0, res.stderr
    assert "1 lanes whose centre line cannot be widened dropped" in _summary(res)
    assert "103" not in set(pd.read_parquet(tmp_path / "out" / "_maps").feature_id)
    res = run_bounded("extract", "scenarionet", str(path), "--out", str(tmp_path / "strict"), "--strict-maps",
                      timeout=60, max_rss_mb=600)
    assert res.returncode == 2 and "lane '103' has a centre line that cannot be widened" in res.stderr


@pytest.mark.parametrize("map_features", [[1, 2], np.zeros(3), "map"])
def test_a_map_that_cannot_be_used_leaves_the_frames_without_road_columns(tmp_path, map_features):
    sd = waymo_scenario()
    sd["map_features"] = map_features
    path = _write(sd, tmp_path / "in")
    res = run_r2s("extract", "scenarionet", str(path), "--out", str(tmp_path / "out"))
    assert res.returncode == 0, res.stderr
    lines = res.stderr.strip().splitlines()
    assert any("its map cannot be used" in line and "without road columns" in line for line in lines), lines
    assert _summary(res).endswith("1 maps unusable (their frames have no road columns)")
    frames = pd.read_parquet(tmp_path / "out")
    assert len(frames) == 143 and frames.map_id.isna().all() and frames.lanes.isna().all()
    assert not (tmp_path / "out" / "_maps").exists()
    res = run_r2s("extract", "scenarionet", str(path), "--out", str(tmp_path / "strict"), "--strict-maps")
    assert_one_line_error(res, 2, "map_features is")


@pytest.mark.parametrize("where", ["track id", "scenario id", "category", "sdc id"])
def test_a_lone_surrogate_outside_the_map_is_one_line_and_exit_2(tmp_path, where):
    """35.15: a string UTF-8 cannot write in a track id, scenario id or category was a UnicodeEncodeError."""
    sd = waymo_scenario()
    bad = "\ud800x"
    if where == "track id":
        sd["tracks"][bad] = sd["tracks"].pop("1")
    elif where == "scenario id":
        sd["metadata"]["scenario_id"] = bad
    elif where == "category":
        sd["tracks"]["1"]["metadata"]["type"] = bad
    else:
        sd["tracks"][bad] = sd["tracks"].pop(sd["metadata"]["sdc_id"])
        sd["metadata"]["sdc_id"] = bad
    res = run_r2s("extract", "scenarionet", str(_write(sd, tmp_path / "in")), "--out", str(tmp_path / "out"))
    assert_one_line_error(res, 2, "lone surrogate")


# ------------------------------------------------------------------------------ the real files (../shared)


@pytest.fixture(scope="module")
def waymo_frames(tmp_path_factory):
    out = tmp_path_factory.mktemp("waymo") / "frames"
    res = run_r2s("extract", "scenarionet", str(WAYMO), "--out", str(out), "--strict-maps", timeout=600)
    assert res.returncode == 0, res.stderr
    return out, _summary(res)


def _pickles() -> dict[str, dict]:
    out = {}
    for f in sorted(WAYMO.glob("*.pkl")):
        with open(f, "rb") as fh:
            sd = pickle.load(fh)
        out[sd["metadata"]["scenario_id"]] = sd
    return out


def _is_lane(feat: dict) -> bool:
    return "LANE" in feat["type"] or (feat["type"] == "UNKNOWN" and "entry_lanes" in feat)


def _distinct(polyline) -> np.ndarray:
    p = np.asarray(polyline, dtype=float)[:, :2]
    keep = np.ones(len(p), dtype=bool)
    keep[1:] = (np.diff(p, axis=0) != 0).any(axis=1)
    return p[keep]


@needs_waymo
def test_all_twelve_shared_waymo_scenarios_extract_with_their_maps(waymo_frames):
    out, summary = waymo_frames
    frames = pd.read_parquet(out)
    assert frames.scene.nunique() == 12 and len(frames.frame_id.unique()) == 10 * 91 + 2 * 198
    assert frames.map_id.notna().all() and (frames.map_id == frames.scene).all()
    assert frames.lane.notna().mean() > 0.5  # most road users are on a lane
    assert "lane widths from the default" in summary and "one-point features dropped" in summary
    assert "breaking a map rule" not in summary  # nothing the converter writes is a broken rule


@needs_waymo
def test_the_lane_graph_is_the_files(waymo_frames):
    out, _ = waymo_frames
    maps = pd.read_parquet(out / "_maps")
    for scene, sd in _pickles().items():
        mine = maps[(maps.map_id == scene) & (maps.kind == "lane")].set_index("feature_id")
        lanes = {fid: f for fid, f in sd["map_features"].items() if _is_lane(f) and len(_distinct(f["polyline"])) >= 2}
        assert set(mine.index) == set(lanes)
        for fid, f in lanes.items():
            row = mine.loc[fid]
            assert list(row.successors) == [str(e) for e in f["exit_lanes"] if str(e) in lanes]
            assert list(row.predecessors) == [str(e) for e in f["entry_lanes"] if str(e) in lanes]
            for side, col in (("left_neighbor", "left_neighbour"), ("right_neighbor", "right_neighbour")):
                want = f[side][0]["feature_id"] if f[side] and f[side][0]["feature_id"] in lanes else None
                assert row[col] == want, (scene, fid, side)


MARGIN = 0.05  # metres: a box this near a lane's edge is not decided by the check (joins and caps differ there)


def _lane_geometry(f: dict):
    """A lane's centre-line segments and its half widths, if the file knows them (every per-vertex width within
    the documented bounds on both sides), from the pickle: the means of each side (docs/formats.md)."""
    p = _distinct(f["polyline"])
    w = np.asarray(f.get("width", np.zeros((0, 2))), dtype=float)
    known = len(w) == len(f["polyline"]) and ((w >= MIN_HALF_WIDTH) & (w <= MAX_HALF_WIDTH)).all()
    return p[:-1], p[1:], (w[:, 0].mean(), w[:, 1].mean()) if known else None


def _sure(a: np.ndarray, b: np.ndarray, half: tuple[float, float], x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """For each point, whether it is inside the lane (1), outside (0), or too near its edge to say (-1): inside
    if, square to some segment and on its left / right, it is within the half width of that side (less MARGIN);
    outside if farther from the whole centre line than the larger half width (plus MARGIN)."""
    d = b - a
    length2 = (d * d).sum(axis=1)
    px, py = x[:, None] - a[:, 0], y[:, None] - a[:, 1]
    t = (px * d[:, 0] + py * d[:, 1]) / length2
    cross = (d[:, 0] * py - d[:, 1] * px) / np.sqrt(length2)  # > 0: left of the segment
    side = np.where(cross > 0, half[0], half[1])
    inside = ((t >= 0) & (t <= 1) & (np.abs(cross) <= side - MARGIN)).any(axis=1)
    tc = np.clip(t, 0, 1)
    gap = np.hypot(px - tc * d[:, 0], py - tc * d[:, 1]).min(axis=1)
    return np.where(inside, 1, np.where(gap > max(half) + MARGIN, 0, -1))


@needs_waymo
def test_every_boxs_lane_facts_agree_with_the_lanes_centre_lines_and_widths(waymo_frames):
    out, _ = waymo_frames
    frames = pd.read_parquet(out)
    checked = 0
    for scene, sd in _pickles().items():
        mine = frames[frames.scene == scene]
        sdc = sd["metadata"]["sdc_id"]
        xy = np.array([np.asarray(sd["tracks"][sdc if r.is_ego else r.track_id]["state"]["position"])[
            r.frame_index, :2] for r in mine.itertuples()], dtype=float)
        x, y = xy[:, 0], xy[:, 1]
        inside = np.zeros((len(mine), 0), dtype=bool)
        undecided = np.zeros(len(mine), dtype=bool)
        names = []
        for fid, f in sd["map_features"].items():
            if not _is_lane(f) or len(_distinct(f["polyline"])) < 2:
                continue
            a, b, half = _lane_geometry(f)
            lo, hi = np.minimum(a.min(axis=0), b.min(axis=0)), np.maximum(a.max(axis=0), b.max(axis=0))
            far = MAX_HALF_WIDTH + MARGIN
            near = (x >= lo[0] - far) & (x <= hi[0] + far) & (y >= lo[1] - far) & (y <= hi[1] + far)
            status = np.zeros(len(mine), dtype=int)
            if near.any():
                # widths the file does not know: a box that may be in this lane is not checked
                status[near] = _sure(a, b, half or (MAX_HALF_WIDTH,) * 2, x[near], y[near])
                if half is None:
                    status[status == 1] = -1
            undecided |= status == -1
            inside = np.column_stack([inside, status == 1])
            names.append(fid)
        crosswalks = [shapely.Polygon(np.asarray(f["polygon"])[:, :2]) for f in sd["map_features"].values()
                      if f["type"] == "CROSSWALK"]
        points = shapely.points(xy)
        on_crosswalk = np.zeros(len(mine), dtype=bool)
        for c in crosswalks:
            on_crosswalk |= shapely.covers(c, points)
        assert (mine.on_crosswalk.to_numpy() == on_crosswalk).all()
        for k, r in enumerate(mine.itertuples()):
            if undecided[k]:
                continue
            checked += 1
            want = {names[j] for j in np.flatnonzero(inside[k])}
            got = set(r.lanes) if r.lanes is not None else set()
            assert got == want, (r.frame_id, r.entity_id, got, want)
            assert (r.lane is None) == (not want) and (r.lane is None or r.lane in want)
            assert r.off_road == (not want)
    assert checked >= len(frames) // 4, (checked, len(frames))


@needs_waymo
def test_the_verbs_run_on_a_waymo_clip(tmp_path):
    """On a 20-second clip: programs with lanes and motion, window programs over time, a frame as scene JSON
    with its road, and that frame exported both ways (and the ScenarioNet export read back)."""
    clip = WAYMO / "sd_waymo_v1.2_1096927972b9efaa.pkl"
    frames = tmp_path / "frames"
    res = run_r2s("extract", "scenarionet", str(clip), "--every", "20", "--out", str(frames), "--strict-maps")
    assert res.returncode == 0, res.stderr
    scene = pd.read_parquet(frames).scene.iloc[0]
    res = run_r2s("run", str(frames), "--lanes", "--motion", "--jobs", "1", "--time-limit", "20",
                  "--out", str(tmp_path / "p.parquet"))
    assert res.returncode == 0, res.stderr
    programs = pd.read_parquet(tmp_path / "p.parquet")
    assert len(programs) == 10 and programs.status.isin(["optimal", "feasible"]).all()
    assert programs.program.str.contains("in lane").any()
    res = run_r2s("run", str(frames), "--lanes", "--window", "4", "--jobs", "1", "--time-limit", "20",
                  "--out", str(tmp_path / "w.parquet"))
    assert res.returncode == 0, res.stderr
    windows = pd.read_parquet(tmp_path / "w.parquet")
    assert len(windows) >= 3 and (windows.n_frames > 1).all() and windows.status.isin(["optimal", "feasible"]).all()
    res = run_r2s("scene", str(frames), f"{scene}/100", "--out", str(tmp_path / "s.json"))
    assert res.returncode == 0, res.stderr
    assert json.loads((tmp_path / "s.json").read_text())["road"]["features"]
    for to in ("scenarionet", "openscenario"):
        res = run_r2s("export", str(tmp_path / "s.json"), "--to", to, "--out", str(tmp_path / to))
        assert res.returncode == 0, res.stderr
    res = run_r2s("extract", "scenarionet", str(tmp_path / "scenarionet"), "--out", str(tmp_path / "back"),
                  "--strict-maps")
    assert res.returncode == 0, res.stderr
    assert len(pd.read_parquet(tmp_path / "back")) == len(json.loads((tmp_path / "s.json").read_text())["entities"])


def test_what_the_other_converters_write_is_read_as_they_write_it():
    """Types and layouts of the nuScenes, nuPlan and Argoverse 2 converters beside Waymo's: a sidewalk
    (ROAD_EDGE_SIDEWALK, a polygon) is not kept, where it used to be taken for a road line without a line;
    UNKNOWN_LINE (Argoverse 2's unknown marks) and an UNKNOWN polyline (MetaDrive's unknown boundary) are road
    lines; nuPlan's neighbours are lists of ids; Argoverse 2's widths are zeros throughout (the default)."""
    features = waymo_scenario()["map_features"]
    features["501"] = {"type": "ROAD_EDGE_SIDEWALK", "polygon": np.array([[0, 10], [5, 10], [5, 12.0]])}
    features["502"] = {"type": "UNKNOWN_LINE", "polyline": np.array([[0, 11], [9, 11.0]])}
    features["503"] = {"type": "UNKNOWN", "polyline": np.array([[0, 12], [9, 12.0]])}
    features["102"]["left_neighbor"] = ["104"]  # nuPlan: ids
    features["101"]["width"] = np.zeros_like(features["101"]["width"])  # Argoverse 2: zeros
    repairs = MapRepairs(strict=True)
    road = scenario_map(SCENE, features, "waymo", repairs)
    kinds = {f.feature_id: f.kind for f in road.features}
    assert "501" not in kinds and kinds["502"] == kinds["503"] == "road_line"
    assert road["102"].left == "104"
    assert repairs.counts == {"lane widths from the default": 3, "one-point features dropped": 2}
    ring = shapely.Polygon(road["101"].polygon)
    assert ring.area / shapely.LineString(road["101"].line).length == pytest.approx(DEFAULT_LANE_WIDTH)
