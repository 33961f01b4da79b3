"""`r2s export --to opendrive`: the recorded road as linked OpenDRIVE, run as a user runs it, on the shipped
nuScenes scenes (scene JSON: their road within r2s scene's radius) and the shipped Argoverse 2 log's whole map
(its maps dataset). ASAM's checker reports no issue; Scenic's own parser loads the file with the map's junctions
as intersections, each lane within 0.10 m of the recorded centre line it follows, the recorded successor links
kept as successors or junction maneuvers, lanes of one road side by side as recorded neighbours Scenic sees as
adjacent; a lane-following car in Scenic's Newtonian simulator drives from a
lane into its successor."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from frames.maps import read_maps
from pipeline.export.opendrive import export_road
from synth.road import opendrive_group
from synth.road.opendrive import network
from tests.support import SHARED, assert_one_line_error, run_r2s
from tests.support.extract import EXCERPT

from .test_export_openscenario import asam_issues

AV2_MAPS = Path(__file__).resolve().parents[3] / "data" / "argoverse2-log-excerpt" / "frames.maps"
SCENES = ("scene-0061/0", "scene-0103/0", "scene-0796/1")
WAYMO = SHARED / "data" / "waymo" / "sd_waymo_v1.2_1096927972b9efaa.pkl"  # the smallest shared map (105 lanes)
TOLERANCE = 0.10  # metres: a Scenic lane's largest distance from its recorded centre line (issue 37)


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("odr-scenes")
    frames = root / "frames.parquet"
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(frames)).returncode == 0
    out = {}
    for fid in SCENES:
        out[fid] = root / f"{fid.replace('/', '_')}.json"
        res = run_r2s("scene", str(frames), fid, "--out", str(out[fid]))
        assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def av2(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("odr-av2") / "map.xodr"
    res = run_r2s("export", str(AV2_MAPS), "--to", "opendrive", "--out", str(out))
    assert res.returncode == 0, res.stderr
    return out


@pytest.mark.parametrize("fid", SCENES)
def test_asam_checker_reports_no_issue_on_a_scene_road(fid, scenes, tmp_path):
    out = tmp_path / "road.xodr"
    res = run_r2s("export", str(scenes[fid]), "--to", "opendrive", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert asam_issues(out) == []


def test_asam_checker_reports_no_issue_on_a_whole_map_with_junctions(av2):
    root = ET.parse(av2).getroot()
    assert len(root.findall("junction")) > 0 and any(r.get("junction") != "-1" for r in root.findall("road"))
    assert asam_issues(av2) == []


@pytest.fixture(scope="module")
def waymo(tmp_path_factory) -> tuple[Path, Path]:
    """A shared Waymo scenario's map (ScenarioNet's format; skipped without ../shared) and its .xodr."""
    if not WAYMO.exists():
        pytest.skip(f"{WAYMO} is not here")
    root = tmp_path_factory.mktemp("odr-waymo")
    (root / "in").mkdir()
    (root / "in" / WAYMO.name).symlink_to(WAYMO)
    assert run_r2s("extract", "scenarionet", str(root / "in"), "--out", str(root / "f.parquet")).returncode == 0
    res = run_r2s("export", str(root / "f.maps"), "--to", "opendrive", "--out", str(root / "map.xodr"))
    assert res.returncode == 0 and "bridged" in res.stdout, res.stderr  # two recorded links 2 m and 20 m long
    return root / "f.maps", root / "map.xodr"


@pytest.mark.parametrize("which", ["av2", "waymo"])
def test_scenic_loads_the_map_with_its_junctions_and_lanes_on_the_recorded_centre_lines(which, request):
    pytest.importorskip("scenic")
    from tests.support.opendrive import adjacent_pairs, centre_line_gaps, kept_links, offset, scenic_network

    maps, av2 = (AV2_MAPS, request.getfixturevalue("av2")) if which == "av2" else request.getfixturevalue("waymo")
    road = next(iter(read_maps(maps)))
    if which == "waymo":
        assert asam_issues(av2) == []
    net = scenic_network(av2)
    assert len(net.intersections) == len(ET.parse(av2).getroot().findall("junction")) > 0
    # every recorded intersection lane between two lanes of the map is in a junction (a connecting road's)
    inside = {n for r in net.connectingRoads for n in r.name.split(" > ")}
    lanes = {f.feature_id for f in road.lanes}
    between = [f.feature_id for f in road.lanes if f.is_intersection and lanes & set(f.predecessors)
               and lanes & set(f.successors)]
    assert (between or which == "waymo") and set(between) <= inside  # Waymo records no intersection lanes
    gaps = centre_line_gaps(net, road, offset(av2))
    assert len(gaps) >= 0.95 * len(road.lanes) and max(gaps.values()) < TOLERANCE
    kept, lost = kept_links(net, road)
    assert len(kept) >= 0.99 * (len(kept) + len(lost)) and len(kept) > 100  # issue 37's bar (all of them today)
    # lanes side by side: each pair of neighbouring lanes of one written road (its name's lanes left to right,
    # each the recorded lanes it follows: a lane's last metres may be put before its successor) follows a
    # recorded neighbour pair, which Scenic sees as adjacent lanes, or a lane beside a lane continuing its recorded
    # neighbour (its predecessor or successor; or the neighbour of a lane it continues)
    adjacent, _ = adjacent_pairs(net, road)
    written = [tuple(x.split(" > ") for x in pair) for r in ET.parse(av2).getroot().findall("road")
               for pair in zip(r.get("name").split(" | "), r.get("name").split(" | ")[1:])]
    feature = {f.feature_id: f for f in road.lanes}

    def linked(x: str) -> set[str]:
        return {x, *feature[x].successors, *feature[x].predecessors} | {
            k for k, f in feature.items() if x in f.successors or x in f.predecessors}

    def right_of(x: str) -> set[str]:
        return ({feature[x].right} | {k for k, f in feature.items() if f.left == x}) - {None}

    recorded = [(lf, rt) for lf, rt in written if any(b in right_of(a) for a in lf for b in rt)]
    assert recorded and all(any((a, b) in adjacent for a in lf for b in rt) for lf, rt in recorded)
    assert all(any(b in linked(n) for a in lf for n in right_of(a) for b in rt)
               or any(b in right_of(x) for a in lf for x in linked(a) for b in rt)
               for lf, rt in written if (lf, rt) not in recorded)


def test_a_map_dataset_of_several_maps_needs_one_named(tmp_path):
    maps = tmp_path / "f.maps"
    assert run_r2s("extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out",
                   str(tmp_path / "f.parquet")).returncode == 0
    res = run_r2s("export", str(maps), "--to", "opendrive", "--out", str(tmp_path / "x.xodr"))
    assert_one_line_error(res, contains="name one with --map ID")
    assert not (tmp_path / "x.xodr").exists()
    map_id = next(iter(read_maps(maps))).map_id
    res = run_r2s("export", str(maps), "--to", "opendrive", "--map", map_id, "--out", str(tmp_path / "x.xodr"))
    assert res.returncode == 0, res.stderr
    assert asam_issues(tmp_path / "x.xodr") == []


def test_a_lane_following_car_drives_through_a_junction_into_the_next_road(av2, tmp_path):
    """Scenic's Newtonian simulator, headless (2D, render off): a car with FollowLaneBehavior set 6 m before
    the end of a road that enters a junction leaves it for one of the recorded lanes after it (a connecting
    road's, then its outgoing road's) and keeps moving. One car, 4 s: the whole map's figure is
    bench/bench_opendrive.py's."""
    scenic = pytest.importorskip("scenic")
    import shapely
    from scenic.simulators.newtonian import NewtonianSimulator

    from synth.road.opendrive import lane_graph, network
    from tests.support.opendrive import offset, recorded

    road = next(iter(read_maps(AV2_MAPS)))
    net = network(road)
    assert net.offset == offset(av2)
    start = next(r for r in net.roads if r.junction == -1 and r.successor is not None
                 and r.successor.kind == "junction" and shapely.LineString(r.points).length > 12)
    p = shapely.LineString(start.points).interpolate(shapely.LineString(start.points).length - 6)
    xodr = tmp_path / "map.xodr"  # Scenic writes its cache beside the map
    xodr.write_bytes(av2.read_bytes())
    scenario = scenic.scenarioFromString(
        f"param map = {str(xodr)!r}\nmodel scenic.simulators.newtonian.driving_model\n"
        f"ego = new Car at ({p.x!r}, {p.y!r}), with behavior FollowLaneBehavior(target_speed=6)\n",
        mode2D=True, params={"render": False})
    scene, _ = scenario.generate(maxIterations=10)
    trajectory = NewtonianSimulator().simulate(scene, maxSteps=40).trajectory
    first, last, before = trajectory[0][0], trajectory[-1][0], trajectory[-2][0]
    network = scene.workspace.network
    succ, _ = lane_graph({f.feature_id: f for f in road.lanes})
    after, frontier = set(), {start.lanes[-1]}
    for _ in range(3):  # the recorded lanes within three links after the start (some are shorter than a metre)
        frontier = {s for f in frontier for s in succ[f]} - after
        after |= frontier
    assert (first - last).norm() > 6 and (last - before).norm() > 0.1  # past the road's end, still moving
    # on a recorded lane after its own at some step (the Newtonian lateral controller may weave off a lane
    # after a turn: bench/results/opendrive.md)
    lanes = [network.laneAt(step[0]) for step in trajectory]
    assert any(set(recorded(lane)) & after for lane in lanes if lane is not None), start.lanes


