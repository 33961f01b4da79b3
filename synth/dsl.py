"""The paper's DSL (Fig. 3): statements and programs, their cost, printer and parser, which round-trip exactly.

    P       ::= S*
    S       ::= ID = new TYPE POS, HEADING [, MOTION]
    POS     ::= (ahead of | behind | left of | right of) REF by Range(a, b)      cost 0
              | on Range(a, b) @ Range(c, d) relative to REF                    cost 1
              | on Range(a, b) @ Range(c, d)                                    cost 2
    HEADING ::= facing (toward | away from) REF                                 cost 0
              | facing Range(a, b) deg relative to REF                          cost 1
              | facing Range(a, b) deg                                          cost 2
    MOTION  ::= stationary | moving like REF                                     cost 0  (beyond the paper)
              | moving Range(a, b) m/s relative to REF                          cost 1
              | moving Range(a, b) m/s                                          cost 2
    REF     ::= ego | an ID declared earlier

Each part's clauses (their classes, printing and parsing) live with the part, in synth.parts; they are
re-exported here, where programs are assembled.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass
from typing import Union

from synth.parts import ALL_PARTS, MOTION, STATIC_PARTS
from synth.parts.heading import FACINGS, AbsoluteHeading, FacingRelation, RelativeHeading
from synth.parts.motion import AbsoluteSpeed, MovingLike, RelativeSpeed, Stationary
from synth.parts.position import DIRECTIONS, AbsoluteXYPos, DirectionPos, LocalXYPos
from synth.scene import EGO_ID, ENTITY_TYPES, SceneError, check_identifier
from synth.syntax import DslError, Line, Range, fmt_number

Position = Union[DirectionPos, LocalXYPos, AbsoluteXYPos]
Heading = Union[FacingRelation, RelativeHeading, AbsoluteHeading]
Motion = Union[Stationary, MovingLike, RelativeSpeed, AbsoluteSpeed]


@dataclass(frozen=True)
class Statement:
    id: str
    type: str
    position: Position
    heading: Heading
    motion: Motion | None = None  # static programs (the paper's) have none

    def clauses(self) -> Iterator[tuple[object, object]]:
        """(part, clause) for every part the statement carries, in statement order."""
        for part in ALL_PARTS:
            clause = getattr(self, part.name)
            if clause is not None:
                yield part, clause

    @property
    def cost(self) -> int:
        return sum(c.cost for _, c in self.clauses())

    def __str__(self) -> str:
        return f"{self.id} = new {self.type} " + ", ".join(str(c) for _, c in self.clauses())


@dataclass(frozen=True)
class Program:
    statements: tuple[Statement, ...]

    @property
    def cost(self) -> int:
        return sum(s.cost for s in self.statements)

    def __str__(self) -> str:
        return "".join(f"{s}\n" for s in self.statements)


def format_program(program: Program) -> str:
    return str(program)


def parse_program(text: str) -> Program:
    """Parse DSL text (one statement a line; blank lines and # comments allowed).

    Scoping is part of the grammar: a reference is ego or an entity declared on an earlier line.
    """
    return Program(parse_statements(text, ENTITY_TYPES))


def parse_statements(text: str, types: Collection[str]) -> tuple[Statement, ...]:
    """The statements of DSL text whose TYPEs are drawn from `types` (programs: the entity types; patterns,
    synth.pattern, add their type classes). Errors name the line and column."""
    declared: set[str] = set()
    statements = []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        line = raw.split("#", 1)[0]
        if not line.strip():
            continue
        st = _statement(Line(line, lineno), declared, types)
        declared.add(st.id)
        statements.append(st)
    return tuple(statements)


def _statement(ln: Line, declared: set[str], types: Collection[str]) -> Statement:
    name = ln.take("word")
    try:
        check_identifier(name)
    except SceneError as exc:
        raise DslError(f"{ln.where(back=1)}: {exc}") from None
    if name == EGO_ID:
        raise DslError(f"{ln.where(back=1)}: ego is given by the scene and is never declared")
    if name in declared:
        raise DslError(f"{ln.where(back=1)}: {name!r} is declared twice")
    ln.take(text="=")
    ln.take(text="new")
    etype = ln.take("word")
    if etype not in types:
        raise DslError(f"{ln.where(back=1)}: unknown type {etype!r}")
    clauses = {}
    for k, part in enumerate(STATIC_PARTS):
        if k:
            ln.take(text=",")
        clauses[part.name] = part.parse(ln, declared)
    if ln.accept(","):
        clauses[MOTION.name] = MOTION.parse(ln, declared)
    ln.end()
    return Statement(name, etype, **clauses)


__all__ = [
    "DIRECTIONS", "FACINGS", "AbsoluteHeading", "AbsoluteSpeed", "AbsoluteXYPos", "DirectionPos", "DslError",
    "FacingRelation", "Heading", "LocalXYPos", "Motion", "MovingLike", "Position", "Program", "Range",
    "RelativeHeading", "RelativeSpeed", "Stationary", "Statement", "fmt_number",
    "format_program", "parse_program", "parse_statements",
]
