"""The paper's DSL (Fig. 3): abstract syntax, cost, printer and parser, which round-trip exactly.

    P       ::= S*
    S       ::= ID = new TYPE POS, HEADING
    POS     ::= (ahead of | behind | left of | right of) REF by Range(a, b)      cost 0
              | on Range(a, b) @ Range(c, d) relative to REF                    cost 1
              | on Range(a, b) @ Range(c, d)                                    cost 2
    HEADING ::= facing (toward | away from) REF                                 cost 0
              | facing Range(a, b) deg relative to REF                          cost 1
              | facing Range(a, b) deg                                          cost 2
    REF     ::= ego | an ID declared earlier
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection, Iterator
from dataclasses import dataclass
from typing import Union

from synth.scene import EGO_ID, ENTITY_TYPES, SceneError, check_identifier

# Direction -> (printed words, phi in degrees, counter-clockwise from the reference's heading).
DIRECTIONS: dict[str, tuple[str, float]] = {
    "ahead": ("ahead of", 0.0),
    "left": ("left of", 90.0),
    "behind": ("behind", 180.0),
    "right": ("right of", 270.0),
}
FACINGS: dict[str, str] = {"toward": "toward", "away": "away from"}


class DslError(ValueError):
    """A program text that is not in the DSL. One line, with its position."""


@dataclass(frozen=True)
class Range:
    lo: float
    hi: float

    def __post_init__(self) -> None:
        if not (math.isfinite(self.lo) and math.isfinite(self.hi)):
            raise DslError(f"Range bounds must be finite, got ({self.lo}, {self.hi})")
        if self.lo > self.hi:
            raise DslError(f"Range({fmt_number(self.lo)}, {fmt_number(self.hi)}) is empty")

    def contains(self, v: float, eps: float = 0.0) -> bool:
        return self.lo - eps <= v <= self.hi + eps

    def __str__(self) -> str:
        return f"Range({fmt_number(self.lo)}, {fmt_number(self.hi)})"


@dataclass(frozen=True)
class DirectionPos:
    """`ahead of | behind | left of | right of REF by Range`: cost 0."""

    direction: str
    ref: str
    distance: Range
    cost = 0

    def __str__(self) -> str:
        return f"{DIRECTIONS[self.direction][0]} {self.ref} by {self.distance}"


@dataclass(frozen=True)
class LocalXYPos:
    """`on Range @ Range relative to REF`: lateral @ forward in REF's frame, cost 1."""

    lateral: Range
    forward: Range
    ref: str
    cost = 1

    def __str__(self) -> str:
        return f"on {self.lateral} @ {self.forward} relative to {self.ref}"


@dataclass(frozen=True)
class AbsoluteXYPos:
    """`on Range @ Range`: x @ y in the scene frame, cost 2."""

    x: Range
    y: Range
    cost = 2
    ref = None

    def __str__(self) -> str:
        return f"on {self.x} @ {self.y}"


@dataclass(frozen=True)
class FacingRelation:
    """`facing toward | away from REF`: cost 0."""

    mode: str
    ref: str
    cost = 0

    def __str__(self) -> str:
        return f"facing {FACINGS[self.mode]} {self.ref}"


@dataclass(frozen=True)
class RelativeHeading:
    """`facing Range deg relative to REF`: cost 1."""

    angle: Range
    ref: str
    cost = 1

    def __str__(self) -> str:
        return f"facing {self.angle} deg relative to {self.ref}"


@dataclass(frozen=True)
class AbsoluteHeading:
    """`facing Range deg`: cost 2."""

    angle: Range
    cost = 2
    ref = None

    def __str__(self) -> str:
        return f"facing {self.angle} deg"


Position = Union[DirectionPos, LocalXYPos, AbsoluteXYPos]
Heading = Union[FacingRelation, RelativeHeading, AbsoluteHeading]


@dataclass(frozen=True)
class Statement:
    id: str
    type: str
    position: Position
    heading: Heading

    @property
    def cost(self) -> int:
        return self.position.cost + self.heading.cost

    def __str__(self) -> str:
        return f"{self.id} = new {self.type} {self.position}, {self.heading}"


@dataclass(frozen=True)
class Program:
    statements: tuple[Statement, ...]

    @property
    def cost(self) -> int:
        return sum(s.cost for s in self.statements)

    def __str__(self) -> str:
        return "".join(f"{s}\n" for s in self.statements)


def fmt_number(v: float) -> str:
    """At most two decimals, no trailing zeros, never '-0'."""
    s = f"{v:.2f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def format_program(program: Program) -> str:
    return str(program)


# ---------------------------------------------------------------------------------------------- parser

_TOKEN = re.compile(
    r"\s*(?:(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<word>[A-Za-z_][A-Za-z0-9_]*)|(?P<punct>[(),@=]))"
)


@dataclass(frozen=True)
class _Tok:
    kind: str
    text: str
    col: int


