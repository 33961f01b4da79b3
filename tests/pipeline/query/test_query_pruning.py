"""The pruning of one-frame joins (pipeline.query.sql, "Pruning the joins"): the box around a name's anchor is a
necessary condition of the clauses' semantics (checked by the checker's own Clause.holds, at and beyond the
boundaries), and random scenes with random Ranges give the brute force's matches with the box and without it."""

from __future__ import annotations

import math
import random

import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from frames.dataset import FramesDataset
from frames.rows import iter_scenes, read_frames
from pipeline.query import mining, sql
from pipeline.query.mining import query_frames
from synth.config import SynthConfig
from synth.patterns.one_frame import parse_pattern
from synth.patterns.temporal import parse_query_pattern
from synth.scene import Entity, Scene
from tests.pipeline.query.test_query import KEYFRAMES, _write, brute, engine
from tests.support import ROOT

PAIR = ROOT / "data" / "patterns" / "pedestrian-beside-vehicle.dsl"
CUT_IN = ROOT / "data" / "patterns" / "cut-in-from-right.dsl"
LOG = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"

CLAUSES = ["ahead of {r} by Range({a}, {b})", "left of {r} by Range({a}, {b})", "within Range({a}, {b}) of {r}",
           "on Range({c}, {d}) @ Range({a}, {b}) relative to {r}"]


def _clause(form: str, a: float, b: float, c: float, d: float):
    text = f"r = new Car on Range(-1e3, 1e3) @ Range(-1e3, 1e3)\ne = new Car {form.format(a=a, b=b, c=c, d=d, r='r')}\n"
    pattern = parse_pattern(text)
    return pattern, next(cl for _, cl in pattern.statements[1].clauses() if cl.ref == "r")


ranges = st.tuples(st.floats(0, 50), st.floats(0, 50)).map(sorted)


@settings(max_examples=400, deadline=None)
@given(form=st.sampled_from(CLAUSES), ab=ranges, cd=ranges, rx=st.floats(-1e6, 1e6), ry=st.floats(-1e6, 1e6),
       rh=st.floats(0, 360), bearing=st.floats(0, 360), nudge=st.sampled_from([0.0, 1e-9, -1e-9, 1e-6]))
def test_every_pair_that_holds_is_within_the_box(form, ab, cd, rx, ry, rh, bearing, nudge):
    """A pair the semantics accept lies within box(reach) of its reference on each axis: entities placed on the
    Range's far boundary (and a hair either side) in a random direction, far from the origin too."""
    (a, b), (c, d) = ab, (cd[0] - 25, cd[1] - 25)
    _, clause = _clause(form, a, b, c, d)
    bound = sql.reach(clause)
    assert bound is not None
    far = math.hypot(max(abs(c), abs(d)), b) if form.startswith("on") else b
    r = Entity("r", "Car", rx, ry, rh)
    t = math.radians(bearing)
    e = Entity("e", "Car", rx + (far + nudge) * math.cos(t), ry + (far + nudge) * math.sin(t), 0.0)
    if clause.holds(e, r, SynthConfig()):
        half = sql.box(bound)
        assert abs(e.x - r.x) <= half and abs(e.y - r.y) <= half


def test_clauses_without_a_distance_have_no_reach():
    pattern = parse_pattern("r = new Car on Range(-5, 5) @ Range(-5, 5)\n"
                            "e = new Car on Range(-5, 5) @ Range(-5, 5), facing toward r\n")
    assert all(sql.reach(cl) is None for _, cl in pattern.statements[1].clauses() if cl.ref == "r")
    assert sql.anchor(pattern.statements[1]) == sql.Anchor("r")  # still paired with r, on the frame alone
    assert sql.reach(_clause(CLAUSES[0], 0, 1e300, 0, 0)[1]) is None  # beyond any two entities that are not wild


def _scenes(g: random.Random, n: int) -> list[Scene]:
    """Frames of 6 to 12 cars in a 40 m square (so Ranges of a few metres keep some pairs and drop others),
    one in eight frames with a wild car (beyond 1e6 m)."""
    scenes = []
    for i in range(n):
        ents = [Entity("ego", "Car", 0.0, 0.0, g.uniform(0, 360))]
        for j in range(g.randint(6, 12)):
            x, y = g.uniform(-20, 20), g.uniform(-20, 20)
            if g.random() < 0.02:
                x *= 1e6
            ents.append(Entity(f"car{j}", g.choice(["Car", "Truck"]), x, y, g.uniform(0, 360)))
        scenes.append(Scene(f"p/{i}", tuple(ents)))
    return scenes


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 10**6), forms=st.lists(st.sampled_from(CLAUSES), min_size=2, max_size=2),
       bounds=st.lists(st.tuples(st.floats(0, 8), st.floats(0, 8)).map(sorted), min_size=4, max_size=4))
