"""`r2s render`: the bird's-eye view's geometry, the images it writes, and its one-line errors."""

from __future__ import annotations

import math
import random

import pytest

from pipeline.variants.render import Footprint, ego_frame, references
from synth.dsl import parse_program
from synth.scene import scene_from_dict
from synth.synthesize import synthesize
from tests.support import ROOT, assert_one_line_error, run_r2s

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def test_ego_frame_puts_ego_at_the_origin_facing_up():
    # ego at (10, 5) facing 90 deg (-x); car1 10 m ahead of it, facing the same way; ped1 4 m to its right.
    scene = scene_from_dict({"frame_id": "f", "entities": [
        {"id": "ego", "type": "Car", "x": 10, "y": 5, "heading": 90},
        {"id": "car1", "type": "Car", "x": 0, "y": 5, "heading": 90},
        {"id": "ped1", "type": "Pedestrian", "x": 10, "y": 9, "heading": 0}]})
    boxes = ego_frame(scene)
    ego, car, ped = boxes["ego"], boxes["car1"], boxes["ped1"]
    assert (ego.x, ego.y, ego.heading) == (0, 0, 0)
    assert car.x == pytest.approx(0, abs=1e-9) and car.y == pytest.approx(10) and car.heading == 0
    assert ped.x == pytest.approx(4) and ped.y == pytest.approx(0, abs=1e-9) and ped.heading == 270


def test_box_corners_follow_the_heading():
    b = Footprint("car1", "Car", 1.0, 2.0, 90.0, 4.0, 2.0)  # facing -x: length along x, width along y
    xs = sorted(round(c[0], 9) for c in b.corners())
    ys = sorted(round(c[1], 9) for c in b.corners())
    assert xs == [-1, -1, 3, 3] and ys == [1, 1, 3, 3]
    fx, fy = b.front()
    assert (round(fx, 9), round(fy, 9)) == (-1, 2)
    assert math.isclose(abs(_area(b.corners())), 8.0)


def _area(pts):
    return sum(x0 * y1 - x1 * y0 for (x0, y0), (x1, y1) in zip(pts, pts[1:] + pts[:1])) / 2


def test_references_name_each_relation_kind():
    program = parse_program(
        "car1 = new Car ahead of ego by Range(5, 10), facing toward ego\n"
        "car2 = new Car on Range(1, 6) @ Range(0, 5) relative to car1, facing Range(0, 5) deg relative to ego\n"
        "car3 = new Car on Range(1, 6) @ Range(0, 5), facing Range(0, 5) deg\n")
    arrows, marks = references(program)
    assert [(r.ref, r.entity, r.kind) for r in arrows] == [
        ("ego", "car1", "sector"), ("ego", "car1", "facing"),
        ("car1", "car2", "relative_xy"), ("ego", "car2", "relative_heading")]
    assert [(m.entity, m.kind) for m in marks] == [("car3", "absolute_position"), ("car3", "absolute_heading")]


@pytest.fixture(scope="module")
def inputs(real_frames, tmp_path_factory):
    d = tmp_path_factory.mktemp("render")
    scene = next(s for s in real_frames if s.frame_id == "scene-0757/0")  # all categories, 11 entities
    (d / "scene.json").write_text(scene.to_json())
    (d / "p.dsl").write_text(str(synthesize(scene).program))
    return d


