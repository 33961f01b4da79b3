"""The DSL's lexical layer: Ranges, printed numbers, tokens and references, shared by every statement part.

Statement parts (synth.parts) print and parse their own clauses with these pieces; synth.dsl assembles them
into statements and programs. Nothing here knows what a clause means.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from fractions import Fraction
from typing import NamedTuple

from synth.errors import InputError
from synth.scene import EGO_ID


class DslError(InputError, ValueError):
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


def fmt_number(v: float) -> str:
    """At most two decimals, no trailing zeros, never '-0'."""
    s = f"{v:.2f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def printed(v: float) -> Fraction:
    """The exact value a Range bound has once printed: certification is about the text users get."""
    return Fraction(fmt_number(v))


# The DSL is ASCII: digits are 0-9 (not Arabic-Indic or full-width digits, which \d and float() would read as
# numbers), blanks are spaces and tabs, and a line ends at \n, \r\n or \r only (str.splitlines would also end one
# at U+2028, U+0085, a form feed...). A string (a lane id) is printable ASCII in double quotes, without a quote or a
# backslash or a # (which begins a comment). Any other character is "unexpected", with its line and column.
# One scan of the line reads every token in turn: blanks are skipped, and `bad` (any one character) is the
# unexpected one, so the matches tile the line and finditer never looks back (linear in the line).
_TOKEN = re.compile(
    r"(?P<num>[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)|(?P<word>[A-Za-z_][A-Za-z0-9_]*)|(?P<punct>[(),@=/])"
    r'|(?P<str>"[ !$-\[\]-~]*")|[ \t]+|(?P<bad>.)',
    re.ASCII | re.DOTALL,
)
_LINE_END = re.compile(r"\r\n|\r|\n")
BLANKS = " \t"
# The longest line of DSL text (programs, patterns), in characters. A statement r2sgen writes is a few hundred
# (five clauses, a lane id of at most 256 characters); the bound keeps what one line can cost small before a
# token is read (docs/cli.md, "Inputs and their bounds").
MAX_LINE = 10_000


def lines(text: str, first_line: int = 1) -> list[str]:
    """The lines of DSL text (see _TOKEN), each at most MAX_LINE characters (errors number them from
    `first_line`)."""
    out = _LINE_END.split(text)
    for lineno, line in enumerate(out, start=first_line):
        if len(line) > MAX_LINE:
            raise DslError(f"line {lineno}: {len(line)} characters, more than the {MAX_LINE} a line may have "
                           "(one statement a line)")
    return out


class _Tok(NamedTuple):
    kind: str
    text: str
    col: int


def _tokens(line: str, lineno: int) -> list[_Tok]:
    out = []
    for m in _TOKEN.finditer(line):
        kind = m.lastgroup
        if kind == "bad":
            raise DslError(f"line {lineno} column {m.start() + 1}: unexpected character {m.group()!r}")
        if kind is not None:  # else blanks
            out.append(_Tok(kind, m.group(), m.start() + 1))
    return out


class Line:
    """The tokens of one statement line, read left to right; every failure is a DslError naming the column."""

    def __init__(self, text: str, lineno: int):
        self.toks = _tokens(text, lineno)
        self.i = 0
        self.lineno = lineno

    def where(self, back: int = 0) -> str:
        """Where the next token is (back=1: the token just taken)."""
        i = self.i - back
        col = self.toks[i].col if i < len(self.toks) else (self.toks[-1].col + len(self.toks[-1].text) if self.toks else 1)
        return f"line {self.lineno} column {col}"

    def peek(self) -> str | None:
        return self.toks[self.i].text if self.i < len(self.toks) else None

    def take(self, kind: str | None = None, text: str | None = None) -> str:
        if self.i >= len(self.toks):
            raise DslError(f"{self.where()}: expected {text or kind}, found end of line")
        t = self.toks[self.i]
        if (kind and t.kind != kind) or (text and t.text != text):
            raise DslError(f"{self.where()}: expected {text or kind}, found {t.text!r}")
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
            raise DslError(f"{self.where()}: number out of range")
        return v

    def range_(self) -> Range:
        start = self.where()
        self.take(text="Range")
        self.take(text="(")
        lo = self.number()
        self.take(text=",")
        hi = self.number()
        self.take(text=")")
        if lo > hi:
            raise DslError(f"{start}: Range({fmt_number(lo)}, {fmt_number(hi)}) is empty")
        return Range(lo, hi)

    def reference(self, declared: set[str]) -> str:
        """REF: ego or an entity declared on an earlier line (scoping is part of the grammar)."""
        name = self.take("word")
        if name != EGO_ID and name not in declared:
            raise DslError(f"{self.where(back=1)}: reference {name!r} is neither ego nor declared earlier")
        return name

    def end(self) -> None:
        if self.i != len(self.toks):
            raise DslError(f"{self.where()}: unexpected {self.toks[self.i].text!r} after the statement")
