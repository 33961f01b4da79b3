"""Patterns: DSL programs whose declared names are variables, matched against scenes (scenario mining).

A pattern is a program in the DSL, parsed by the same parser, with two differences of reading:
- TYPE may also be a type class: `Vehicle` (any of VEHICLE_CLASSES, what `--categories vehicles` keeps) or
  `Object` (any type at all);
- Ranges are taken as written, of any width (the C_dist / C_head widths are a rule for synthesized programs).
A match of a pattern in a scene is an injective binding of its names to the scene's non-ego entities, of
matching types, under which every statement holds by the DSL semantics, REF resolved through the binding
(synth.semantics: the same functions `r2s check` uses). This module is the definition; pipeline.query.mining is the
vectorized engine over a whole frames dataset, which must agree with it exactly.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass

from synth.config import SynthConfig
from synth.dsl import DslError, Statement, parse_statements
from synth.scene import EGO_ID, ENTITY_TYPES, VEHICLE_CLASSES, Entity, Scene

VEHICLE = "Vehicle"
ANY = "Object"
PATTERN_TYPES = frozenset(ENTITY_TYPES) | {VEHICLE}


@dataclass(frozen=True)
class Pattern:
    statements: tuple[Statement, ...]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.id for s in self.statements)

    @property
    def uses_motion(self) -> bool:
        """Does a statement carry a MOTION clause (which needs the entities' speeds)?"""
        return any(s.motion is not None for s in self.statements)

    def __str__(self) -> str:
        return "".join(f"{s}\n" for s in self.statements)


def parse_pattern(text: str) -> Pattern:
    """A pattern from DSL text; errors (DslError) carry the line and column, as `r2s check` reports them."""
    statements = parse_statements(text, PATTERN_TYPES)
    if not statements:
        raise DslError("line 1 column 1: the pattern declares no name (one statement a line: NAME = new TYPE ...)")
    return Pattern(statements)


def matched_types(pattern_type: str) -> frozenset[str] | None:
    """The entity types a pattern TYPE matches; None: every type."""
    if pattern_type == ANY:
        return None
    if pattern_type == VEHICLE:
        return VEHICLE_CLASSES
    return frozenset({pattern_type})


def type_matches(pattern_type: str, entity_type: str) -> bool:
    types = matched_types(pattern_type)
    return types is None or entity_type in types


def statement_holds(st: Statement, bound: Mapping[str, Entity], config: SynthConfig) -> bool:
    """Does statement st hold of bound[st.id], its references looked up in `bound` (which maps ego too)? Every
    clause is read by its own semantics (Clause.holds, what `r2s check` uses)."""
    e = bound[st.id]
    return type_matches(st.type, e.type) and all(
        clause.holds(e, bound[clause.ref] if clause.ref is not None else None, config)
        for _, clause in st.clauses())


def binding_holds(pattern: Pattern, ego: Entity, binding: Mapping[str, Entity], config: SynthConfig) -> bool:
    """Is `binding` (pattern name -> entity, injective, ego excluded) a match? The definition the engine meets."""
    bound = {EGO_ID: ego, **binding}
    return all(statement_holds(st, bound, config) for st in pattern.statements)


def matches(pattern: Pattern, scene: Scene, config: SynthConfig | None = None) -> Iterator[dict[str, str]]:
    """Every match in `scene` (name -> entity id), by backtracking in declaration order, each statement checked as
    soon as its entity is bound (its references are declared earlier). Bindings come in lexicographic order of
    the entities' positions in the scene, so the first one binds the earliest entities (the nearest, for
    extracted frames)."""
    config = config or SynthConfig()
    others = scene.others
    bound: dict[str, Entity] = {EGO_ID: scene.ego}
    used: set[int] = set()
    statements = pattern.statements

    def extend(k: int) -> Iterator[dict[str, str]]:
        if k == len(statements):
            yield {st.id: bound[st.id].id for st in statements}
            return
        st = statements[k]
        for i, e in enumerate(others):
            if i in used:
                continue
            bound[st.id] = e
            if statement_holds(st, bound, config):
                used.add(i)
                yield from extend(k + 1)
                used.discard(i)
        bound.pop(st.id, None)

    return extend(0)
