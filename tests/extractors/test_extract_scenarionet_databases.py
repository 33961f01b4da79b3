"""ScenarioNet databases exactly as ScenarioNet's tools write them (issue 13): a converter's per-worker
sub-databases under a top database, `scenarionet.merge` databases whose mappings point to `../<db>`, summaries
and scenarios holding defaultdict(int) in pickle protocols 4 and 5 — and defaultdicts whose factory would run
code. The layouts come from tests/support/scenarionet_layouts.py (each function there names the upstream function it
mirrors); the scenarios are real nuScenes-mini scenarios, as converted and re-laid out as the Waymo converter
lays out its tracks. Expected rows are computed here from the scenario arrays, independently of the extractor.
"""

from __future__ import annotations

import collections
import os
import pickle
import shutil

import pandas as pd
import pytest

from extractors.categories import ALL
from extractors.safe_pickle import load_pickle
from extractors.scenarionet import extract
from frames.rows import FramesError, read_frames
from tests.support.extract import assert_refused, frames_of, r2s
from tests.support.scenarionet_layouts import (
    MAPPING,
    SUMMARY,
    as_waymo,
    load_real,
    merge_database,
    write_single_worker,
    write_to_directory,
)
from tests.support.scenarionet_rows import assert_rows_match, real_scenarios


def _all(path) -> pd.DataFrame:
    return frames_of(extract, path, categories=ALL, radius=1e9)


@pytest.mark.parametrize("protocol", [4, 5])
def test_per_worker_sub_databases_extract_every_scenario_and_frame(tmp_path, protocol):
    waymo = [as_waymo(sd) for sd in real_scenarios()]
    db = tmp_path / "waymo"
    subdirs = write_to_directory(waymo, db, "waymo", "v1.2", num_workers=2, protocol=protocol)

    # the layout write_to_directory leaves: db/db_0, db/db_1 with their own summary and mapping ("" = here),
    # the top database pointing into them
    assert [p.name for p in subdirs] == ["waymo_0", "waymo_1"]
    assert set(load_real(db / MAPPING).values()) == {"waymo_0", "waymo_1"}
    for sub in subdirs:
        assert set(load_real(sub / MAPPING).values()) == {""}
    top = load_pickle(db / SUMMARY)  # through the restricted unpickler: the defaultdicts are what it meets
    assert (db / SUMMARY).read_bytes()[1] == protocol
    counts = next(iter(top.values()))["number_summary"]["num_moving_objects_each_type"]
    assert isinstance(counts, collections.defaultdict) and counts.default_factory is int and counts["VEHICLE"] > 0
    sd = load_pickle(subdirs[0] / next(iter(load_real(subdirs[0] / SUMMARY))))
    assert isinstance(sd["metadata"]["number_summary"]["num_moving_objects_each_type"], collections.defaultdict)
    assert isinstance(sd["metadata"]["number_summary"]["object_types"], set)

    got = _all(db)
    assert_rows_match(got, waymo)
    assert got.scene.nunique() == len(waymo)
    # one frame per 10 Hz step, for every step of every scenario (the ego is valid throughout)
    assert len(got[got.is_ego]) == sum(int(sd["length"]) for sd in waymo)


def test_merged_database_follows_its_relative_mappings(tmp_path, capsys):
    nus = tmp_path / "nuscenes"
    write_single_worker(real_scenarios(), nus, "nuscenes", "v1.0-mini")
    waymo = [as_waymo(sd) for sd in real_scenarios()]
    write_to_directory(waymo, tmp_path / "waymo", "waymo", "v1.2", num_workers=2)
    merged = tmp_path / "merged"
    _, mapping = merge_database(merged, nus, tmp_path / "waymo")
    assert set(mapping.values()) == {"../nuscenes", "../waymo/waymo_0", "../waymo/waymo_1"}

    got = _all(merged)
    assert_rows_match(got, real_scenarios() + waymo)
    # the same rows as the source databases extracted one by one, in the summary's order
    one_by_one = pd.concat([_all(nus), _all(tmp_path / "waymo")], ignore_index=True)
    pd.testing.assert_frame_equal(got, one_by_one)

    out = tmp_path / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(merged), "--categories", "all", "--out", str(out))
    assert res.returncode == 0, res.stderr
    assert len(read_frames(out)) == len(one_by_one[one_by_one.x.pow(2) + one_by_one.y.pow(2) <= 2500])


