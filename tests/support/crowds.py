"""Dense crowd scenes for the synthesis benchmark and tests: the frames that make the search work hardest.

Issue 18: held-out nuScenes frames with 50-60 pedestrians standing and walking in many directions, among
barriers and cones, take A* thousands of nodes, where the shipped keyframes never need more than 24. Those
frames cannot be shipped, so this module lays out frames like them, deterministically from a seed, on the
sidewalks and crosswalks of a crossing ahead of ego:

- pedestrians in groups: pairs in conversation (facing each other across the sidewalk), standing clusters
  (people facing into the group or anywhere), walking groups (a shared heading, side by side and in rows),
  queues (one behind the other) and crossing streams (both ways along a crosswalk), in every direction;
- barriers in rows (end to end, each facing across the row, as nuScenes annotates them) and cones in lines
  (nuScenes' cone headings carry no meaning: any direction);
- a few cars in the lanes.

What makes such a frame hard is its conversations: two people facing each other are each other's only
`facing toward` witness when nobody else stands on their line of sight, so each such pair (a source of the
heading witness graph that ego does not feed) costs one more than the sum of floors, and A* with the
floor-sum bound opens every subset of those pairs before it can prove the optimum. A few frames in every
thirty of `crowd_scenes` take the search more than a thousand nodes (bench/results/synth.md has the counts).

Sizes are real: (length, width) pairs drawn from nuScenes-mini annotations of the type (the quartiles of the
242 shipped keyframes, data/nuscenes-mini-keyframes, per type). Positions keep boxes from overlapping (people
keep a personal distance, barriers touch end to end at most), everything within 50 m of ego, as the extractors
keep it. Ids are type and rank by distance to ego over all types (`pedestrian1` nearest), as the extractors
numbered a frame before ids became stable across a scene; the crowd pins keep them.

Not product code: test and benchmark data (tests/synth/test_crowds.py, bench/bench_synth.py).
"""

from __future__ import annotations

import math
import random

from synth.scene import Scene, scene_from_dict
from synth.variants.overlap import boxes_overlap

# (length, width) in metres: min, quartiles and max of each type over the 242 shipped nuScenes-mini keyframes
# (`df.groupby('type')[['length', 'width']].quantile([0, .25, .5, .75, 1])` on frames.parquet); a size is drawn
# by picking a quantile position and interpolating, length and width at the same position.
REAL_SIZES: dict[str, tuple[tuple[float, float], ...]] = {
    "Pedestrian": ((0.331, 0.345), (0.695, 0.621), (0.780, 0.694), (0.891, 0.759), (1.235, 1.019)),
    "TrafficCone": ((0.305, 0.214), (0.395, 0.392), (0.451, 0.439), (0.484, 0.488), (0.644, 1.214)),
    "Barrier": ((0.395, 1.730), (0.535, 1.977), (0.647, 2.050), (0.696, 2.884), (0.764, 3.586)),
    "Car": ((3.484, 1.482), (4.364, 1.834), (4.573, 1.963), (4.782, 2.034), (5.837, 2.732)),
}
RADIUS = 50.0  # metres: the extractors' default --radius
WALK_JITTER = 6.0  # degrees: how far a walker's heading strays from the group's (two sigmas)
# How often a group of people is of each kind (weights).
GROUPS = {"talking": 0.6, "standing": 0.1, "walking": 0.15, "queue": 0.05, "crossing": 0.1}
TALK_SPREAD = 15.0  # degrees (sigma): how far a conversation's axis turns from across the sidewalk


def real_size(rng: random.Random, kind: str) -> tuple[float, float]:
    """A (length, width) pair from the type's real quantiles (the middle half twice as often as the tails)."""
    q = REAL_SIZES[kind]
    u = rng.uniform(0.25, 0.75) if rng.random() < 0.5 else rng.random()
    pos = u * (len(q) - 1)
    i = min(int(pos), len(q) - 2)
    f = pos - i
    return tuple(round(q[i][k] + f * (q[i + 1][k] - q[i][k]), 3) for k in (0, 1))


class _Layout:
    """Boxes placed so far; a new one is kept only if it overlaps none (touching rows aside) and lies in range."""

    def __init__(self) -> None:
        self.boxes: list[tuple[str, float, float, float, float, float]] = []  # type, x, y, heading, length, width

    def place(self, kind: str, x: float, y: float, heading: float, size: tuple[float, float], gap: float = 0.0) -> bool:
        if math.hypot(x, y) > RADIUS - 0.5 or math.hypot(x, y) < 3.0:
            return False
        length, width = size[0] + gap, size[1] + gap
        for _, bx, by, bh, bl, bw in self.boxes:
            if abs(bx - x) > 8.0 or abs(by - y) > 8.0:
                continue
            if bool(boxes_overlap(x, y, heading, length, width, bx, by, bh, bl, bw)):
                return False
        self.boxes.append((kind, x, y, heading % 360.0, size[0], size[1]))
        return True


