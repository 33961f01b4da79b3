"""Patterns: DSL programs whose declared names are variables, matched against scenes (scenario mining).

A pattern is a program in the DSL, parsed by the same parser, with these differences of reading:
- TYPE may also be a type class: `Vehicle` (any of VEHICLE_CLASSES, what `--categories vehicles` keeps) or
  `Object` (any type at all);
- Ranges are taken as written, of any width (the C_dist / C_head widths are a rule for synthesized programs);
- a statement may leave out its position or heading clause (or both): any position, any heading;
- a position may be a distance alone, `within Range(a, b) of REF` (WithinDistance: any direction);
- a line `ego CLAUSE, ...` constrains the frame's ego by clauses of the optional parts (its motion: `ego
  stationary`, `ego moving Range(5, 15) m/s`, `ego moving like car`; its lane: `ego in intersection`, `ego in
  lane of car`), its references declared above it.
A match of a pattern in a scene is an injective binding of its names to the scene's non-ego entities, of
matching types, under which every statement holds by the DSL semantics, REF resolved through the binding
(synth.semantics: the same functions `r2s check` uses). This module is the definition; pipeline.query.mining is the
vectorized engine over a whole frames dataset, which must agree with it exactly.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

from synth.config import SynthConfig
from synth.dsl import DslError, Statement, parse_statements, statement_head
from synth.parts import Clause, Part, all_parts
from synth.parts.position import LENGTH_EPS
from synth.scene import EGO_ID, ENTITY_TYPES, VEHICLE_CLASSES, Entity, Scene
from synth.syntax import Line, Range

# The most names a pattern declares (its steps together, for a temporal one): each name is a join of the query.
# Checked as the lines are read, so a pattern of a million lines is refused at its 13th name, not after parsing.
MAX_NAMES = 12

VEHICLE = "Vehicle"
ANY = "Object"
PATTERN_TYPES = frozenset(ENTITY_TYPES) | {VEHICLE}


PATTERN_ONLY = "a pattern's clause: patterns are matched, never synthesized, certified or sampled"


@dataclass(frozen=True)
class WithinDistance(Clause):
    """`within Range(a, b) of REF`, in patterns only: the centre distance to REF is in [a, b] (within 1e-9 m, as
    every length of the checker), in any direction. A position clause (it takes the position's place)."""

    distance: Range
    ref: str
    cost = 0
    text = "within {c.distance} of {c.ref}"
    labels = ("within",)
    drawn_as = "sector"
    first_word = "within"

    @classmethod
    def read(cls, ln: Line, declared: set[str]) -> WithinDistance | None:
        if not ln.accept("within"):
            return None
        distance = ln.range_()
        ln.take(text="of")
        return cls(distance, ln.reference(declared))

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self.distance.contains(math.hypot(e.x - ref.x, e.y - ref.y), LENGTH_EPS)

    def observed(self, e: Entity) -> str:
        return f"({e.x:.3f}, {e.y:.3f})"

    def formula(self, backend: Any, e: Entity, ref: Entity | None) -> Any:
        raise NotImplementedError(PATTERN_ONLY)

    def violations(self, backend: Any, e: Entity, ref: Entity | None) -> list[Any]:
        raise NotImplementedError(PATTERN_ONLY)

    def scenic(self, at: str) -> str:
        raise NotImplementedError(PATTERN_ONLY)

    def draws(self, config: SynthConfig) -> Any:
        raise NotImplementedError(PATTERN_ONLY)


# The parts an `ego ...` line may use: motion and lane (the engine reads ego's row as any other: pipeline.query.lanes).
EGO_PARTS = ("motion", "lane")

# Pattern-only clause kinds, by the part whose place they take.
PATTERN_CLAUSES: dict[str, tuple[type[Clause], ...]] = {"position": (WithinDistance,)}


@dataclass(frozen=True)
class Pattern:
    statements: tuple[Statement, ...]
    ego: Statement | None = None  # the `ego ...` line: clauses of optional parts that ego must satisfy

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(s.id for s in self.statements)

    @property
    def uses_motion(self) -> bool:
        """Does a statement (or the ego line) carry a MOTION clause (which needs the entities' speeds)?"""
        return any(s.motion is not None for s in (*self.statements, *([self.ego] if self.ego else [])))

    @property
    def uses_lanes(self) -> bool:
        """Does a statement (or the ego line) carry a LANE clause (which needs the frames' lane columns and maps)?"""
        return any(s.lane is not None for s in (*self.statements, *([self.ego] if self.ego else [])))

    def __str__(self) -> str:
        ego = f"{EGO_ID} {', '.join(str(c) for _, c in self.ego.clauses())}\n" if self.ego is not None else ""
        return "".join(f"{s}\n" for s in self.statements) + ego


def parse_pattern(text: str, first_line: int = 1) -> Pattern:
    """A pattern from DSL text whose first line is line `first_line` of its file; errors (DslError) carry the line
    and column, as `r2s check` reports them."""
    lines = parse_statements(text, PATTERN_TYPES, reader=_pattern_line, first_line=first_line)
    statements = tuple(st for st in lines if st.id != EGO_ID)
    if not statements:
        raise DslError(f"line {first_line} column 1: the pattern declares no name (one statement a line: "
                       "NAME = new TYPE ...)")
    return Pattern(statements, next((st for st in lines if st.id == EGO_ID), None))


def _pattern_line(ln: Line, declared: set[str], types: Collection[str]) -> Statement:
    """A pattern's line: `NAME = new TYPE [CLAUSE[, CLAUSE ...]]`, its clauses in the parts' order, each part at
    most once (a required part left out: any); or `ego CLAUSE[, ...]` with clauses of the optional parts."""
    if ln.peek() == EGO_ID:
        ln.take()
        if ln.peek() == "=":
            raise DslError(f"{ln.where()}: ego is given by the scene and is never declared; constrain it with a line "
                           "such as `ego moving Range(5, 15) m/s`")
        if EGO_ID in declared:
            raise DslError(f"{ln.where(back=1)}: ego is constrained twice (one `ego ...` line, its clauses "
                           "comma-separated)")
        clauses = _clauses(ln, declared, [p for p in all_parts() if p.name in EGO_PARTS], "ego")
        if not clauses:
            raise DslError(f"{ln.where()}: expected a clause about ego after `ego`")
        declared.add(EGO_ID)  # marks the ego line as given (references to ego are always allowed)
        return Statement(EGO_ID, ANY, **clauses)
    if len(declared - {EGO_ID}) >= MAX_NAMES:
        raise too_many_names(ln.lineno)
    name, etype = statement_head(ln, declared, types)
    return Statement(name, etype, **_clauses(ln, declared, list(all_parts()), name))


def too_many_names(lineno: int) -> DslError:
    return DslError(f"line {lineno}: the pattern declares {MAX_NAMES + 1} or more names, more than the bound of "
                    f"{MAX_NAMES} (docs/cli.md, Inputs and their bounds)")


def _clauses(ln: Line, declared: set[str], parts: list[Part], who: str) -> dict[str, Clause]:
    clauses: dict[str, Clause] = {}
    ln.accept(",")  # `p = new Pedestrian, facing toward ego` reads as well as without the comma
    while ln.peek() is not None:
        if clauses:
            ln.take(text=",")
        part, clause = _clause(ln, declared, parts, who)
        clauses[part.name] = clause
        parts = parts[parts.index(part) + 1:]
    ln.end()
    return clauses


def _clause(ln: Line, declared: set[str], parts: list[Part], who: str) -> tuple[Part, Clause]:
    """The clause at the cursor, of the first of `parts` (the parts not yet said, in order) that reads one."""
    for part in parts:
        for kind in PATTERN_CLAUSES.get(part.name, ()):
            if (clause := kind.read(ln, declared)) is not None:
                return part, clause
        start = ln.i
        try:
            return part, part.parse(ln, declared)
        except DslError:
            if ln.i > start:  # the part recognised its first word: the error is in its clause
                raise
            ln.i = start
    found = ln.peek()
    words = ", ".join(f"{p.name} ({', '.join(sorted(_first_words(p)))})" for p in parts)
    raise DslError(f"{ln.where()}: expected a clause of {who} in this order: {words or 'none left'}; found "
                   f"{'end of line' if found is None else repr(found)}")


def _first_words(part: Part) -> set[str]:
    """The words a part's clauses begin with, for messages (position and heading parse themselves)."""
    own = {"position": {"ahead of", "behind", "left of", "right of", "on"}, "heading": {"facing"}}.get(part.name, set())
    return own | set(part.first_words) | {k.first_word for k in PATTERN_CLAUSES.get(part.name, ())}


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
    """Is `binding` (pattern name -> entity, injective, ego excluded) a match? The definition the engine meets:
    every statement holds, and the ego line of ego."""
    bound = {EGO_ID: ego, **binding}
    return all(statement_holds(st, bound, config) for st in pattern.statements) and (
        pattern.ego is None or statement_holds(pattern.ego, bound, config))


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
            if pattern.ego is None or statement_holds(pattern.ego, bound, config):
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
