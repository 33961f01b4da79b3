"""The report about the data (`r2s report --frames F`): entities by type, distance and speed, and the frames worth a
look for a data user, checked against the same numbers computed by pandas from the frames file."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from pipeline.report.data import BANDS, NEAR, data_looks, data_overview, rarest_relations
from pipeline.report.stats import ProgramsDB, relation_kinds, relation_usage
from tests.support import ROOT

AV2 = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"  # with speeds
KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"  # without


@pytest.fixture(scope="module", params=["av2", "keyframes"])
def run(request, tmp_path_factory):
    from pipeline import run_frames

    d = tmp_path_factory.mktemp("data")
    rows = pd.read_parquet(AV2 if request.param == "av2" else KEYFRAMES)
    keep = sorted(set(rows.frame_id))[::max(1, rows.frame_id.nunique() // 12)][:12]
    rows[rows.frame_id.isin(keep)].to_parquet(d / "frames.parquet")
    run_frames(d / "frames.parquet", d / "programs", jobs=1, log=lambda _: None)
    return d


def _boxes(frames) -> pd.DataFrame:
    """Every non-ego box with its distance to its frame's ego, by pandas."""
    rows = pd.read_parquet(frames)
    ego = rows[rows.is_ego].set_index("frame_id")[["x", "y"]]
    boxes = rows[~rows.is_ego].join(ego, on="frame_id", rsuffix="_ego")
    boxes["dist"] = np.hypot(boxes.x - boxes.x_ego, boxes.y - boxes.y_ego)
    return boxes


def test_entities_by_type_distance_and_speed_are_the_frames(run):
    boxes = _boxes(run / "frames.parquet")
    with ProgramsDB(run / "programs") as db:
        o = data_overview(db, str(run / "frames.parquet"))
    assert (o.frames, o.boxes) == (pd.read_parquet(run / "frames.parquet").frame_id.nunique(), len(boxes))
    assert o.has_speed == ("speed" in boxes.columns)
    assert [t.type for t in o.types] == sorted(boxes.type.unique(), key=lambda t: (-(boxes.type == t).sum(), t))
    per_frame = boxes.groupby("frame_id").size()
    assert (o.per_frame_median, o.per_frame_max) == (per_frame.median(), per_frame.max())
    for t in o.types:
        b = boxes[boxes.type == t.type]
        assert (t.boxes, t.frames, t.near) == (len(b), b.frame_id.nunique(), int((b.dist < NEAR).sum()))
        assert t.distance_median == pytest.approx(b.dist.median())
        assert t.distance_p90 == pytest.approx(b.dist.quantile(0.9))
        edges = [*BANDS, math.inf]
        assert t.bands == tuple(int(((b.dist >= lo) & (b.dist < hi)).sum()) for lo, hi in zip(edges, edges[1:]))
        assert sum(t.bands) == t.boxes
        if o.has_speed:
            assert t.speed_median == pytest.approx(b.speed.median())
            assert t.stationary == int((b.speed <= 0.5).sum())
        else:
            assert t.speed_median is None and t.stationary is None


def test_frames_worth_a_look_for_a_data_user(run):
    boxes = _boxes(run / "frames.parquet")
    with ProgramsDB(run / "programs") as db:
        o = data_overview(db, str(run / "frames.parquet"))
        looks = data_looks(db, o)
        counts = relation_usage(db).counts.sum(axis=1)
    by = {}
    for look in looks:
        by.setdefault(look.reason.split(":")[0], []).append(look)
    per_frame = boxes.groupby("frame_id").size()
    most = sorted(per_frame.items(), key=lambda kv: (-kv[1], kv[0]))[:3]
    assert [(x.frame_id, x.detail) for x in by["most entities"]] == [(f, f"{n} entities") for f, n in most]
    nearest = boxes.loc[boxes.groupby("frame_id").dist.idxmin()].sort_values(["dist", "frame_id"]).head(3)
    assert [x.frame_id for x in by["nearest to ego"]] == list(nearest.frame_id)
    assert all(f"at {d:.1f} m" in x.detail for x, d in zip(by["nearest to ego"], nearest.dist))
    if o.has_speed:
        fastest = boxes.groupby("frame_id").speed.max().sort_values(ascending=False)
        assert by["fastest entity"][0].frame_id == fastest.index[0]
    rare = sorted(boxes.type.unique(), key=lambda t: ((boxes.type == t).sum(), t))[0]
    assert any(x.reason.startswith(f"rare type: {rare} ") and x.frame_id in set(boxes[boxes.type == rare].frame_id)
               for x in by["rare type"])
    # The rarest relation used, and only frames whose program says it.
    kind = min((n, k) for k, n in counts.items() if n > 0)[1]
    programs = pd.read_parquet(run / "programs").set_index("frame_id").program
    frames = [x.frame_id for x in by["rare relation"] if x.reason.startswith(f"rare relation: {kind} ")]
    assert frames and all(relation_kinds(programs[f])[kind] > 0 for f in frames)  # by the DSL's own parser
    using = sorted(f for f, text in programs.items() if text and relation_kinds(text)[kind] > 0)
    assert frames == using[:3]


def test_the_report_has_the_data_sections_and_without_frames_only_the_rare_relations(run, tmp_path):
    from pipeline.report import report

    report(run / "programs", tmp_path / "with", frames=run / "frames.parquet")
    text = (tmp_path / "with" / "report.md").read_text()
    assert "## The data" in text and "## Frames worth a look for a data user" in text and "most entities" in text
    assert f"r2s scene {run / 'frames.parquet'}" in text
    report(run / "programs", tmp_path / "without")
    text = (tmp_path / "without" / "report.md").read_text()
    assert "## The data" not in text and "## Frames worth a look for a data user" in text
    assert "most entities" not in text and "rare relation" in text
    with ProgramsDB(run / "programs") as db:
        assert rarest_relations(db)


def test_frames_that_cannot_be_read_are_said_and_the_report_is_still_written(run, tmp_path):
    """--frames also only fills in the render commands: a path that is not readable frames costs the data sections,
    which say why, not the report."""
    from pipeline.report import report

    report(run / "programs", tmp_path / "r", frames=tmp_path / "nowhere.parquet")
    text = (tmp_path / "r" / "report.md").read_text()
    assert "could not be read, so there is no report about the data" in text and "nowhere.parquet" in text
    assert "most entities" not in text and "rare relation" in text
