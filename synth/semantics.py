"""Does a program contain a scene? The paper's denotational semantics, read literally.

This module is the test oracle for everything else, so it shares nothing with the search or the oracles but
the angle helpers: float atan2 bearings, the W difference, and the Range bounds as printed. Decisions at the
exact edge of a tolerance are accepted within ANGLE_EPS (1e-9 degrees) to absorb float rounding of atan2;
the synthesizer itself decides edges exactly, so it never relies on that slack by more than rounding.
A bearing between coincident points is undefined: no direction or facing relation holds there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from synth.config import SynthConfig
from synth.dsl import (
    DIRECTIONS,
    AbsoluteHeading,
    AbsoluteXYPos,
    DirectionPos,
    FacingRelation,
    LocalXYPos,
    Program,
    RelativeHeading,
    Statement,
)
from synth.geometry import angular_difference, bearing, normalize, to_local
from synth.scene import EGO_ID, Entity, Scene

ANGLE_EPS = 1e-9
LENGTH_EPS = 1e-9


@dataclass(frozen=True)
class Violation:
    entity: str
    part: str  # position | heading | scope | type | missing | extra
    message: str

    def __str__(self) -> str:
        return f"{self.entity}: {self.part}: {self.message}"


@dataclass(frozen=True)
class CheckResult:
    violations: tuple[Violation, ...]

    @property
    def ok(self) -> bool:
        return not self.violations


def position_holds(pos, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
    if isinstance(pos, AbsoluteXYPos):
        return pos.x.contains(e.x, LENGTH_EPS) and pos.y.contains(e.y, LENGTH_EPS)
    assert ref is not None
    dx, dy = e.x - ref.x, e.y - ref.y
    if isinstance(pos, LocalXYPos):
        lx, ly = to_local(dx, dy, ref.heading)
        return pos.lateral.contains(lx, LENGTH_EPS) and pos.forward.contains(ly, LENGTH_EPS)
    if isinstance(pos, DirectionPos):
        dist = math.hypot(dx, dy)
        if dist == 0.0 or not pos.distance.contains(dist, LENGTH_EPS):
            return False
        axis = ref.heading + DIRECTIONS[pos.direction][1]
        return angular_difference(bearing(ref.x, ref.y, e.x, e.y), axis) <= config.delta1 + ANGLE_EPS
    raise TypeError(f"not a position: {pos!r}")


def heading_holds(head, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
    if isinstance(head, AbsoluteHeading):
        return _in_angle_range(e.heading, 0.0, head.angle)
    assert ref is not None
    if isinstance(head, RelativeHeading):
        return _in_angle_range(e.heading, ref.heading, head.angle)
    if isinstance(head, FacingRelation):
        if (e.x, e.y) == (ref.x, ref.y):
            return False
        if head.mode == "toward":
            target = bearing(e.x, e.y, ref.x, ref.y)
        else:
            target = bearing(ref.x, ref.y, e.x, e.y)
        return angular_difference(e.heading, target) <= config.delta2 + ANGLE_EPS
    raise TypeError(f"not a heading: {head!r}")


def _in_angle_range(heading: float, base: float, rng) -> bool:
    """Is heading = N(base + alpha) for some alpha in rng? Measured as an offset past rng.lo, mod 360."""
    if rng.hi - rng.lo >= 360.0:
        return True
    past = normalize(heading - base - rng.lo)
    # Just below 360 means just below rng.lo: inside within rounding.
    return past <= (rng.hi - rng.lo) + ANGLE_EPS or past >= 360.0 - ANGLE_EPS


def check_statement(st: Statement, scene_by_id: dict[str, Entity], config: SynthConfig) -> list[Violation]:
    e = scene_by_id[st.id]
    out = []
    if st.type != e.type:
        out.append(Violation(st.id, "type", f"declared {st.type}, scene has {e.type}"))
    pref = scene_by_id.get(st.position.ref) if st.position.ref else None
    if not position_holds(st.position, e, pref, config):
        out.append(Violation(st.id, "position", f"({e.x:.3f}, {e.y:.3f}) is not {st.position}"))
    href = scene_by_id.get(st.heading.ref) if st.heading.ref else None
    if not heading_holds(st.heading, e, href, config):
        out.append(Violation(st.id, "heading", f"heading {e.heading:.3f} is not {st.heading}"))
    return out


def check(program: Program, scene: Scene, config: SynthConfig | None = None) -> CheckResult:
    """All the ways in which `scene` is not in the semantics of `program` (none: it is)."""
    config = config or SynthConfig()
    by_id = scene.by_id()
    violations: list[Violation] = []
    declared = {EGO_ID}
    for st in program.statements:
        if st.id == EGO_ID or st.id not in by_id:
            violations.append(Violation(st.id, "extra", "declared but not an entity of the scene"))
            continue
        if st.id in declared:
            violations.append(Violation(st.id, "extra", "declared twice"))
            continue
        refs = [r for r in (st.position.ref, st.heading.ref) if r is not None]
        bad = [r for r in refs if r not in declared]
        declared.add(st.id)
        if bad:
            violations.append(Violation(st.id, "scope", f"refers to {bad[0]!r} before it is declared"))
            continue
        violations.extend(check_statement(st, by_id, config))
    for e in scene.others:
        if e.id not in declared:
            violations.append(Violation(e.id, "missing", "entity of the scene that the program does not declare"))
    return CheckResult(tuple(violations))
