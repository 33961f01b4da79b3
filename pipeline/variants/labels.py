"""Where a picture's labels go so that none overlaps another, a box or the picture's edge (r2s render).

Placement is in display pixels, after the figure's layout is fixed (the caller draws it once first): each label is
measured as matplotlib will print it, then tried beside its box (below, above, right, left, the corners), then on
rings farther out, where a leader line will tie it to its box; the first free spot wins. Labels are placed in the
order given (the caller puts the ones that matter first: ego, a match's entities, then by distance from ego), so
those sit closest to their boxes. A label that finds no free spot on any ring (a frame denser than the picture)
takes the spot that overlaps least: `Placement.overlaps` says so, and the tests hold real frames to none."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

Rect = tuple[float, float, float, float]  # x0, y0, x1, y1 in display pixels

GAP = 2.0  # pixels between a label and its box
RINGS = 14  # how far out a label may go, in steps of its own height
ANGLES = 16  # spots per ring


@dataclass(frozen=True)
class Placement:
    rect: Rect  # where the label's text sits
    leader: bool  # tied to its box by a line (it sits away from it)
    overlaps: bool  # no free spot was found


def overlap(a: Rect, b: Rect) -> float:
    """The area two rectangles share (0: apart or touching)."""
    w = min(a[2], b[2]) - max(a[0], b[0])
    h = min(a[3], b[3]) - max(a[1], b[1])
    return w * h if w > 0 and h > 0 else 0.0


def _at(cx: float, cy: float, w: float, h: float) -> Rect:
    return (cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2)


def candidates(box: Rect, w: float, h: float) -> list[tuple[Rect, bool]]:
    """The spots to try for a w x h label of a box, nearest first: (rect, needs a leader line)."""
    x0, y0, x1, y1 = box
    cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
    near = [
        (_at(cx, y0 - GAP - h / 2, w, h), False), (_at(cx, y1 + GAP + h / 2, w, h), False),
        (_at(x1 + GAP + w / 2, cy, w, h), False), (_at(x0 - GAP - w / 2, cy, w, h), False),
        (_at(x1 + GAP + w / 2, y0 - GAP - h / 2, w, h), False), (_at(x0 - GAP - w / 2, y0 - GAP - h / 2, w, h), False),
        (_at(x1 + GAP + w / 2, y1 + GAP + h / 2, w, h), False), (_at(x0 - GAP - w / 2, y1 + GAP + h / 2, w, h), False),
    ]
    far = []
    reach = max(x1 - x0, y1 - y0) / 2
    for ring in range(1, RINGS + 1):
        r = reach + GAP + ring * 1.6 * h
        for k in range(ANGLES):
            a = 2 * math.pi * (k + 0.5 * (ring % 2)) / ANGLES - math.pi / 2
            # Along the ray, far enough that the label's nearer edge clears the ring.
            far.append((_at(cx + math.cos(a) * (r + w / 2 * abs(math.cos(a))),
                            cy + math.sin(a) * (r + h / 2 * abs(math.sin(a))), w, h), True))
    return near + far


def place(sizes: Sequence[tuple[float, float]], boxes: Sequence[Rect], obstacles: Sequence[Rect],
          frame: Rect) -> list[Placement]:
    """A spot for each label i (sizes[i] = (w, h) in pixels) of boxes[i]: never over another placed label, over an
    obstacle (every box of the picture, its own included), or outside `frame` (the axes)."""
    placed: list[Rect] = []
    out = []
    for (w, h), box in zip(sizes, boxes):
        best, best_cost = None, math.inf
        for rect, leader in candidates(box, w, h):
            if rect[0] < frame[0] or rect[1] < frame[1] or rect[2] > frame[2] or rect[3] > frame[3]:
                continue
            cost = sum(overlap(rect, p) for p in placed) + sum(overlap(rect, o) for o in obstacles)
            if cost == 0.0:
                best, best_cost = (rect, leader), 0.0
                break
            if cost < best_cost:
                best, best_cost = (rect, leader), cost
        if best is None:  # nothing inside the frame: beside the box, as before
            best, best_cost = candidates(box, w, h)[0], math.inf
        placed.append(best[0])
        out.append(Placement(best[0], best[1], best_cost > 0.0))
    return out
