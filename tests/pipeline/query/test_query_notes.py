"""`r2s query` says when its pattern names a type the frames never hold (issue 26 item 2, query half): one note on
stderr, not an error (exit 0, the empty answer is right), with how the frames were extracted when `make corpus`
recorded it beside them (FRAMES.args). Real processes on frames cut from the shipped keyframes."""

from __future__ import annotations

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pipeline.query.notes import missing_types
from synth.patterns.one_frame import VEHICLE, matched_types, parse_pattern
from synth.scene import ENTITY_TYPES
from tests.support import ROOT
from tests.support.bounded import run_bounded

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
ANY = "on Range(-100, 100) @ Range(-100, 100) relative to ego, facing Range(0, 360) deg"


def _frames_of(tmp_path, types: set[str]):
    t = pq.read_table(KEYFRAMES)
    keep = pc.or_(t.column("is_ego"), pc.is_in(t.column("type"), value_set=pa.array(sorted(types))))
    out = tmp_path / "frames.parquet"
    pq.write_table(t.filter(keep), out)
    return out


def _query(frames, pattern: str, tmp_path):
    (tmp_path / "p.dsl").write_text(pattern)
    return run_bounded("query", str(frames), str(tmp_path / "p.dsl"), "--out", str(tmp_path / "m.parquet"), timeout=120)


def test_a_type_the_frames_never_hold_is_noted_with_how_they_were_extracted(tmp_path):
    """Before: "0 matched" without a word."""
    frames = _frames_of(tmp_path, {"Car", "Truck", "Bus"})
    result = _query(frames, f"ped = new Pedestrian {ANY}\n", tmp_path)
    assert result.returncode == 0, result.stderr
    (note,) = result.stderr.strip().splitlines()
    assert "names Pedestrian, which the frames never hold (their types: Bus, Car, Truck)" in note
    assert "not recorded beside them" in note
    assert "0 matched" in result.stdout
    (tmp_path / "frames.parquet.args").write_text("scenarionet /data/db --categories vehicles (r2sgen 1.0)\n")
    result = _query(frames, f"ped = new Pedestrian {ANY}\nthen\nped = new Pedestrian {ANY}\n", tmp_path)
    assert result.returncode == 0, result.stderr
    (note,) = result.stderr.strip().splitlines()
    assert "extracted from `scenarionet /data/db --categories vehicles (r2sgen 1.0)`" in note


@pytest.mark.parametrize("pattern", [f"ped = new Pedestrian {ANY}\n", f"x = new Object {ANY}\n",
                                     f"car = new Vehicle {ANY}\n"])
def test_no_note_when_every_type_occurs(pattern, tmp_path):
    result = _query(KEYFRAMES, pattern, tmp_path)
    assert result.returncode == 0 and result.stderr.strip() == "", result.stderr


def test_vehicle_without_any_vehicle_class_is_noted(tmp_path):
    frames = _frames_of(tmp_path, {"Pedestrian"})
    result = _query(frames, f"car = new Vehicle {ANY}\nped = new Pedestrian {ANY}\n", tmp_path)
    assert result.returncode == 0
    assert "names Vehicle, which the frames never hold (their types: Pedestrian)" in result.stderr


@settings(max_examples=200, deadline=None)
@given(st.lists(st.sampled_from(sorted(ENTITY_TYPES) + [VEHICLE, "Object"]), min_size=1, max_size=4),
       st.sets(st.sampled_from(sorted(ENTITY_TYPES))))
def test_missing_types_is_the_types_no_entity_can_bind(types, present):
    """Against the definition, one entity type at a time: a pattern type is missing iff no present type matches
    (`Object` never is: it names no type a category filter could have left out)."""
    pattern = parse_pattern("".join(f"n{k} = new {t} {ANY}\n" for k, t in enumerate(types)))
    want = [t for t in dict.fromkeys(types)
            if t != "Object" and not any(e in matched_types(t) for e in present)]
    assert missing_types([pattern], present) == want