def test_random_scenes_and_ranges_match_with_and_without_the_box(seed, forms, bounds, tmp_path_factory):
    g = random.Random(seed)
    (a1, b1), (a2, b2), (c1, d1), (c2, d2) = bounds
    text = ("a = new Vehicle on Range(-30, 30) @ Range(-30, 30), facing Range(0, 360) deg\n"
            f"b = new Vehicle {forms[0].format(r='a', a=a1, b=b1, c=c1 - 4, d=d1 - 4)}\n"
            f"c = new Vehicle {forms[1].format(r='b', a=a2, b=b2 + 2, c=c2 - 4, d=d2 - 4)}\n")
    scenes = _scenes(g, 30)
    tmp = tmp_path_factory.mktemp("p")
    path = _write(scenes, tmp / "f.parquet")
    got, _ = engine(path, text, tmp)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(sql, "reach", lambda clause: None)  # no box: every pair of the frame is a candidate
        unpruned, _ = engine(path, text, tmp)
    assert got == unpruned == brute(scenes, text)


def _split(source, folder, cuts):
    """The frames file as a dataset of files cut before the frames at `cuts` (rows and columns as they are)."""
    table = pq.read_table(source)
    ids = table.column("frame_id").to_pylist()
    starts = [i for i in range(len(ids)) if i == 0 or ids[i] != ids[i - 1]]
    bounds = [0] + [starts[c] for c in cuts] + [len(ids)]
    folder.mkdir()
    for k in range(len(bounds) - 1):
        pq.write_table(table.slice(bounds[k], bounds[k + 1] - bounds[k]), folder / f"part-{k}.parquet")
    return folder


@pytest.mark.parametrize("size", [1, 7, 100])
def test_frames_in_chunks_match_as_in_one(size, tmp_path, monkeypatch):
    """Frames as datasets of three files, queried CHUNK_FRAMES frames at a time (chunks across the files): the
    brute force's matches of a two-name pattern on the shipped keyframes, and a temporal pattern's events on the
    Argoverse 2 log as in one chunk."""
    keyframes = _split(KEYFRAMES, tmp_path / "k", [50, 51])
    log = _split(LOG, tmp_path / "log", [60, 61])
    text = PAIR.read_text()
    temporal = parse_query_pattern(CUT_IN.read_text())
    whole, _ = engine(keyframes, text, tmp_path)
    query_frames(log, temporal, tmp_path / "one.parquet", events=True, log=lambda s: None)
    monkeypatch.setattr(sql, "CHUNK_FRAMES", size)
    got, _ = engine(keyframes, text, tmp_path)
    assert got == whole == brute(list(iter_scenes(read_frames(KEYFRAMES))), text) and got
    query_frames(log, temporal, tmp_path / "chunked.parquet", events=True, log=lambda s: None)
    events = pq.read_table(tmp_path / "chunked.parquet")
    assert events.equals(pq.read_table(tmp_path / "one.parquet")) and events.num_rows


def test_the_estimate_in_chunks_is_the_estimate_of_the_whole(tmp_path):
    """Per frame, the chunks' estimates (both kinds) are the one query's: each frame is in exactly one chunk."""
    folder = _split(KEYFRAMES, tmp_path / "k", [50, 51])
    con = mining._open([p.path for p in FramesDataset.open(folder).parts], False, 1, None, str(tmp_path))
    pattern = parse_pattern(PAIR.read_text())
    chunks = sql.frame_chunks(con, False, size=7)
    for fanout in (False, True):
        whole = sorted(con.execute(sql.estimate_query(pattern, SynthConfig(), fanout, per_frame=True)).fetchall())
        parts = sorted(r for c in chunks for r in con.execute(
            sql.estimate_query(pattern, SynthConfig(), fanout, per_frame=True, chunk=c)).fetchall())
        assert parts == whole and len(whole) == 242
    con.close()