def _forward(heading: float) -> tuple[float, float]:
    t = math.radians(heading)
    return (-math.sin(t), math.cos(t))


def _standing_group(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int) -> None:
    """People around a centre, most facing into the group (talking), some anywhere."""
    placed, tries = 0, 0
    while placed < n and tries < 60 * n:
        tries += 1
        a, r = rng.uniform(0, 360), rng.uniform(0.6, 0.6 + 0.35 * n)
        fx, fy = _forward(a)
        x, y = cx + r * fx, cy + r * fy
        heading = (a + 180.0 + rng.gauss(0, 12)) if rng.random() < 0.7 else rng.uniform(0, 360)
        placed += lay.place("Pedestrian", x, y, heading, real_size(rng, "Pedestrian"), gap=0.15)


def _walking_group(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int, heading: float) -> None:
    """A group walking one way: side by side in rows of up to three, rows one behind the other."""
    fx, fy = _forward(heading)
    rx, ry = fy, -fx  # the walkers' right
    for i in range(n):
        row, col = divmod(i, 3)
        side = (col - 1) * rng.uniform(0.75, 1.0)
        back = -row * rng.uniform(1.0, 1.5)
        x = cx + side * rx + back * fx + rng.gauss(0, 0.12)
        y = cy + side * ry + back * fy + rng.gauss(0, 0.12)
        lay.place("Pedestrian", x, y, heading + rng.gauss(0, WALK_JITTER / 2), real_size(rng, "Pedestrian"), gap=0.1)


