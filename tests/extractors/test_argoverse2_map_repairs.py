"""Argoverse 2 maps under the rule of every recorded map (docs/formats.md, "A recorded map that breaks a rule"): a
map never costs the tracks. `r2s extract argoverse2` run as a real process on a small log in av2's own layout
(tests/support/av2_logs.py, so CI without ../shared covers it) and on a copy of the av2-api test log: a feature
that breaks a rule is dropped (a link: the link, the lane kept) and counted in the summary, an archive that cannot
be used leaves the frames without road columns and one line naming it; with --strict-maps each is one line, exit 2,
nothing written."""

from __future__ import annotations

import copy
import json
import shutil
from pathlib import Path
from unittest.mock import patch

import pandas as pd
import pyarrow as pa
import pyarrow.ipc  # noqa: F401 (pa.ipc)
import pytest

from extractors import argoverse2
from tests.support import SHARED, assert_one_line_error, run_r2s
from tests.support.av2_logs import FRAMES, LOG_ID, archive_of, log_map, write_log
from tests.support.extract import r2s

AV2_LOG = SHARED / "data" / "argoverse2" / "test_data" / "sensor_dataset_logs" / "adcf7d18-0510-35b0-a2fa-b4cea13a6d76"
BROKEN = "features breaking a map rule dropped"
LINKS = "lane links to no lane dropped"
UNUSABLE = "1 maps unusable (their frames have no road columns)"


def _extract(log: Path, out: Path, *more: str):
    return run_r2s("extract", "argoverse2", str(log), "--categories", "all", "--out", str(out), *more, timeout=120)


def _summary(proc) -> str:
    return proc.stderr.strip().splitlines()[-1]


def _refused(proc, out: Path, contains: str) -> None:
    assert_one_line_error(proc, contains=contains)
    assert not out.exists() and not out.with_suffix(".maps").exists()
    assert not any(out.parent.iterdir())


def _alike_both_ways(log: Path, tmp_path: Path) -> tuple[pd.DataFrame, pd.DataFrame]:
    """The log's frames and maps, extracted alike with and without --strict-maps, nothing repaired."""
    got = []
    for more in ((), ("--strict-maps",)):
        out = tmp_path / f"out{len(got)}.parquet"
        proc = _extract(log, out, *more)
        assert proc.returncode == 0 and "map repairs" not in proc.stderr, proc.stderr
        got.append((pd.read_parquet(out), pd.read_parquet(out.with_suffix(".maps"))))
    assert got[0][0].equals(got[1][0]) and got[0][1].equals(got[1][1])
    return got[0]


def _edited(edit) -> dict:
    m = copy.deepcopy(log_map())
    edit(m)
    return m


def _lane(m: dict, lane: int) -> dict:
    return m["lane_segments"][str(lane)]


def _set(d: dict, key: str, value) -> None:
    d[key] = value


# (edit of the map, the feature it breaks, the kind counted, whether the feature is kept (only a link dropped),
#  what --strict-maps says)
FEATURES = [
    (lambda m: _set(_lane(m, 12)["left_lane_boundary"][1], "x", float("nan")), "12", BROKEN, False,
     "lane '12' has a point that is not two finite numbers"),
    (lambda m: _set(_lane(m, 12)["left_lane_boundary"][1], "y", "3.5"), "12", BROKEN, False,
     "not two finite numbers"),
    (lambda m: _set(_lane(m, 12)["right_lane_boundary"][0], "x", True), "12", BROKEN, False,
     "not two finite numbers"),
    (lambda m: _set(_lane(m, 12), "id", 12.5), "12", BROKEN, False, "id 12.5 is not an integer"),
    (lambda m: _set(_lane(m, 12), "right_lane_boundary", _lane(m, 12)["right_lane_boundary"][:1] * 2), "12", BROKEN,
     False, "lane '12' has a boundary of fewer than two distinct points"),
    (lambda m: _lane(m, 12).pop("left_lane_boundary"), "12", BROKEN, False, "KeyError"),
    (lambda m: _set(_lane(m, 12), "lane_type", 7), "12", BROKEN, False, "lane_type 7 is not text"),
    (lambda m: _set(_lane(m, 12), "lane_type", "\ud800"), "12", BROKEN, False, "is not text"),
    # edge2 reversed: the crossing's ring crosses itself (a bow tie)
    (lambda m: m["pedestrian_crossings"]["20"]["edge2"].reverse(), "20", BROKEN, False,
     "crosswalk '20' has a self-intersecting polygon"),
    (lambda m: _set(m["pedestrian_crossings"]["20"], "edge1", m["pedestrian_crossings"]["20"]["edge1"] * 2), "20",
     BROKEN, False, "crosswalk '20' has edges that are not two points each"),
    (lambda m: _set(m["drivable_areas"]["30"]["area_boundary"][2], "x", 1e400), "30", BROKEN, False,
     "drivable area '30' has a point that is not two finite numbers"),
    (lambda m: _set(m["drivable_areas"], "31", "an area"), None, BROKEN, False, "a drivable area lacks a field"),
    (lambda m: _set(_lane(m, 10), "successors", [10, 11]), "10", LINKS, True, "lane '10' names itself as its successor"),
    (lambda m: _set(_lane(m, 10), "successors", [None, 11]), "10", LINKS, True, "successor null, which names no lane"),
    (lambda m: _set(_lane(m, 10), "left_neighbor_id", "twelve"), "10", LINKS, True,
     "left neighbour 'twelve', which is not a lane id"),
    (lambda m: _set(_lane(m, 11), "predecessors", 10), "11", LINKS, True, "predecessors 10, not a list of ids"),
]