def _png_size(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    return width, height


def test_render_writes_a_png(inputs, tmp_path):
    out = tmp_path / "bev.png"
    proc = run_r2s("render", str(inputs / "scene.json"), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    w, h = _png_size(out)
    assert w > 600 and h > 400
    import matplotlib.image

    pixels = matplotlib.image.imread(out)
    assert pixels.std() > 0.05  # something is drawn, not a blank canvas
    assert not list(tmp_path.glob(".*.tmp"))


def test_render_with_program_and_samples_is_reproducible(inputs, tmp_path):
    pytest.importorskip("scenic", reason="scenic (3.1.1) is not importable here: --samples needs the compiler")
    plain, a, b = tmp_path / "plain.png", tmp_path / "a.png", tmp_path / "b.png"
    base = ("render", str(inputs / "scene.json"), "--program", str(inputs / "p.dsl"))
    assert run_r2s(*base, "--out", str(plain)).returncode == 0
    for out in (a, b):
        proc = run_r2s(*base, "--samples", "6", "--seed", "3", "--allow-collisions", "--out", str(out))
        assert proc.returncode == 0, proc.stderr
    _png_size(a)
    assert a.read_bytes() == b.read_bytes()  # same seed, same picture
    assert a.read_bytes() != plain.read_bytes()  # the variants are drawn


def test_render_svg(inputs, tmp_path):
    out = tmp_path / "bev.svg"
    assert run_r2s("render", str(inputs / "scene.json"), "--program", str(inputs / "p.dsl"), "--out", str(out)).returncode == 0
    assert out.read_text().lstrip().startswith("<?xml")


@pytest.mark.parametrize("case, message", [
    ("missing scene", "does not exist"),
    ("bad scene", "not valid JSON"),
    ("bad program", "line 1"),
    ("foreign program", "not an entity"),
    ("samples without program", "--samples needs --program"),
    ("bad suffix", "must end in"),
    ("negative samples", "--samples"),
])
def test_bad_input_is_one_line_exit_2_and_nothing_written(inputs, tmp_path, case, message):
    (tmp_path / "bad.json").write_text("{ nope")
    (tmp_path / "bad.dsl").write_text("car1 = new Car sideways of ego\n")
    (tmp_path / "foreign.dsl").write_text("ghost1 = new Car ahead of ego by Range(1, 6), facing toward ego\n")
    scene, program, out = str(inputs / "scene.json"), str(inputs / "p.dsl"), tmp_path / "bev.png"
    args = {
        "missing scene": (str(tmp_path / "nope.json"),),
        "bad scene": (str(tmp_path / "bad.json"),),
        "bad program": (scene, "--program", str(tmp_path / "bad.dsl")),
        "foreign program": (scene, "--program", str(tmp_path / "foreign.dsl")),
        "samples without program": (scene, "--samples", "3"),
        "bad suffix": (scene, "--out", str(tmp_path / "bev.txt")),
        "negative samples": (scene, "--program", program, "--samples", "-2"),
    }[case]
    if "--out" not in args:
        args = (*args, "--out", str(out))
    proc = run_r2s("render", *args)
    assert_one_line_error(proc, 2, contains=message)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.dsl", "bad.json", "foreign.dsl"]


def test_motion_references_are_drawn(tmp_path):
    from pipeline.variants.render import View, draw, save
    from synth.scene import scene_from_dict

    program = parse_program(
        "car1 = new Car ahead of ego by Range(5, 10), facing toward ego, moving like ego\n"
        "car2 = new Car ahead of car1 by Range(0, 5), facing Range(0, 5) deg relative to ego, stationary\n"
        "car3 = new Car on Range(1, 6) @ Range(0, 5), facing Range(0, 5) deg, moving Range(2, 4) m/s relative to car1\n"
        "car4 = new Car on Range(1, 6) @ Range(5, 10), facing Range(0, 5) deg, moving Range(0, 2) m/s\n")
    arrows, marks = references(program)
    motion = [(r.ref, r.entity, r.kind) for r in arrows if r.kind in ("moving_like", "relative_speed")]
    assert motion == [("ego", "car1", "moving_like"), ("car1", "car3", "relative_speed")]
    assert [(m.entity, m.kind) for m in marks if m.kind in ("stationary", "absolute_speed")] == [
        ("car2", "stationary"), ("car4", "absolute_speed")]
    scene = scene_from_dict({"frame_id": "m", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0, "speed": 5},
        {"id": "car1", "type": "Car", "x": 0, "y": 8, "heading": 180, "speed": 5.5},
        {"id": "car2", "type": "Car", "x": 0, "y": 11, "heading": 2, "speed": 0},
        {"id": "car3", "type": "Car", "x": 3, "y": 3, "heading": 2, "speed": 8},
        {"id": "car4", "type": "Car", "x": 3, "y": 8, "heading": 2, "speed": 1}]})
    fig = draw(View(scene, program))
    labels = [t.get_text() for t in fig.legends[0].get_texts()]
    assert any("moving like" in t for t in labels) and any("stationary" in t for t in labels)
    assert any("relative to\n(motion" in t for t in labels) and any("absolute speed" in t for t in labels)
    save(fig, tmp_path / "m.png")
    assert (tmp_path / "m.png").stat().st_size > 10_000


