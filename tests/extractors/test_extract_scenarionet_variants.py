"""What varies across ScenarioNet's converters (issue 13), on real nuScenes-mini tracks re-laid out as each
converter lays out its own (tests/support/scenarionet_layouts.py names the upstream code): Waymo, nuPlan and Argoverse 2
tracks, int or str track ids and sdc_id, per-step arrays of shape (T,) or (T, 1), `valid` as bool or float;
object types no map knows (typed by their MetaDrive type, else Object / left out, and counted); a scenario id
that a merged database holds twice (the first kept, the second skipped with a warning naming both files).
"""

from __future__ import annotations

import copy

import pandas as pd
import pytest

from extractors.base import MAX_NAMES, ExtractOptions, ExtractTally
from extractors.categories import ALL, VEHICLES
from extractors.scenarionet import extract
from frames.rows import read_frames
from tests.support.extract import frames_of, r2s
from tests.support.scenarionet_layouts import (
    as_av2,
    as_nuplan,
    as_waymo,
    load_real,
    merge_database,
    write_single_worker,
    write_to_directory,
)
from tests.support.scenarionet_rows import assert_rows_match, real_scenarios

# The class each MetaDrive type is documented to become (extractors/categories.py).
METADRIVE_CLASS = {"VEHICLE": "Car", "PEDESTRIAN": "Pedestrian", "CYCLIST": "Bicycle", "OTHER": "Object",
                   "TRAFFIC_CONE": "TrafficCone", "TRAFFIC_BARRIER": "Barrier"}


def _int_sdc_str_tracks(sd: dict) -> dict:
    sd = as_waymo(sd)
    sd["metadata"]["sdc_id"] = int(sd["metadata"]["sdc_id"])
    return sd


def _int_ids_int_valid(sd: dict) -> dict:
    sd = as_waymo(sd, ids_as_int=True)
    for tr in sd["tracks"].values():
        tr["state"]["valid"] = tr["state"]["valid"].astype(int)
    return sd


LAYOUTS = {
    "waymo": as_waymo,
    "waymo-int-ids-int-valid": _int_ids_int_valid,
    "waymo-int-sdc-str-tracks": _int_sdc_str_tracks,
    "nuplan": as_nuplan,
    "av2": as_av2,
}


@pytest.mark.parametrize("layout", list(LAYOUTS))
def test_every_converter_layout_gives_every_frame_and_box(tmp_path, layout):
    scenarios = [LAYOUTS[layout](sd) for sd in real_scenarios()]
    db = write_single_worker(copy.deepcopy(scenarios), tmp_path / layout, layout.split("-")[0], "v1")
    got = frames_of(extract, db, categories=ALL, radius=1e9)
    assert_rows_match(got, scenarios)
    # every track's class is its MetaDrive type's; sizes are the converter's (AV2: its estimated constants)
    kinds = {(sd["metadata"]["scenario_id"], str(t)): tr["type"] for sd in scenarios for t, tr in sd["tracks"].items()}
    others = got[~got.is_ego]
    want = [METADRIVE_CLASS[kinds[(s, t)]] for s, t in zip(others.scene, others.track_id)]
    assert list(others.type) == want
    if layout == "av2":
        cars = others[others.type == "Car"]
        assert (cars.length == 4.0).all() and (cars.width == 2.0).all()


def test_lyft_and_nuscenes_types_in_metadata_type_win_over_the_metadrive_type(tmp_path):
    sd = as_waymo(real_scenarios()[0])
    sd["metadata"]["dataset"] = "lyft"
    lyft = {"VEHICLE": "truck", "PEDESTRIAN": "pedestrian", "CYCLIST": "bicycle", "OTHER": "animal"}
    for tr in sd["tracks"].values():
        tr["metadata"]["type"] = lyft[tr["type"]]
    db = write_single_worker([sd], tmp_path / "lyft", "lyft", "v1")
    got = frames_of(extract, db, categories=ALL, radius=1e9)
    others = got[~got.is_ego]
    classes = {"truck": "Truck", "pedestrian": "Pedestrian", "bicycle": "Bicycle", "animal": "Animal"}
    assert list(others.type) == [classes[c] for c in others.category]
    assert set(others.category) <= set(lyft.values()) and "truck" in set(others.category)


def _with_unknown_types(tmp_path):
    """The real scene-0103 (nuScenes converter): one car's metadata.type unknown (its MetaDrive type VEHICLE is
    known), one pedestrian's type and MetaDrive type both unknown."""
    sd = real_scenarios()[1]
    assert sd["metadata"]["scenario_id"] == "scene-0103"
    sdc = sd["metadata"]["sdc_id"]
    car = next(t for t, tr in sd["tracks"].items() if tr["metadata"]["type"] == "vehicle.car" and t != sdc)
    ped = next(t for t, tr in sd["tracks"].items() if tr["metadata"]["type"].startswith("human."))
    sd["tracks"][car]["metadata"]["type"] = "vehicle.hovercraft"
    sd["tracks"][ped]["metadata"]["type"] = "human.jetpack"
    sd["tracks"][ped]["type"] = "FLYING"
    db = write_single_worker([sd], tmp_path / "db", "nuscenes", "v1.0-mini")
    return db, car, ped


