"""Stable ids (docs/formats.md, "how ids are made"): within a scene a track keeps one entity id in every frame,
and an id names one track; ids follow the rule computed independently in tests.support.stable_ids, on every
shipped scene of every source (and /work/shared/data when present), and on random scenes (hypothesis)."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from extractors.base import ExtractOptions, FrameBuilder, RecordedObject
from extractors.categories import ALL
from extractors.nuscenes import TAXONOMY as NUSCENES
from frames.rows import read_frames
from tests.support.extract import EXCERPT, frames_of
from tests.support.stable_ids import expected_ids

ROOT = Path(__file__).resolve().parents[2]
SHARED = Path("/work/shared/data")


def assert_stable(frames: pd.DataFrame) -> None:
    others = frames[~frames.is_ego]
    assert not others.duplicated(["frame_id", "track_id"]).any()  # the rule below assumes one box per track
    assert (others.groupby(["scene", "track_id"]).entity_id.nunique() == 1).all()
    assert (others.groupby(["scene", "entity_id"]).track_id.nunique() == 1).all()
    assert (others.entity_id == expected_ids(frames)).all()
    for _, f in others.groupby("frame_id"):  # rows of a frame: by distance to ego
        d = ((f.x ** 2 + f.y ** 2) ** 0.5).tolist()
        assert d == sorted(d)


def _extracted(source: str, path: Path) -> pd.DataFrame:
    from extractors.registry import source as source_of

    return frames_of(source_of(source).extract, path, categories=ALL)


SHIPPED = [("scenarionet", EXCERPT / "scenarionet"), ("argoverse2", ROOT / "tests" / "data" / "argoverse2")]
SHARED_INPUTS = [("scenarionet", SHARED / "nuscenes-mini" / "scenarionet"),
                 ("argoverse2", SHARED / "argoverse2" / "test_data")]


@pytest.mark.parametrize("source,path", SHIPPED, ids=[s for s, _ in SHIPPED])
def test_shipped_inputs_give_one_id_per_track(source, path):
    frames = _extracted(source, path)
    assert frames.frame_id.nunique() > frames.scene.nunique()  # scenes of several frames
    assert_stable(frames)


@pytest.mark.parametrize("name", ["nuscenes-mini-keyframes", "argoverse2-log-excerpt"])
def test_shipped_frames_files_have_stable_ids(name):
    assert_stable(read_frames(ROOT / "data" / name / "frames.parquet"))


@pytest.mark.parametrize("source,path", SHARED_INPUTS, ids=[s for s, _ in SHARED_INPUTS])
def test_shared_data_gives_one_id_per_track(source, path):
    if not path.exists():
        pytest.skip(f"{path} is not on this machine (real data of /work/shared)")
    assert_stable(_extracted(source, path))


def test_a_track_keeps_its_first_id_when_it_leaves_and_comes_back():
    b = FrameBuilder("test", NUSCENES, ExtractOptions(categories=ALL, radius=50.0))
    ego = RecordedObject("ego", "vehicle.car", 0, 0, 0)
    near, far = RecordedObject("a", "vehicle.car", 0, 5, 0), RecordedObject("b", "vehicle.car", 0, 10, 0)
    f0 = b.frame("s", 0, 0, ego, [far])
    f1 = b.frame("s", 1, 1, ego, [near])  # b out of sight; a is new
    f2 = b.frame("s", 2, 2, ego, [near, far])  # b is back, nearer than nothing: still car1
    assert [r["entity_id"] for r in f0[1:]] == ["car1"]
    assert [r["entity_id"] for r in f1[1:]] == ["car2"]
    assert [(r["entity_id"], r["track_id"]) for r in f2[1:]] == [("car2", "a"), ("car1", "b")]
    f3 = b.frame("t", 0, 0, ego, [near])  # a new scene starts a new numbering
    assert [r["entity_id"] for r in f3[1:]] == ["car1"]


_box = st.tuples(st.sampled_from("abcdefg"), st.sampled_from(["vehicle.car", "human.pedestrian.adult",
                                                               "vehicle.truck"]),
                 st.integers(-30, 30), st.integers(-30, 30))


@settings(max_examples=150, deadline=None)
@given(st.lists(st.lists(st.tuples(st.sampled_from("st"), st.lists(_box, max_size=6)), min_size=1, max_size=4),
                min_size=1, max_size=3))
def test_random_scenes_follow_the_rule(scenes):
    """Random tracks that come and go (and change class: the first class names the track), ties in distance."""
    b = FrameBuilder("test", NUSCENES, ExtractOptions(categories=ALL, radius=100.0))
    ego = RecordedObject("ego", "vehicle.car", 0, 0, 0)
    rows = []
    for k, frames in enumerate(scenes):
        for i, (_, boxes) in enumerate(frames):
            unique = {t: (c, x, y) for t, c, x, y in boxes}  # one box per track in a frame
            objs = [RecordedObject(t, c, float(x), float(y), 0.0) for t, (c, x, y) in unique.items()]
            rows += b.frame(f"scene{k}", i, i, ego, objs)
    frames = pd.DataFrame(rows)
    first_type = frames[~frames.is_ego].groupby(["scene", "track_id"]).type.transform("first")
    frames.loc[~frames.is_ego, "type"] = first_type  # the rule numbers a track by its first type
    assert_stable(frames)