@pytest.mark.parametrize("edit, feature, kind, kept, message", FEATURES)
def test_a_feature_breaking_a_rule_is_dropped_and_counted_or_refused_with_strict_maps(tmp_path, edit, feature, kind,
                                                                                      kept, message):
    log = write_log(tmp_path / "in", _edited(edit))
    out = tmp_path / "strict" / "frames.parquet"
    out.parent.mkdir()
    proc = _extract(log, out, "--strict-maps")
    _refused(proc, out, message)
    assert str(archive_of(log)) in proc.stderr  # the archive is named

    out = tmp_path / "default" / "frames.parquet"
    proc = _extract(log, out)
    assert proc.returncode == 0, proc.stderr
    assert f"map repairs: 1 {kind}" in _summary(proc) and "maps unusable" not in proc.stderr
    frames, maps = pd.read_parquet(out), pd.read_parquet(out.with_suffix(".maps"))
    assert frames.frame_id.nunique() == FRAMES and (frames.map_id == LOG_ID).all()  # the tracks, on the map
    want = {"10", "11", "12", "20", "30"} - ({feature} if feature and not kept else set())
    assert set(maps.feature_id) == want
    lanes = maps[maps.kind == "lane"].set_index("feature_id")
    for lane in lanes.itertuples():  # every link left names another lane of the map
        links = set(lane.successors) | set(lane.predecessors) | {lane.left_neighbour, lane.right_neighbour}
        assert links <= set(lanes.index) - {lane.Index} | {None}
    if kept:  # the link, not the lane, is gone; the links that name lanes are kept
        assert lanes.successors["10"].tolist() == ["11"] and lanes.predecessors["11"].tolist() == (
            [] if feature == "11" else ["10"])
        assert lanes.left_neighbour["10"] == (None if "neighbour" in message else "12")


def test_the_map_as_written_extracts_alike_with_and_without_strict_maps(tmp_path):
    frames, _ = _alike_both_ways(write_log(tmp_path / "in"), tmp_path)
    # the log's road as written: ego and car in lane 10, the pedestrian in lane 12, nobody off road
    assert set(frames[frames.entity_id != "pedestrian1"].lane) == {"10"}
    assert set(frames[frames.entity_id == "pedestrian1"].lane) == {"12"} and not frames.off_road.any()


# (what the archive holds, what the line says)
UNUSABLE_ARCHIVES = [
    ("{ not JSON", "not a readable Argoverse 2 map archive"),
    (b'{"lane_segments": {"\xff": 1}}', "not a readable Argoverse 2 map archive"),  # not UTF-8
    ("[]", "no lane_segments object"),
    ('{"pedestrian_crossings": {}, "drivable_areas": {}}', "no lane_segments object"),
    ('{"lane_segments": [], "pedestrian_crossings": {}}', "no lane_segments object"),
    ('{"lane_segments": {}, "drivable_areas": []}', "drivable_areas is not an object"),
    ('{"lane_segments": {}, "deep": ' + "[" * 100_000 + "]" * 100_000 + "}", "nested too deeply"),
]


@pytest.mark.parametrize("archive, message", UNUSABLE_ARCHIVES)
def test_an_archive_that_cannot_be_used_leaves_the_frames_without_road_columns_or_is_refused(tmp_path, archive,
                                                                                           message):
    log = write_log(tmp_path / "in", archive)
    out = tmp_path / "strict" / "frames.parquet"
    out.parent.mkdir()
    _refused(_extract(log, out, "--strict-maps"), out, message)

    out = tmp_path / "default" / "frames.parquet"
    proc = _extract(log, out)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    said = [line for line in lines if "its map cannot be used" in line]
    assert len(said) == 1 and str(archive_of(log)) in said[0] and message in said[0], lines
    assert _summary(proc).endswith(UNUSABLE) and "Traceback" not in proc.stderr
    frames = pd.read_parquet(out)
    assert frames.frame_id.nunique() == FRAMES and frames.map_id.isna().all() and frames.lanes.isna().all()
    assert not out.with_suffix(".maps").exists()


