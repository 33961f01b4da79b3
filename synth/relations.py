"""Which spatial relations hold between every (reference, target) pair of a scene: closed form, all at once.

Position: target e is `dir of r` when the bearing r -> e lies within delta1 of r.heading + phi(dir).
Heading: e is `facing toward r` when e.heading lies within delta2 of the bearing e -> r (`away from`: r -> e).
Both are the same test, "v lies within delta of the unit vector u", which without atan2 reads
    v.u > 0  and  (v.u)^2 >= cos^2(delta) |v|^2        (|v| > 0)
the polynomial form the SMT oracle encodes too. Floats decide every pair whose cosine margin exceeds
GUARD; the few pairs inside the guard band are marked undecided, for the caller to settle exactly (with
rationals in closed form, with the solver in hybrid).
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from synth.config import SynthConfig
from synth.dsl import DIRECTIONS
from synth.geometry import exact_cos_squared, exact_heading_vector, heading_vector
from synth.scene import Scene

DIRECTION_NAMES = tuple(DIRECTIONS)  # ahead, left, behind, right: index = code in the tables
FACING_NAMES = ("toward", "away")
NONE = -1
UNDECIDED = -2
# Cosine margin below which a float decision is not trusted (float error is ~1e-15 here).
GUARD = 1e-9


@dataclass(frozen=True)
class RelationTable:
    """position[r, e]: index into DIRECTION_NAMES, NONE or UNDECIDED; heading[r, e]: FACING_NAMES index, ....

    Index 0 is ego; rows are references, columns targets, both in `ids` order.
    """

    ids: tuple[str, ...]
    position: np.ndarray
    heading: np.ndarray

    def undecided(self) -> list[tuple[str, int, int]]:
        """('position' | 'heading', r, e) for every pair the floats could not settle."""
        out = [("position", int(r), int(e)) for r, e in zip(*np.nonzero(self.position == UNDECIDED))]
        out += [("heading", int(r), int(e)) for r, e in zip(*np.nonzero(self.heading == UNDECIDED))]
        return out


def scene_arrays(scene: Scene) -> tuple[tuple[str, ...], np.ndarray, np.ndarray, np.ndarray]:
    """ids (ego first), x, y, heading as arrays."""
    ents = (scene.ego,) + scene.others
    return (
        tuple(e.id for e in ents),
        np.array([e.x for e in ents], dtype=np.float64),
        np.array([e.y for e in ents], dtype=np.float64),
        np.array([e.heading for e in ents], dtype=np.float64),
    )


def _unit_vectors(headings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    # The same float constants as geometry.heading_vector, element by element.
    pairs = [heading_vector(float(h)) for h in headings]
    return (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))


def _within(dot: np.ndarray, dist: np.ndarray, cos_delta: float) -> tuple[np.ndarray, np.ndarray]:
    """(holds, undecided) of the cone test, given v.u and |v| (|v| = 0: never holds, decided)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        margin = np.where(dist > 0.0, dot / np.where(dist > 0.0, dist, 1.0) - cos_delta, -1.0)
    return margin > GUARD, np.abs(margin) <= GUARD


def closed_form_table(scene: Scene, config: SynthConfig) -> RelationTable:
    ids, x, y, h = scene_arrays(scene)
    dx = x[None, :] - x[:, None]  # [r, e] = e - r
    dy = y[None, :] - y[:, None]
    dist = np.hypot(dx, dy)
    cos1 = float(np.cos(np.radians(config.delta1)))
    cos2 = float(np.cos(np.radians(config.delta2)))

    position = np.full(dx.shape, NONE, dtype=np.int8)
    for code, name in enumerate(DIRECTION_NAMES):
        ux, uy = _unit_vectors(h + DIRECTIONS[name][1])
        mark(position, code, *_within(dx * ux[:, None] + dy * uy[:, None], dist, cos1))

    heading = np.full(dx.shape, NONE, dtype=np.int8)
    hx, hy = _unit_vectors(h)
    # toward r: e's heading vector against (r - e); away: against (e - r).
    toward = -(dx * hx[None, :] + dy * hy[None, :])
    for code, dot in enumerate((toward, -toward)):
        mark(heading, code, *_within(dot, dist, cos2))
    return finish_table(ids, position, heading)


def mark(codes: np.ndarray, code: int, holds: np.ndarray, unsure: np.ndarray) -> None:
    """Record one relation's float decisions: its code where it holds; UNDECIDED where the floats cannot tell
    and no other relation holds (sectors are disjoint, so at most one ever does)."""
    codes[holds] = code
    codes[unsure & (codes == NONE)] = UNDECIDED


def finish_table(ids: tuple[str, ...], position: np.ndarray, heading: np.ndarray) -> RelationTable:
    """No entity is its own witness."""
    np.fill_diagonal(position, NONE)
    np.fill_diagonal(heading, NONE)
    return RelationTable(ids, position, heading)


# ------------------------------------------------------------------------------ exact rational decisions


def exact_within(vx: Fraction, vy: Fraction, u: tuple[Fraction, Fraction], cos_sq: Fraction) -> bool:
    """The cone test in exact rational arithmetic (the ground truth the solver encodes too)."""
    dot = vx * u[0] + vy * u[1]
    return dot > 0 and dot * dot >= cos_sq * (vx * vx + vy * vy)


def exact_position(scene: Scene, ref_id: str, target_id: str, direction: str, config: SynthConfig) -> bool:
    by = scene.by_id()
    r, e = by[ref_id], by[target_id]
    vx, vy = Fraction(e.x) - Fraction(r.x), Fraction(e.y) - Fraction(r.y)
    u = exact_heading_vector(r.heading + DIRECTIONS[direction][1])
    return exact_within(vx, vy, u, exact_cos_squared(config.delta1))


def exact_heading(scene: Scene, ref_id: str, target_id: str, mode: str, config: SynthConfig) -> bool:
    by = scene.by_id()
    r, e = by[ref_id], by[target_id]
    vx, vy = Fraction(e.x) - Fraction(r.x), Fraction(e.y) - Fraction(r.y)
    if mode == "toward":
        vx, vy = -vx, -vy
    return exact_within(vx, vy, exact_heading_vector(e.heading), exact_cos_squared(config.delta2))


def settle_exactly(table: RelationTable, scene: Scene, config: SynthConfig) -> RelationTable:
    """Replace every UNDECIDED entry by the exact rational decision."""
    position, heading = table.position.copy(), table.heading.copy()
    for kind, r, e in table.undecided():
        rid, eid = table.ids[r], table.ids[e]
        if kind == "position":
            hits = [c for c, d in enumerate(DIRECTION_NAMES) if exact_position(scene, rid, eid, d, config)]
            position[r, e] = hits[0] if hits else NONE
        else:
            hits = [c for c, m in enumerate(FACING_NAMES) if exact_heading(scene, rid, eid, m, config)]
            heading[r, e] = hits[0] if hits else NONE
    return RelationTable(table.ids, position, heading)