def _talking(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int, heading: float) -> None:
    """People in pairs, each pair facing each other at arm's length (a conversation)."""
    for i in range(0, n, 2):
        a = heading + (i // 2) * 180.0
        fx, fy = _forward(a)
        d = rng.uniform(0.9, 1.6)
        x0, y0 = cx + (i // 2) * 2.2 * fy, cy - (i // 2) * 2.2 * fx
        lay.place("Pedestrian", x0, y0, a + rng.gauss(0, 2), real_size(rng, "Pedestrian"), gap=0.1)
        if i + 1 < n:
            lay.place("Pedestrian", x0 + d * fx, y0 + d * fy, a + 180 + rng.gauss(0, 2), real_size(rng, "Pedestrian"), gap=0.1)


def _queue(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int, heading: float) -> None:
    """People one behind the other, facing the head of the queue."""
    fx, fy = _forward(heading)
    for i in range(n):
        d = -i * rng.uniform(0.8, 1.2)
        x, y = cx + d * fx + rng.gauss(0, 0.1), cy + d * fy + rng.gauss(0, 0.1)
        lay.place("Pedestrian", x, y, heading + rng.gauss(0, 4), real_size(rng, "Pedestrian"), gap=0.1)


def _crossing(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int, heading: float) -> None:
    """Two streams on one crosswalk, opposite ways, spread along it."""
    fx, fy = _forward(heading)
    rx, ry = fy, -fx
    for i in range(n):
        way = heading if i % 2 == 0 else heading + 180.0
        along = rng.uniform(-5.0, 5.0)
        across = rng.uniform(-1.5, 1.5)
        x, y = cx + along * fx + across * rx, cy + along * fy + across * ry
        lay.place("Pedestrian", x, y, way + rng.gauss(0, WALK_JITTER / 2), real_size(rng, "Pedestrian"), gap=0.1)


def _barrier_row(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int, direction: float) -> None:
    """Barriers end to end along `direction`, each facing across the row (nuScenes barriers: width along the row)."""
    fx, fy = _forward(direction)
    size = real_size(rng, "Barrier")  # one model per row, as on a site
    for i in range(n):
        d = i * (size[1] + rng.uniform(0.02, 0.3))
        lay.place("Barrier", cx + d * fx, cy + d * fy, direction + 90.0 + rng.gauss(0, 1.5), size)


def _cone_line(rng: random.Random, lay: _Layout, cx: float, cy: float, n: int, direction: float) -> None:
    """Cones every few metres along a lane edge; a cone's annotated heading means nothing, so any."""
    fx, fy = _forward(direction)
    spacing = rng.uniform(1.5, 4.0)
    for i in range(n):
        d = i * spacing + rng.gauss(0, 0.1)
        lay.place("TrafficCone", cx + d * fx, cy + d * fy, rng.uniform(0, 360), real_size(rng, "TrafficCone"))


def _street(rng: random.Random) -> list[tuple[float, float, float, float]]:
    """The walkable paths of a crossing ahead of ego: (x, y, heading, length) of each path's start.

    A main road along ego's heading (+y) with a sidewalk on each side, a cross street ahead with its own two
    sidewalks, and a crosswalk over each road: people walk along these, both ways, and stand at the corners.
    """
    half = rng.uniform(5.0, 7.5)  # half the main road's width
    cross = rng.uniform(14.0, 28.0)  # how far ahead the cross street runs
    chalf = rng.uniform(4.5, 7.0)
    walk = rng.uniform(2.5, 4.0)  # sidewalk width
    paths = []
    for side in (-1.0, 1.0):
        x = side * (half + walk / 2)
        paths.append((x, -40.0, 0.0, 85.0))  # main-road sidewalks, along +y
        y = cross + side * (chalf + walk / 2)
        paths.append((-45.0, y, 270.0, 90.0))  # cross-street sidewalks, along +x
    paths.append((-half, cross - chalf - walk, 270.0, 2 * half))  # crosswalk over the main road
    paths.append((half + walk / 2, cross - chalf, 0.0, 2 * chalf))  # crosswalk over the cross street
    return paths


def crowd_scene_dict(seed: int, pedestrians: int = 55, barriers: int = 10, cones: int = 8, cars: int = 4) -> dict:
    """One crowd frame as scene JSON (ego at the origin heading +y, as every extracted frame)."""
    rng = random.Random(seed)
    lay = _Layout()
    paths = _street(rng)

    def on_path() -> tuple[float, float, float]:
        x0, y0, h, length = rng.choice(paths)
        fx, fy = _forward(h)
        d, off = rng.uniform(0, length), rng.gauss(0, 0.8)
        return x0 + d * fx + off * fy, y0 + d * fy - off * fx, h

    def spot() -> tuple[float, float]:
        return on_path()[:2]

    def count(kind: str) -> int:
        return sum(b[0] == kind for b in lay.boxes)

    tries = 0
    while count("Pedestrian") < pedestrians and tries < 400:
        tries += 1
        size = min(pedestrians - count("Pedestrian"), rng.choice((1, 1, 2, 2, 3, 4, 5, 6)))
        cx, cy, h = on_path()
        way = h if rng.random() < 0.5 else h + 180.0
        style = rng.choices(tuple(GROUPS), weights=tuple(GROUPS.values()))[0]
        if style == "talking":
            _talking(rng, lay, cx, cy, size, h + 90.0 + rng.gauss(0, TALK_SPREAD))
        elif style == "standing":
            _standing_group(rng, lay, cx, cy, size)
        elif style == "walking":
            _walking_group(rng, lay, cx, cy, size, way)
        elif style == "queue":
            _queue(rng, lay, cx, cy, size, way)
        else:
            _crossing(rng, lay, cx, cy, size, h)
    while count("Pedestrian") > pedestrians:
        last = max(i for i, b in enumerate(lay.boxes) if b[0] == "Pedestrian")
        del lay.boxes[last]
    _fill(rng, lay, "Barrier", barriers, spot, _barrier_row, (3, 8))
    _fill(rng, lay, "TrafficCone", cones, spot, _cone_line, (2, 6))
    placed, tries = 0, 0
    while placed < cars and tries < 200:
        tries += 1
        lane = rng.choice((-4.0, -1.75, 1.75, 4.0))
        heading = 0.0 if lane > 0 else 180.0
        ok = lay.place("Car", lane + rng.gauss(0, 0.2), rng.uniform(-40, 45), heading + rng.gauss(0, 2),
                       real_size(rng, "Car"), gap=0.5)
        placed += ok
    return _as_scene_dict(f"crowd/{seed}", lay.boxes)


def _fill(rng, lay: _Layout, kind: str, total: int, spot, layout, run: tuple[int, int]) -> None:
    tries = 0
    while sum(b[0] == kind for b in lay.boxes) < total and tries < 100:
        tries += 1
        left = total - sum(b[0] == kind for b in lay.boxes)
        x, y = spot()
        layout(rng, lay, x, y, min(left, rng.randint(*run)), rng.uniform(0, 360))


def _as_scene_dict(frame_id: str, boxes) -> dict:
    ranked = sorted(boxes, key=lambda b: (math.hypot(b[1], b[2]), b[1], b[2]))
    entities = [{"id": "ego", "type": "Car", "x": 0.0, "y": 0.0, "heading": 0.0, "length": 4.08, "width": 1.73}]
    for rank, (kind, x, y, heading, length, width) in enumerate(ranked, start=1):
        entities.append({"id": f"{kind.lower()}{rank}", "type": kind, "x": x, "y": y, "heading": heading,
                         "length": length, "width": width})
    return {"frame_id": frame_id, "entities": entities}


def crowd_scene(seed: int, **sizes: int) -> Scene:
    return scene_from_dict(crowd_scene_dict(seed, **sizes))


def crowd_scenes(count: int, first_seed: int = 0) -> list[Scene]:
    """The benchmark's crowd frames: seeds first_seed.., 50-60 pedestrians each with barriers, cones and cars."""
    out = []
    for seed in range(first_seed, first_seed + count):
        rng = random.Random(10_000 + seed)  # the frame's head-counts, apart from its layout's stream
        out.append(crowd_scene(seed, pedestrians=rng.randint(50, 60), barriers=rng.randint(3, 8),
                               cones=rng.randint(2, 6), cars=rng.randint(1, 4)))
    return out