def test_two_archives_or_one_beyond_the_bound_are_unusable_and_no_archive_is_no_map(tmp_path, capsys):
    log = write_log(tmp_path / "two")
    shutil.copy(archive_of(log), log / "map" / "log_map_archive_other.json")
    out = tmp_path / "out-two" / "frames.parquet"
    out.parent.mkdir()
    _refused(_extract(log, out, "--strict-maps"), out, "2 map archives")
    proc = _extract(log, out)
    assert proc.returncode == 0 and _summary(proc).endswith(UNUSABLE), proc.stderr
    assert pd.read_parquet(out).map_id.isna().all()

    # beyond MAX_MAP_BYTES (256 MB: here the bound made small, in-process)
    log = write_log(tmp_path / "large")
    out = tmp_path / "large.parquet"
    with patch.object(argoverse2, "MAX_MAP_BYTES", 100):
        res = r2s(capsys, "extract", "argoverse2", str(log), "--out", str(out), "--strict-maps")
        assert res.returncode == 2 and "larger than the limit of 100 bytes" in res.stderr and not out.exists()
        res = r2s(capsys, "extract", "argoverse2", str(log), "--out", str(out))
    assert res.returncode == 0 and res.stderr.strip().splitlines()[-1].endswith(UNUSABLE), res.stderr
    assert res.stderr.count(str(archive_of(log))) == 1

    # no archive: no map and no word, as before (the scenario-mining release ships none)
    log = write_log(tmp_path / "none", None)
    out = tmp_path / "none.parquet"
    for more in ((), ("--strict-maps",)):
        proc = _extract(log, out, *more)
        assert proc.returncode == 0 and len(proc.stderr.strip().splitlines()) == 1, proc.stderr
        assert pd.read_parquet(out).map_id.isna().all() and not out.with_suffix(".maps").exists()


# ------------------------------------------------------------------------------- the av2-api test log (../shared)
needs_shared = pytest.mark.skipif(not AV2_LOG.is_dir(), reason="needs ../shared/data/argoverse2 (the av2-api test log)")
LANE = "42809424"  # a lane of the test log that holds many boxes


def _shared_log(tmp_path: Path, edit=None) -> Path:
    log = tmp_path / "logs" / AV2_LOG.name
    shutil.copytree(AV2_LOG, log)
    for p in log.rglob("*"):  # the shared copy is read-only
        p.chmod(0o755 if p.is_dir() else 0o644)
    if edit is not None:
        archive = archive_of(log)
        data = json.loads(archive.read_text())
        edit(data)
        archive.write_text(json.dumps(data))
    return log


@needs_shared
def test_the_real_log_extracts_alike_with_and_without_strict_maps_every_feature_kept(tmp_path):
    log = _shared_log(tmp_path)
    _, maps = _alike_both_ways(log, tmp_path)
    data = json.loads(archive_of(log).read_text())
    assert len(maps) == sum(len(data[k]) for k in ("lane_segments", "pedestrian_crossings", "drivable_areas"))


@needs_shared
@pytest.mark.parametrize("edit, message", [
    (lambda m: _set(m["lane_segments"][LANE]["left_lane_boundary"][0], "x", float("inf")),
     f"lane '{LANE}' has a point that is not two finite numbers"),
    (lambda m: _set(m["lane_segments"][LANE], "id", 4.5), "id 4.5 is not an integer"),
])
def test_a_broken_lane_of_the_real_log_is_dropped_and_the_others_keep_their_facts(tmp_path, edit, message):
    log = _shared_log(tmp_path / "edited", edit)
    out = tmp_path / "strict" / "frames.parquet"
    out.parent.mkdir()
    _refused(_extract(log, out, "--strict-maps"), out, message)
    out, plain = tmp_path / "edited.parquet", tmp_path / "plain.parquet"
    proc = _extract(log, out)
    assert proc.returncode == 0 and "map repairs: 1 features breaking a map rule dropped" in _summary(proc), proc.stderr
    assert _extract(_shared_log(tmp_path / "plain"), plain).returncode == 0
    got, ref = pd.read_parquet(out), pd.read_parquet(plain)
    maps, ref_maps = pd.read_parquet(out.with_suffix(".maps")), pd.read_parquet(plain.with_suffix(".maps"))
    assert set(ref_maps.feature_id) - set(maps.feature_id) == {LANE}
    assert got.frame_id.equals(ref.frame_id) and got.entity_id.equals(ref.entity_id)  # every track kept
    # boxes that were not in the dropped lane keep every fact
    away = ~ref.lanes.map(lambda lanes: LANE in list(lanes))
    facts = ["lanes", "lane", "in_intersection", "on_crosswalk", "off_road"]
    assert away.sum() > 1000 and got[away][facts].astype(str).equals(ref[away][facts].astype(str))
    assert not got.lanes.map(lambda lanes: LANE in list(lanes)).any()


@needs_shared
def test_an_unusable_archive_of_the_real_log_leaves_its_frames_without_road_columns(tmp_path):
    log = _shared_log(tmp_path)
    archive_of(log).write_text('{"lane_segments": "gone"}')
    out = tmp_path / "strict" / "frames.parquet"
    out.parent.mkdir()
    _refused(_extract(log, out, "--strict-maps"), out, "no lane_segments object")
    out = tmp_path / "default.parquet"
    proc = _extract(log, out)
    assert proc.returncode == 0 and _summary(proc).endswith(UNUSABLE), proc.stderr
    frames = pd.read_parquet(out)
    stamps = pa.ipc.open_file(str(log / "annotations.feather")).read_all().column("timestamp_ns").unique()
    assert frames.frame_id.nunique() == len(stamps) and frames.map_id.isna().all() and frames.lanes.isna().all()
