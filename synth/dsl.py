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
re-exported here, where programs are assembled. A statement carries one clause per part, in the registry's
order (synth.parts): the required parts, comma-separated, then the optional ones it has, each after a comma.
"""

from __future__ import annotations

from collections.abc import Collection, Iterator
from dataclasses import dataclass
from typing import Union

from synth.parts import Clause, Part, all_parts, part_named
from synth.parts.heading import FACINGS, AbsoluteHeading, FacingRelation, RelativeHeading
from synth.parts.motion import AbsoluteSpeed, MovingLike, RelativeSpeed, Stationary
from synth.parts.position import DIRECTIONS, AbsoluteXYPos, DirectionPos, LocalXYPos
from synth.scene import EGO_ID, ENTITY_TYPES, SceneError, check_identifier
from synth.syntax import BLANKS, DslError, Line, Range, fmt_number, lines

Position = Union[DirectionPos, LocalXYPos, AbsoluteXYPos]
Heading = Union[FacingRelation, RelativeHeading, AbsoluteHeading]
Motion = Union[Stationary, MovingLike, RelativeSpeed, AbsoluteSpeed]


@dataclass(frozen=True, init=False)
class Statement:
    """`ID = new TYPE` and one clause per part it carries, read by the part's name (st.position, st.heading,
    st.motion: None where the statement has no such clause; static programs, the paper's, have no motion)."""

    id: str
    type: str
    parts: tuple[tuple[str, Clause], ...]  # (part name, clause), in the registry's order

    def __init__(self, id: str, type: str, position: Position | None = None, heading: Heading | None = None,
                 motion: Motion | None = None, parts: tuple[tuple[str, Clause], ...] = (), **more: Clause | None):
        # `parts` (what dataclasses.replace passes on), then the clauses named here.
        given = dict(parts)
        named = {"position": position, "heading": heading, "motion": motion, **more}
        given.update({n: c for n, c in named.items() if c is not None})
        order = {p.name: k for k, p in enumerate(all_parts())}
        unknown = sorted(set(given) - set(order))
        if unknown:
            raise TypeError(f"Statement: no part named {unknown[0]!r}")
        # A program's statement carries every required part (the parser and Alg. 4 see to it); a pattern's may
        # leave one out, which means "any" (synth.patterns.one_frame).
        object.__setattr__(self, "id", id)
        object.__setattr__(self, "type", type)
        object.__setattr__(self, "parts", tuple(sorted(((n, c) for n, c in given.items() if c is not None),
                                                       key=lambda nc: order[nc[0]])))

    def __getattr__(self, name: str) -> Clause | None:
        # Only reached for names that are not attributes: a registered part's name reads its clause.
        if name.startswith("_") or name == "parts":
            raise AttributeError(name)
        clause = next((c for n, c in self.parts if n == name), None)
        if clause is None and all(p.name != name for p in all_parts()):
            raise AttributeError(f"'Statement' object has no attribute {name!r}")
        return clause

    def clauses(self) -> Iterator[tuple[Part, Clause]]:
        """(part, clause) for every part the statement carries, in statement order."""
        for name, clause in self.parts:
            yield part_named(name), clause

    @property
    def cost(self) -> int:
        return sum(c.cost for _, c in self.clauses())

    def __str__(self) -> str:
        return " ".join(filter(None, (f"{self.id} = new {self.type}", ", ".join(str(c) for _, c in self.clauses()))))


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


# The most statements a program has: one an entity, and a scene has at most 1,000 by default (r2s check; synthesis
# of ten times as many would not end). The bound keeps what a program file can cost to parse (about 100 us a
# statement: 1 s at the bound) far from the 100 s that 64 MB of statements take (docs/cli.md, "Inputs and their
# bounds").
MAX_STATEMENTS = 10_000


def parse_statements(text: str, types: Collection[str], reader=None, first_line: int = 1) -> tuple[Statement, ...]:
    """The statements of DSL text whose TYPEs are drawn from `types` (programs: the entity types; patterns,
    synth.patterns.one_frame, add their type classes and read their lines with their own `reader`, called as _statement
    is). Errors name the line (the text's first is `first_line`) and column."""
    declared: set[str] = set()
    statements = []
    for lineno, raw in enumerate(lines(text, first_line), start=first_line):
        line = raw.split("#", 1)[0]
        if not line.strip(BLANKS):
            continue
        if len(statements) == MAX_STATEMENTS:
            raise DslError(f"line {lineno}: statement {MAX_STATEMENTS + 1:,}, more than the bound of "
                           f"{MAX_STATEMENTS:,} (docs/cli.md, Inputs and their bounds)")
        st = (reader or _statement)(Line(line, lineno), declared, types)
        if st.id != EGO_ID:  # a pattern's line about ego (synth.patterns.one_frame) declares nothing
            declared.add(st.id)
        statements.append(st)
    return tuple(statements)


def statement_head(ln: Line, declared: set[str], types: Collection[str]) -> tuple[str, str]:
    """`ID = new TYPE`: the declared name (an identifier, not ego, not declared before) and its type."""
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
    return name, etype


def _statement(ln: Line, declared: set[str], types: Collection[str]) -> Statement:
    name, etype = statement_head(ln, declared, types)
    clauses = {}
    parts = all_parts()
    for k, part in enumerate(p for p in parts if not p.optional):
        if k:
            ln.take(text=",")
        clauses[part.name] = part.parse(ln, declared)
    optional = [p for p in parts if p.optional]
    while optional and ln.accept(","):
        # The first optional part that begins here; with none, the only one left says what it expected.
        k = next((k for k, p in enumerate(optional) if p.starts(ln)), None)
        if k is None and len(optional) > 1:
            raise DslError(f"{ln.where()}: expected one of: {', '.join(sorted(w for p in optional for w in p.first_words))}")
        part, optional = optional[k or 0], optional[(k or 0) + 1:]
        clauses[part.name] = part.parse(ln, declared)
    ln.end()
    return Statement(name, etype, **clauses)


__all__ = [
    "DIRECTIONS", "FACINGS", "AbsoluteHeading", "AbsoluteSpeed", "AbsoluteXYPos", "DirectionPos", "DslError",
    "FacingRelation", "Heading", "LocalXYPos", "Motion", "MovingLike", "Position", "Program", "Range",
    "RelativeHeading", "RelativeSpeed", "Stationary", "Statement", "fmt_number",
    "format_program", "parse_program", "parse_statements", "statement_head",
]
