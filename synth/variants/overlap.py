"""Do two oriented boxes overlap? The separating-axis test, vectorised over pairs with numpy.

Boxes are closed rectangles (centre, heading, length along the heading, width across it), so boxes that only
touch overlap: that is what Scenic's `a intersects b` answers for two planar boxes (shapely's `intersects` of
their footprints, scenic 3.1.1 Object.intersects), and the collision rule must mean the same thing in our
sampler and in the emitted Scenic text. For two rectangles the four edge normals are the only candidate
separating axes, so the test is exact (up to float rounding, where a tie is a measure-zero event).
"""

from __future__ import annotations

import numpy as np

from synth.scene import Entity, Scene


def box_radius(length, width):
    """Half the diagonal: no point of the box is farther from its centre."""
    return np.hypot(length, width) / 2


def boxes_overlap(ax, ay, ah, al, aw, bx, by, bh, bl, bw, xp=np):
    """Does box a (x, y, heading in degrees, length, width) overlap box b? Elementwise over numpy arrays (they
    broadcast), or for one pair of plain floats with xp=math (no numpy call overhead: the sampler's inner loop)."""
    ta, tb = xp.radians(ah), xp.radians(bh)
    ca, sa, cb, sb = xp.cos(ta), xp.sin(ta), xp.cos(tb), xp.sin(tb)
    dx, dy = bx - ax, by - ay
    cos_d = abs(ca * cb + sa * sb)  # |cos(hb - ha)|: forward.forward and right.right
    sin_d = abs(ca * sb - sa * cb)  # |sin(hb - ha)|: forward.right
    hal, haw, hbl, hbw = al * 0.5, aw * 0.5, bl * 0.5, bw * 0.5
    # Forward of heading h is (-sin h, cos h), right is (cos h, sin h); project the centre offset on each axis.
    return ((abs(-dx * sa + dy * ca) <= hal + hbl * cos_d + hbw * sin_d)
            & (abs(dx * ca + dy * sa) <= haw + hbl * sin_d + hbw * cos_d)
            & (abs(-dx * sb + dy * cb) <= hbl + hal * cos_d + haw * sin_d)
            & (abs(dx * cb + dy * sb) <= hbw + hal * sin_d + haw * cos_d))


def box_arrays(entities: list[Entity]) -> tuple[np.ndarray, ...]:
    """(x, y, heading, length, width) arrays of entities (length / width: recorded, else the type's)."""
    dims = [e.dimensions() for e in entities]
    return (np.array([e.x for e in entities]), np.array([e.y for e in entities]),
            np.array([e.heading for e in entities]), np.array([d[0] for d in dims]), np.array([d[1] for d in dims]))


def overlapping_pairs(entities: list[Entity]) -> list[tuple[int, int]]:
    """Index pairs (i < j) of entities whose boxes overlap, in order."""
    n = len(entities)
    if n < 2:
        return []
    x, y, h, length, width = box_arrays(entities)
    i, j = np.triu_indices(n, 1)
    near = np.hypot(x[i] - x[j], y[i] - y[j]) <= box_radius(length[i], width[i]) + box_radius(length[j], width[j])
    i, j = i[near], j[near]
    hit = boxes_overlap(x[i], y[i], h[i], length[i], width[i], x[j], y[j], h[j], length[j], width[j])
    return [(int(a), int(b)) for a, b in zip(i[hit], j[hit])]


def scene_overlaps(scene: Scene) -> list[tuple[str, str]]:
    """Pairs of entity ids whose boxes overlap in the scene, in scene order."""
    ents = list(scene.entities)
    return [(ents[a].id, ents[b].id) for a, b in overlapping_pairs(ents)]