def test_a_merge_of_merged_databases_still_points_at_the_files(tmp_path):
    nus = tmp_path / "a" / "nuscenes"
    write_single_worker(real_scenarios(), nus, "nuscenes", "v1.0-mini")
    inner = tmp_path / "a" / "inner"
    merge_database(inner, nus)
    outer = tmp_path / "b" / "outer"
    _, mapping = merge_database(outer, inner)
    assert set(mapping.values()) == {"../../a/nuscenes"}
    pd.testing.assert_frame_equal(_all(outer), _all(nus))


def _merged(tmp_path):
    nus = tmp_path / "nuscenes"
    write_single_worker(real_scenarios(), nus, "nuscenes", "v1.0-mini")
    merged = tmp_path / "merged"
    merge_database(merged, nus)
    return nus, merged


def test_a_mapping_to_a_missing_file_names_the_entry_and_the_path(tmp_path, capsys):
    nus, merged = _merged(tmp_path)
    name = sorted(load_real(merged / SUMMARY))[1]
    (nus / name).unlink()
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(merged), "--out", str(out))
    assert_refused(res, out, f"{MAPPING} entry {name!r} maps to {merged / '..' / 'nuscenes' / name}, which does not exist")


def test_a_mapping_into_a_symlink_loop_is_refused_not_followed(tmp_path, capsys):
    nus, merged = _merged(tmp_path)
    shutil.rmtree(nus)
    (tmp_path / "loop").symlink_to(tmp_path / "nuscenes")
    nus.symlink_to(tmp_path / "loop")
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "scenarionet", str(merged), "--out", str(out)), out, "symlink loop")


@pytest.mark.parametrize("index", [MAPPING, SUMMARY])
def test_entries_must_be_scenario_file_names(tmp_path, capsys, index):
    nus, merged = _merged(tmp_path)
    if index == SUMMARY:  # the summary is the index only without a mapping (scenarios beside it)
        (nus / MAPPING).unlink()
        merged = nus
    entries = load_real(merged / index)
    entries["../escape.pkl"] = "" if index == MAPPING else {}
    (merged / index).write_bytes(pickle.dumps(entries))
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "scenarionet", str(merged), "--out", str(out)), out,
                   f"{index} entry '../escape.pkl' is not the file name of a scenario")


def test_the_mapping_is_the_index_and_the_summary_is_not_loaded(tmp_path):
    # the summary holds every scenario's metadata (gigabytes for a full Waymo conversion): with a mapping, it is
    # never read, as a summary that is not even a pickle shows
    nus, merged = _merged(tmp_path)
    (merged / SUMMARY).write_bytes(b"not read")
    pd.testing.assert_frame_equal(_all(merged), _all(nus))


def test_a_database_without_mapping_file_has_its_scenarios_beside_the_summary(tmp_path):
    nus = tmp_path / "nuscenes"
    write_single_worker(real_scenarios(), nus, "nuscenes", "v1.0-mini")
    (nus / MAPPING).unlink()  # metadrive's read_dataset_summary then maps every scenario to ""
    assert_rows_match(_all(nus), real_scenarios())


# --- defaultdicts whose factory is not one of the closed set ------------------------------------------------------

class _RunsCode:
    """A callable (so defaultdict takes it as a factory) that pickles as os.system("touch marker")."""

    def __init__(self, marker):
        self.marker = marker

    def __call__(self):
        return 0

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def _handmade_build(factory_global: bytes) -> bytes:
    """defaultdict(int) followed by BUILD (None, {"default_factory": <global>}): the factory set after the
    constructor checked it. Protocol 2 opcodes, written by hand since pickle.dumps never emits this."""
    return (b"\x80\x02" + b"ccollections\ndefaultdict\n" + b"c__builtin__\nlong\n" + b"\x85R"
            + b"N}X\x0f\x00\x00\x00default_factory" + factory_global + b"s\x86b.")


