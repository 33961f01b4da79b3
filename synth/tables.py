"""Relation tables: who witnesses whom, as one code array per statement part, and how floats decide them.

A table holds, for every statement part, codes[r, e]: the index of the relation of that part that target e has
with reference r (ego is index 0), NONE, or UNDECIDED where floats cannot tell and an exact decision is owed.
Floats decide every pair whose margin exceeds the guard band; inside it the caller settles exactly (rationals in
closed form, the solver in hybrid). The cone test, "v lies within delta of the unit vector u", is the shared
question of position and heading relations:
    v.u > 0  and  (v.u)^2 >= cos^2(delta) |v|^2        (|v| > 0)
the polynomial form the SMT oracle encodes too.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from fractions import Fraction

import numpy as np

from synth.geometry import heading_vector
from synth.scene import Entity, Scene

NONE = -1
UNDECIDED = -2
# Margin below which a float decision is not trusted (float error is ~1e-15 here).
GUARD = 1e-9


@dataclass(frozen=True)
class SceneArrays:
    """A scene as arrays, ego first then the entities to declare in scene order: what closed forms compute on."""

    ids: tuple[str, ...]
    x: np.ndarray
    y: np.ndarray
    heading: np.ndarray
    speed: np.ndarray  # m/s; NaN where an entity has no speed
    entities: tuple[Entity, ...] = ()  # the entities themselves, same order (parts whose questions are lookups)


def scene_arrays(scene: Scene) -> SceneArrays:
    ents = (scene.ego,) + scene.others
    return SceneArrays(
        tuple(e.id for e in ents),
        np.array([e.x for e in ents], dtype=np.float64),
        np.array([e.y for e in ents], dtype=np.float64),
        np.array([e.heading for e in ents], dtype=np.float64),
        np.array([np.nan if e.speed is None else e.speed for e in ents], dtype=np.float64),
        ents,
    )


@dataclass(frozen=True)
class RelationTable:
    """codes[part][r, e] for every statement part: rows are references, columns targets, both in `ids` order."""

    ids: tuple[str, ...]
    codes: Mapping[str, np.ndarray]

    def __getitem__(self, part: str) -> np.ndarray:
        return self.codes[part]

    @property
    def position(self) -> np.ndarray:
        return self.codes["position"]

    @property
    def heading(self) -> np.ndarray:
        return self.codes["heading"]

    def undecided(self) -> Iterator[tuple[str, int, int]]:
        """(part, r, e) for every pair the floats could not settle, part by part."""
        for part, codes in self.codes.items():
            for r, e in zip(*np.nonzero(codes == UNDECIDED)):
                yield (part, int(r), int(e))

    def replaced(self, codes: Mapping[str, np.ndarray]) -> RelationTable:
        return RelationTable(self.ids, dict(codes))


def mark(codes: np.ndarray, code: int, holds: np.ndarray, unsure: np.ndarray) -> None:
    """Record one relation's float decisions: its code where it holds; UNDECIDED where the floats cannot tell
    and no other relation holds (a part's relations are disjoint, so at most one ever does)."""
    codes[holds] = code
    codes[unsure & (codes == NONE)] = UNDECIDED


def no_self_witness(codes: np.ndarray) -> np.ndarray:
    """No entity is its own witness."""
    np.fill_diagonal(codes, NONE)
    return codes


# ------------------------------------------------------------------------------------------------ the cone test


def unit_vectors(headings: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The same float constants as geometry.heading_vector, element by element."""
    pairs = [heading_vector(float(h)) for h in headings]
    return (np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs]))


def within(dot: np.ndarray, dist: np.ndarray, cos_delta: float) -> tuple[np.ndarray, np.ndarray]:
    """(holds, undecided) of the cone test, given v.u and |v| (|v| = 0: never holds, decided)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        margin = np.where(dist > 0.0, dot / np.where(dist > 0.0, dist, 1.0) - cos_delta, -1.0)
    return margin > GUARD, np.abs(margin) <= GUARD


def exact_within(vx: Fraction, vy: Fraction, u: tuple[Fraction, Fraction], cos_sq: Fraction) -> bool:
    """The cone test in exact rational arithmetic (the ground truth the solver encodes too)."""
    dot = vx * u[0] + vy * u[1]
    return dot > 0 and dot * dot >= cos_sq * (vx * vx + vy * vy)