def test_what_opendrive_cannot_be_made_from_is_one_line_and_nothing_is_written(scenes, tmp_path):
    bare = tmp_path / "bare.json"
    bare.write_text('{"frame_id": "log/7", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}]}')
    out = tmp_path / "x.xodr"
    for args, says in (([str(bare)], "has no road"), ([str(scenes["scene-0103/0"]), str(bare)], "give no variants"),
                       ([str(scenes["scene-0103/0"]), "--map", "m"], "--map names a map of a maps dataset"),
                       ([str(AV2_MAPS), "--map", "nope"], "holds no map 'nope'")):
        assert_one_line_error(run_r2s("export", *args, "--to", "opendrive", "--out", str(out)), contains=says)
        assert not out.exists()


def test_a_road_exported_again_in_one_process_is_the_same_file(av2, tmp_path):
    """scenariogeneration numbers objects (crosswalks) in a registry shared by the whole process: a second road
    exported in one process (the API, a batch worker) had its crosswalk ids renumbered, and a warning printed on
    stdout. Each file's ids are its own: in process, twice, the bytes of a fresh process's file."""
    first, again = tmp_path / "a.xodr", tmp_path / "b.xodr"
    export_road(str(AV2_MAPS), None, str(first))
    export_road(str(AV2_MAPS), None, str(again))
    assert b"crosswalk" in av2.read_bytes()
    assert first.read_bytes() == av2.read_bytes() and again.read_bytes() == av2.read_bytes()