def test_the_road_is_drawn_in_ego_s_frame_under_the_boxes(tmp_path):
    from pipeline.variants.render import ROAD_STYLES, road_shapes

    # a scene whose ego stands at (10, 5) facing 90 deg (towards -x): its lane runs along x, and car1 is in it
    lane = {"id": "L", "kind": "lane", "polygon": [[-20.0, 3.0], [20.0, 3.0], [20.0, 7.0], [-20.0, 7.0]],
            "line": [[20.0, 5.0], [-20.0, 5.0]], "left": None, "right": None, "successors": [], "predecessors": [],
            "is_intersection": False}
    cross = {"id": "W", "kind": "crosswalk", "polygon": [[0.0, 0.0], [2.0, 0.0], [2.0, 10.0], [0.0, 10.0]]}
    scene = scene_from_dict({"frame_id": "f", "entities": [
        {"id": "ego", "type": "Car", "x": 10.0, "y": 5.0, "heading": 90.0},
        {"id": "car1", "type": "Car", "x": -5.0, "y": 5.5, "heading": 90.0}],
        "road": {"map_id": "m", "features": [cross, lane]}})
    shapes = road_shapes(scene)
    assert [s.style for s in shapes] == ["lane", "crosswalk"]  # areas by their drawing order
    boxes = ego_frame(scene)
    lane_shape = shapes[0]
    # in ego's frame the lane runs straight ahead of ego, 4 m wide, and car1 (15 m ahead) lies in it
    xs = [p[0] for p in lane_shape.polygon]
    assert min(xs) == pytest.approx(-2.0) and max(xs) == pytest.approx(2.0)
    assert lane_shape.line[-1][1] == pytest.approx(30.0) and abs(boxes["car1"].y - 15.0) < 1e-9
    assert min(xs) <= boxes["car1"].x <= max(xs)
    assert set(ROAD_STYLES) >= {s.style for s in shapes}
    path = tmp_path / "scene.json"
    path.write_text(scene.to_json())
    with_road, without = tmp_path / "road.png", tmp_path / "plain.png"
    assert run_r2s("render", str(path), "--out", str(with_road)).returncode == 0
    plain = scene.to_dict()
    plain.pop("road")
    path.write_text(scene_from_dict(plain).to_json())
    assert run_r2s("render", str(path), "--out", str(without)).returncode == 0
    assert with_road.read_bytes() != without.read_bytes()