@pytest.mark.parametrize("where", ["summary", "mapping", "scenario"])
@pytest.mark.parametrize("factory, refused", [
    (os.system, "posix.system"),
    (eval, "builtins.eval"),
    ("nested-reduce", "posix.system"),
    (collections.OrderedDict, "collections.defaultdict with default factory collections.OrderedDict"),
    ("build", "collections.defaultdict with state set after construction (BUILD)"),
])
def test_evil_defaultdict_factories_are_refused_and_never_run(tmp_path, capsys, where, factory, refused):
    marker = tmp_path / "pwned"
    nus = tmp_path / "nuscenes"
    write_single_worker(real_scenarios(), nus, "nuscenes", "v1.0-mini")
    if where == "summary":
        (nus / MAPPING).unlink()  # so that the summary is what lists the scenarios
    elif where == "mapping":  # the mapping itself a defaultdict(str), its evil twin beside it
        data = load_real(nus / MAPPING)
        (nus / MAPPING).write_bytes(pickle.dumps(collections.defaultdict(str, data), protocol=4))
        assert len(_all(nus)) > 0
    target = nus / {"summary": SUMMARY, "mapping": MAPPING, "scenario": sorted(load_real(nus / SUMMARY))[0]}[where]
    data = load_real(target)
    if where == "mapping":  # the evil defaultdict is one more (ignored) value of the mapping
        data["extra"] = {"number_summary": {}}
    meta = next(iter(data.values())) if where == "summary" else data["extra"] if where == "mapping" else data["metadata"]
    if factory == "build":
        evil = pickle.loads(_handmade_build(b"ccollections\nOrderedDict\n"))  # what the plain unpickler builds
        assert evil.default_factory is collections.OrderedDict
        # splice the hand-made defaultdict + BUILD in place of the real counts
        meta["number_summary"]["num_moving_objects_each_type"] = "SPLICE"
        blob = pickle.dumps(data, protocol=2)
        mark = b"X\x06\x00\x00\x00SPLICE"
        assert blob.count(mark) == 1
        blob = blob.replace(mark, _handmade_build(b"ccollections\nOrderedDict\n")[2:-1])
    else:
        made = _RunsCode(marker) if factory == "nested-reduce" else factory
        meta["number_summary"]["num_moving_objects_each_type"] = collections.defaultdict(made)
        blob = pickle.dumps(data, protocol=4)
    target.write_bytes(blob)
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(nus), "--out", str(out))
    assert_refused(res, out, f"refused to unpickle: it references {refused}")
    assert "which is not data a ScenarioNet file may hold" in res.stderr and target.name in res.stderr
    assert not marker.exists()


@pytest.mark.parametrize("protocol", [2, 3, 4, 5])
def test_defaultdicts_of_the_closed_set_of_factories_load_in_every_protocol(tmp_path, protocol):
    path = tmp_path / "d.pkl"
    for factory in (int, float, str, list, dict, set, tuple, None):
        d = collections.defaultdict(factory, {"VEHICLE": factory() if factory else 3})
        path.write_bytes(pickle.dumps({"counts": d}, protocol=protocol))
        back = load_pickle(path)["counts"]
        assert isinstance(back, collections.defaultdict) and back.default_factory is factory and back == d
        # it stays a plain defaultdict when pickled again
        assert type(pickle.loads(pickle.dumps(back))) is collections.defaultdict


def test_factory_types_do_not_become_callables_of_a_pickle(tmp_path):
    # int / str / ... resolve for a defaultdict's sake only: calling one from a pickle is not possible
    path = tmp_path / "call.pkl"
    path.write_bytes(b"\x80\x02c__builtin__\nlong\nX\x02\x00\x00\x0042\x85R.")
    assert pickle.loads(path.read_bytes()) == 42
    with pytest.raises(FramesError, match="not a readable pickle"):
        load_pickle(path)