def test_unknown_object_types_are_typed_by_their_metadrive_type_or_object_and_counted(tmp_path, capsys):
    db, car, ped = _with_unknown_types(tmp_path)
    tally = ExtractTally()
    got = pd.DataFrame([r for f in extract(str(db), ExtractOptions(categories=ALL, radius=1e9), tally) for r in f])
    car_rows, ped_rows = got[got.track_id == car], got[got.track_id == ped]
    assert len(car_rows) and (car_rows.type == "Car").all() and (car_rows.category == "vehicle.hovercraft").all()
    assert len(ped_rows) and (ped_rows.type == "Object").all() and (ped_rows.category == "human.jetpack").all()
    assert tally.by_fallback == {"vehicle.hovercraft as VEHICLE": len(car_rows)}
    assert tally.unknown_kept == {"human.jetpack": len(ped_rows)} and not tally.unknown_left_out

    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out), "--radius", "1000", "--categories",
              "vehicles")
    assert res.returncode == 0, res.stderr
    df = read_frames(out)
    assert car in set(df.track_id) and ped not in set(df.track_id)  # vehicles: the unknown pedestrian left out
    assert res.stderr.strip().endswith(
        f"objects of unknown type: {len(car_rows)} typed by their MetaDrive type "
        f"(vehicle.hovercraft as VEHICLE x{len(car_rows)}), {len(ped_rows)} left out (human.jetpack x{len(ped_rows)})")


def test_a_scenario_id_held_twice_is_read_once_with_a_warning_naming_both_files(tmp_path, capsys):
    mini = write_single_worker(real_scenarios(), tmp_path / "mini", "nuscenes", "v1.0-mini")
    # the same scene converted again under another version: another file name, the same scenario id
    again = write_single_worker([real_scenarios()[1]], tmp_path / "trainval", "nuscenes", "v1.0-trainval")
    merged = tmp_path / "merged"
    _, mapping = merge_database(merged, mini, again)
    assert len(mapping) == 4

    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(merged), "--categories", "all", "--out", str(out))
    assert res.returncode == 0, res.stderr
    warning, summary = res.stderr.strip().splitlines()
    skipped = merged / "../trainval/sd_nuscenes_v1.0-trainval_scene-0103.pkl"
    kept = merged / "../mini/sd_nuscenes_v1.0-mini_scene-0103.pkl"
    assert warning == f"r2s extract: skipping {skipped}: scenario 'scene-0103' was already read from {kept}"
    df = read_frames(out)
    alone = frames_of(extract, mini, categories=ALL)
    # the extractor's rows carry no lane facts (the writer decides them, with the maps): the columns both have
    common = [c for c in df.columns if c in alone.columns]
    pd.testing.assert_frame_equal(df[common], alone[common].astype(df[common].dtypes.to_dict()), check_dtype=False)
    assert summary == (f"r2s extract: 4 scenarios, {df.frame_id.nunique()} frames, {len(df)} rows -> {out}; "
                       "skipped 1 scenarios (duplicate scenario id x1)")


def test_a_scenario_whose_ego_is_never_valid_is_counted_as_skipped(tmp_path):
    sds = real_scenarios()
    sdc = sds[0]["metadata"]["sdc_id"]
    sds[0]["tracks"][sdc]["state"]["valid"][:] = 0
    db = write_single_worker(sds, tmp_path / "db", "nuscenes", "v1.0-mini")
    tally = ExtractTally()
    frames = list(extract(str(db), ExtractOptions(categories=VEHICLES), tally))
    assert {f[0]["scene"] for f in frames} == {sd["metadata"]["scenario_id"] for sd in sds[1:]}
    assert tally.scenarios == 2 and tally.skipped == {"no step with a valid ego": 1} and tally.scenarios_read == 3


def test_the_six_shared_scenes_through_workers_and_a_merge(shared_dir, tmp_path):
    """The full shared nuScenes-mini conversions, as a 4-worker database merged with a 2-worker one (in pickle
    protocol 5), extract to exactly the rows of the plain folder (which test_extract_scenarionet checks against
    the nuScenes keyframes)."""
    plain = shared_dir / "data" / "nuscenes-mini" / "scenarionet"
    files = sorted(plain.glob("sd_*.pkl"))
    sds = [load_real(f) for f in files]
    write_to_directory(sds[:4], tmp_path / "first", "nuscenes", "v1.0-mini", num_workers=4, protocol=5)
    write_to_directory(sds[4:], tmp_path / "second", "nuscenes", "v1.0-mini", num_workers=2, protocol=5)
    merged = tmp_path / "merged"
    _, mapping = merge_database(merged, tmp_path / "first", tmp_path / "second", protocol=5)
    assert len(set(mapping.values())) == 6 and all(v.startswith("../") for v in mapping.values())
    got = frames_of(extract, merged, categories=ALL)
    pd.testing.assert_frame_equal(got, frames_of(extract, plain, categories=ALL))


def test_a_file_of_endless_unknown_types_does_not_grow_the_tally(tmp_path):
    # every track a different unknown type: the counts stay exact, the names kept apart stay bounded
    sd = as_waymo(real_scenarios()[0])
    sdc = sd["metadata"]["sdc_id"]
    for i, (tid, tr) in enumerate(sd["tracks"].items()):
        if tid != sdc:
            tr["type"] = tr["metadata"]["type"] = f"KIND_{i}"
    db = write_single_worker([sd], tmp_path / "db", "waymo", "v1")
    tally = ExtractTally()
    got = pd.DataFrame([r for f in extract(str(db), ExtractOptions(categories=ALL, radius=1e9), tally) for r in f])
    others = got[~got.is_ego]
    assert (others.type == "Object").all() and others.category.nunique() > 2 * MAX_NAMES
    assert sum(tally.unknown_kept.values()) == len(others) and len(tally.unknown_kept) == MAX_NAMES + 1
    assert tally.unknown_kept["..."] == len(others[~others.category.isin(set(tally.unknown_kept))])