def test_render_matches_outlines_and_names_exactly_the_bound_entities(tmp_path, monkeypatch):
    """`r2s render --matches M`: every entity a binding of the frame binds (read back from the matches file as pandas
    reads it) is outlined and labelled with its pattern name; no other is."""
    import pandas as pd

    import pipeline.variants.picture as picture
    from pipeline import render, scene
    from pipeline.variants.render import BOUND_EDGE, draw

    keyframes = "data/nuscenes-mini-keyframes/frames.parquet"
    proc = run_r2s("query", keyframes, "data/patterns/queue-of-three.dsl", "--all", "--out", str(tmp_path / "m.parquet"))
    assert proc.returncode == 0, proc.stderr
    matches = pd.read_parquet(tmp_path / "m.parquet")
    fid = matches.frame_id.value_counts().index[0]  # the frame with the most bindings
    want = {(name, eid) for b in matches[matches.frame_id == fid].binding for name, eid in b.items()}
    seen = []
    monkeypatch.setattr(picture, "draw", lambda view: seen.append(view) or draw(view))
    s = scene(keyframes, fid)
    render(s, tmp_path / "m.png", matches=tmp_path / "m.parquet")
    assert set(seen[0].bound) == want and len(want) > 3
    fig = draw(seen[0])
    ax = fig.axes[0]
    outlined = [p for p in ax.patches if p.get_edgecolor()[:3] == pytest.approx((0.0, 160 / 255, 135 / 255))
                and p.get_linewidth() > 2]
    assert len(outlined) == len({eid for _, eid in want})
    labels = {t.get_text() for t in ax.texts}
    for eid in {eid for _, eid in want}:
        names = [n for n, e in seen[0].bound if e == eid]
        assert f"{eid} = {', '.join(names)}" in labels
    assert BOUND_EDGE == "#00a087"
    # The CLI: the same picture from the same inputs, a frame without a match and a file that is not a matches file.
    (tmp_path / "s.json").write_text(s.to_json())
    proc = run_r2s("render", str(tmp_path / "s.json"), "--matches", str(tmp_path / "m.parquet"),
                   "--out", str(tmp_path / "cli.png"))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "cli.png").read_bytes() == (tmp_path / "m.png").read_bytes()
    other = next(f for f in sorted(set(pd.read_parquet(keyframes).frame_id)) if f not in set(matches.frame_id))
    (tmp_path / "o.json").write_text(scene(keyframes, other).to_json())
    pd.DataFrame({"frame_id": ["x"], "n": [1]}).to_parquet(tmp_path / "not-matches.parquet")
    for scene_file, file, words in (("o.json", "m.parquet", "has no match in frame"),
                                    ("s.json", "not-matches.parquet", "is not a matches file"),
                                    ("s.json", "s.json", "not a readable Parquet file")):
        proc = run_r2s("render", str(tmp_path / scene_file), "--matches", str(tmp_path / file),
                       "--out", str(tmp_path / "bad.png"))
        assert_one_line_error(proc, contains=words)
        assert words in proc.stderr and not (tmp_path / "bad.png").exists()


# ----------------------------------------------------------------------------- pictures for people (issue 26)

def _label_rects(fig):
    """The entity labels of a drawn figure as printed (display pixels), by text."""
    from pipeline.variants.render import LABEL_GID

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    ax = fig.axes[0]
    out = {}
    for t in ax.texts:
        if t.get_gid() == LABEL_GID:
            e = t.get_window_extent(renderer)
            assert t.get_text() not in out
            out[t.get_text()] = (e.x0, e.y0, e.x1, e.y1)
    return out


def _box_rects(fig, view):
    from pipeline.variants.render import ego_frame

    to_px = fig.axes[0].transData.transform
    out = {}
    for b in ego_frame(view.scene).values():
        px = to_px(b.corners())
        out[b.id] = (px[:, 0].min(), px[:, 1].min(), px[:, 0].max(), px[:, 1].max())
    return out


def _crowd_at_ego(n: int, seed: int):
    """n pedestrians packed within 6 m of ego (a crossing in front of the car), plus cars around."""
    g = random.Random(seed)
    ents = [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}]
    for i in range(n):
        ents.append({"id": f"pedestrian{i}", "type": "Pedestrian", "x": g.uniform(-6, 6), "y": g.uniform(2.5, 8),
                     "heading": g.uniform(0, 360), "length": 0.7, "width": 0.7})
    for i in range(8):
        ents.append({"id": f"car{i}", "type": "Car", "x": g.uniform(-30, 30), "y": g.uniform(-30, 30),
                     "heading": g.uniform(0, 360)})
    return scene_from_dict({"frame_id": f"crowd/{seed}", "entities": ents})