def _tokens(line: str, lineno: int) -> list[_Tok]:
    out, pos = [], 0
    while pos < len(line):
        if line[pos:].strip() == "":
            break
        m = _TOKEN.match(line, pos)
        if not m or m.end() == pos:
            raise DslError(f"line {lineno} column {pos + 1}: unexpected character {line[pos:].lstrip()[:1]!r}")
        kind = m.lastgroup or "?"
        out.append(_Tok(kind, m.group(kind), m.start(kind) + 1))
        pos = m.end()
    return out


class _Line:
    def __init__(self, text: str, lineno: int):
        self.toks = _tokens(text, lineno)
        self.i = 0
        self.lineno = lineno

    def _where(self, back: int = 0) -> str:
        """Where the next token is (back=1: the token just taken)."""
        i = self.i - back
        col = self.toks[i].col if i < len(self.toks) else (self.toks[-1].col + len(self.toks[-1].text) if self.toks else 1)
        return f"line {self.lineno} column {col}"

    def peek(self) -> str | None:
        return self.toks[self.i].text if self.i < len(self.toks) else None

    def take(self, kind: str | None = None, text: str | None = None) -> str:
        if self.i >= len(self.toks):
            raise DslError(f"{self._where()}: expected {text or kind}, found end of line")
        t = self.toks[self.i]
        if (kind and t.kind != kind) or (text and t.text != text):
            raise DslError(f"{self._where()}: expected {text or kind}, found {t.text!r}")
        self.i += 1
        return t.text

    def accept(self, text: str) -> bool:
        if self.peek() == text:
            self.i += 1
            return True
        return False

    def number(self) -> float:
        v = float(self.take("num"))
        if not math.isfinite(v):
            raise DslError(f"{self._where()}: number out of range")
        return v

    def range_(self) -> Range:
        start = self._where()
        self.take(text="Range")
        self.take(text="(")
        lo = self.number()
        self.take(text=",")
        hi = self.number()
        self.take(text=")")
        if lo > hi:
            raise DslError(f"{start}: Range({fmt_number(lo)}, {fmt_number(hi)}) is empty")
        return Range(lo, hi)

    def end(self) -> None:
        if self.i != len(self.toks):
            raise DslError(f"{self._where()}: unexpected {self.toks[self.i].text!r} after the statement")


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
        st = _statement(_Line(line, lineno), declared, types)
        declared.add(st.id)
        statements.append(st)
    return tuple(statements)


def _ref(ln: _Line, declared: set[str]) -> str:
    name = ln.take("word")
    if name != EGO_ID and name not in declared:
        raise DslError(f"{ln._where(back=1)}: reference {name!r} is neither ego nor declared earlier")
    return name


def _statement(ln: _Line, declared: set[str], types: Collection[str]) -> Statement:
    name = ln.take("word")
    try:
        check_identifier(name)
    except SceneError as exc:
        raise DslError(f"{ln._where(back=1)}: {exc}") from None
    if name == EGO_ID:
        raise DslError(f"{ln._where(back=1)}: ego is given by the scene and is never declared")
    if name in declared:
        raise DslError(f"{ln._where(back=1)}: {name!r} is declared twice")
    ln.take(text="=")
    ln.take(text="new")
    etype = ln.take("word")
    if etype not in types:
        raise DslError(f"{ln._where(back=1)}: unknown type {etype!r}")
    position = _position(ln, declared)
    ln.take(text=",")
    heading = _heading(ln, declared)
    ln.end()
    return Statement(name, etype, position, heading)


def _position(ln: _Line, declared: set[str]) -> Position:
    word = ln.peek()
    if word in ("ahead", "left", "right"):
        ln.take()
        ln.take(text="of")
    elif word == "behind":
        ln.take()
    elif word == "on":
        ln.take()
        first = ln.range_()
        ln.take(text="@")
        second = ln.range_()
        if ln.accept("relative"):
            ln.take(text="to")
            return LocalXYPos(first, second, _ref(ln, declared))
        return AbsoluteXYPos(first, second)
    else:
        raise DslError(f"{ln._where()}: expected a position (ahead of, behind, left of, right of, on), found {word!r}")
    ref = _ref(ln, declared)
    ln.take(text="by")
    return DirectionPos(word, ref, ln.range_())


def _heading(ln: _Line, declared: set[str]) -> Heading:
    ln.take(text="facing")
    if ln.accept("toward"):
        return FacingRelation("toward", _ref(ln, declared))
    if ln.accept("away"):
        ln.take(text="from")
        return FacingRelation("away", _ref(ln, declared))
    angle = ln.range_()
    ln.take(text="deg")
    if ln.accept("relative"):
        ln.take(text="to")
        return RelativeHeading(angle, _ref(ln, declared))
    return AbsoluteHeading(angle)


def iter_references(program: Program) -> Iterator[tuple[str, str, str]]:
    """(entity, 'position' | 'heading', reference) for every reference a program makes."""
    for s in program.statements:
        if s.position.ref is not None:
            yield (s.id, "position", s.position.ref)
        if s.heading.ref is not None:
            yield (s.id, "heading", s.heading.ref)
