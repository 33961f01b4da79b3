"""Does a program contain a scene? The paper's denotational semantics, read literally.

This module is the test oracle for everything else. Each clause reads itself (Clause.holds)
with nothing but the angle helpers: float atan2 bearings, the W difference, and the Range bounds as printed,
never the cone test, the tables or the solver of the oracles. Decisions at the exact edge of a tolerance are
accepted within ANGLE_EPS (1e-9 degrees) to absorb float rounding of atan2; the synthesizer itself decides
edges exactly, so it never relies on that slack by more than rounding. A bearing between coincident points is
undefined: no direction or facing relation holds there.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from synth.config import SynthConfig, as_config
from synth.dsl import Program, Statement, parse_program
from synth.parts.position import ANGLE_EPS, LENGTH_EPS
from synth.scene import EGO_ID, Entity, Scene, as_scene

__all__ = ["ANGLE_EPS", "LENGTH_EPS", "CheckResult", "Violation", "check", "check_statement", "heading_holds",
           "position_holds"]


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
    return pos.holds(e, ref, config)


def heading_holds(head, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
    return head.holds(e, ref, config)


def check_statement(st: Statement, scene_by_id: dict[str, Entity], config: SynthConfig) -> list[Violation]:
    e = scene_by_id[st.id]
    out = []
    if st.type != e.type:
        out.append(Violation(st.id, "type", f"declared {st.type}, scene has {e.type}"))
    for part, clause in st.clauses():
        ref = scene_by_id.get(clause.ref) if clause.ref else None
        if not clause.holds(e, ref, config):
            out.append(Violation(st.id, part.name, f"{clause.observed(e)} is not {clause}"))
    return out


def check(program: Program | str, scene: Scene | Mapping[str, Any],
          config: SynthConfig | Mapping[str, Any] | None = None) -> CheckResult:
    """All the ways in which `scene` is not in the semantics of `program` (none: it is; `r2s check`).

    `program`: a Program or DSL text; `scene`: a Scene or a decoded scene JSON dict; `config`: as synthesize takes
    it (only the tolerances and motion constants matter here)."""
    if isinstance(program, str):
        program = parse_program(program)
    scene = as_scene(scene)
    config = as_config(config)
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
        refs = [c.ref for _, c in st.clauses() if c.ref is not None]
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