@pytest.mark.parametrize("case", ["scene-0061/14", "scene-0103/12", "crowd"])
def test_labels_never_overlap_each_other_or_a_box(case, real_frames, tmp_path):
    """Every entity has one label, its id; after saving (the layout as printed), no two labels share a pixel and
    no label lies on a box: the densest shipped keyframe (128 entities), a 40-entity one, 30 pedestrians at ego."""
    from pipeline import scene as frame_scene
    from pipeline.variants.render import View, draw, save

    scene = (_crowd_at_ego(30, 4) if case == "crowd"
             else frame_scene(ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet", case))
    view = View(scene)
    fig = draw(view)
    save(fig, tmp_path / "x.png")
    labels = _label_rects(fig)
    assert set(labels) == {e.id for e in scene.entities}
    boxes = _box_rects(fig, view)
    from pipeline.variants.labels import overlap

    rects = sorted(labels.items())
    clashes = [(a, b) for i, (a, ra) in enumerate(rects) for b, rb in rects[i + 1:] if overlap(ra, rb) > 0]
    assert not clashes, clashes[:5]
    on_boxes = [(a, b) for a, ra in rects for b, rb in boxes.items() if overlap(ra, rb) > 0]
    assert not on_boxes, on_boxes[:5]
    frame = fig.axes[0].get_window_extent()
    assert all(frame.x0 <= r[0] and r[2] <= frame.x1 and frame.y0 <= r[1] and r[3] <= frame.y1 for r in labels.values())


def test_every_variant_box_is_in_its_entity_s_colour_and_the_legend_is_complete(real_frames):
    """Each variant box is drawn in its entity's colour, which outlines that entity's recorded box and colours its
    label; entities near each other have different colours; the legend names every family, relation kind, mark,
    road style and layer the picture shows."""
    import matplotlib.colors as mcolors

    from pipeline.variants.render import (
        FAMILIES,
        LABEL_GID,
        MARK_KINDS,
        RELATION_KINDS,
        View,
        draw,
        ego_frame,
        entity_colours,
        family_of,
        references,
    )
    from pipeline.variants.sample import SampleOptions, sample_program
    from synth.config import SynthConfig

    scene = next(s for s in real_frames if s.frame_id == "scene-0757/0")
    program = synthesize(scene).program
    variants = sample_program(program, scene, SynthConfig(), SampleOptions(n=4, seed=2)).scenes
    view = View(scene, program, variants, "")
    fig = draw(view)
    ax = fig.axes[0]
    boxes = ego_frame(scene)
    colours = entity_colours(boxes)
    assert set(colours) == {e.id for e in scene.others}
    # Two entities closer than 10 m never share a colour (20 colours, 11 entities here: none do).
    same = [(a, b) for a in colours for b in colours if a < b and colours[a] == colours[b]
            and math.hypot(boxes[a].x - boxes[b].x, boxes[a].y - boxes[b].y) < 10]
    assert not same
    variant_patches = [p for p in ax.patches if p.get_zorder() == 1]
    drawn = [b for s in variants for b in ego_frame(s).values() if b.id != "ego"]
    assert len(variant_patches) == len(drawn)
    for patch, b in zip(variant_patches, drawn):
        assert mcolors.to_hex(patch.get_facecolor()) == colours[b.id]
        assert patch.get_xy()[:4].ravel().tolist() == pytest.approx([v for c in b.corners() for v in c])
    recorded = {tuple(map(tuple, p.get_xy()[:4].round(9))): p for p in ax.patches if p.get_zorder() == 3}
    for b in boxes.values():
        if b.id != "ego":
            assert mcolors.to_hex(recorded[tuple(tuple(round(v, 9) for v in c) for c in b.corners())].get_edgecolor()) \
                == colours[b.id]
    labels = {t.get_text(): mcolors.to_hex(t.get_color()) for t in ax.texts if t.get_gid() == LABEL_GID}
    assert all(labels[i] == c for i, c in colours.items())
    legend = {t.get_text() for t in fig.legends[0].get_texts()}
    arrows, marks = references(program)
    want = {"ego"} | {family_of(e.type) for e in scene.others} | {RELATION_KINDS[r.kind].label for r in arrows} \
        | {MARK_KINDS[m.kind].label for m in marks}
    assert want <= legend, want - legend
    assert any("sampled variants" in t and "entity's" in t for t in legend)
    assert all(name in FAMILIES for name in {family_of(e.type) for e in scene.others})