def test_the_lanes_the_note_calls_a_junctions_lane_are_an_intersections_a_forks_or_a_merges(monkeypatch):
    """The export's note on the AV2 map: each lane it counts as `a junction's lane` is one by the map alone (an
    intersection lane, one of several successors of a lane, or a lane with several predecessors, a link either
    lane records being a link), not an ordinary lane whose last metres were put before a junction lane."""
    if not AV2_MAPS.exists():
        pytest.skip("no shipped Argoverse 2 map")
    road = next(iter(read_maps(AV2_MAPS)))
    seen = {}
    reasons = opendrive_group.apart_reasons
    monkeypatch.setattr(opendrive_group, "apart_reasons", lambda *a: seen.setdefault("why", reasons(*a)))
    network(road)
    lanes = {f.feature_id: f for f in road.lanes}
    nexts = {k: set(f.successors) for k, f in lanes.items()}
    for k, f in lanes.items():
        for p in f.predecessors:
            nexts.setdefault(p, set()).add(k)
    befores = {k: {p for p, ss in nexts.items() if k in ss} for k in lanes}
    forked = {s for ss in nexts.values() if len(ss) > 1 for s in ss}
    called = [k for k, why in seen["why"].items() if why == opendrive_group.APART[0]]
    assert called and all(lanes[k].is_intersection or k in forked or len(befores[k]) > 1 for k in called)
