"""The two shapes every statement part is made of: its clause kinds (Clause) and what they share (Part).

A statement `ID = new TYPE POS, HEADING [, MOTION]` is a sequence of parts. A part has a few witness relations,
which cost 0 and name a reference (or, for some parts, need none), a fallback relative to ego (cost 1) and an
absolute form (cost 2). Each form of its grammar is a clause kind: a class (Clause) that owns what a clause means
(text, cost, report kind, semantics, exact test, SMT formulas, Scenic value, what the sampler draws). The part
holds what its clauses share, in small interfaces the core asks one at a time:

  Relations (its relation table)    relations, refless, disjoint, codes_from, perturbed, closed_form,
                                    robust_closed_form, exact, robust_exact, relation, robust_relation,
                                    any_relation, ask
                                        -> relations, oracle, robust, search (c(e, E) sums over parts)
  Measured (synth.smt.backend)      exact_measure, measure_terms, solver_measure  -> smt (Range values)
  Part                              quantity, float_measure, clause, robust_clause  -> statement (Alg. 4)
                                    window_fallback_cost, merged                   -> window (a clip's program)
                                    parse, optional, starts                        -> dsl (the grammar)
                                    keyword, scenic_prelude                        -> emit_scenic
                                    clauses, clause_kinds, kinds                   -> the report, the pictures
                                    enabled                                        -> which parts a config uses

The SMT methods take the backend as an argument and build formulas from its primitives (synth.smt.backend), so
one encoding serves z3 and dReal. relation and solver_measure get any backend; the robust, certification and
model questions get the exact one (z3). A new part registers in synth.parts (docs/layout.md has the recipes).
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from synth.config import SynthConfig
from synth.perturbation import Bounds, bounds_of
from synth.scene import Entity, Scene
from synth.smt.backend import ExactBackend, Formula, Measured, SolverBackend
from synth.syntax import DslError, Line, Range
from synth.tables import SceneArrays

if TYPE_CHECKING:
    from synth.draws import Draws


class Relations(ABC):
    """A part's witness relations (code = index into `relations`), decided for every pair of a scene at once in
    floats, exactly for one pair, and by a solver, plainly or for every perturbation."""

    name: ClassVar[str]  # the part's name: a Statement's field (st.position), the relation table's key
    relations: ClassVar[tuple[str, ...]]  # witness relations (cost 0); code = index
    # Codes that need no reference: always available, like ego, so they are recorded in ego's row (index 0).
    refless: ClassVar[frozenset[int]] = frozenset()
    # Can two of its relations hold of one pair at once? The paper's parts' cannot (sectors 90 degrees apart,
    # toward / away from); where they can (lanes: a lane where two merge is on both their chains), the table
    # records the first and a window asks for the others (RelationOracle.holds).
    disjoint: ClassVar[bool] = True

    def codes_from(self, ref_is_ego: bool) -> tuple[int, ...]:
        """The codes that may hold with a reference (refless codes only in ego's row), asked in this order."""
        return tuple(c for c in range(len(self.relations)) if ref_is_ego or c not in self.refless)

    @abstractmethod
    def perturbed(self, b: Bounds) -> bool:
        """Does an entity with these measurement bounds make this part's questions robust ones?"""

    def is_robust(self, scene: Scene, config: SynthConfig) -> bool:
        return any(self.perturbed(bounds_of(e, config)) for e in scene.entities)

    def pair_is_robust(self, a: Entity, b: Entity, config: SynthConfig) -> bool:
        return self.perturbed(bounds_of(a, config)) or self.perturbed(bounds_of(b, config))

    # ------------------------------------------------------------------------------- floats, exact
    @abstractmethod
    def closed_form(self, arrays: SceneArrays, config: SynthConfig) -> np.ndarray:
        """codes[r, e] (int8) of every pair by floats: a code, NONE, or UNDECIDED inside the guard band."""

    @abstractmethod
    def robust_closed_form(self, arrays: SceneArrays, bounds: list[Bounds], config: SynthConfig) -> np.ndarray:
        """The same for the robust question (does the relation hold for every perturbation within bounds)."""

    @abstractmethod
    def exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool:
        """Does relation `code` hold, decided in exact rational arithmetic (what the solver encodes too)?"""

    def robust_exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool | None:
        """Does relation `code` hold for every perturbation, decided without a solver; None where only a solver
        can tell (the closed-form oracle then claims nothing). The paper's parts: None; the lane part's questions
        are lookups."""
        return None

    # ------------------------------------------------------------------------------- SMT
    @abstractmethod
    def relation(self, backend: SolverBackend, code: int, ref: Entity, e: Entity) -> bool:
        """The solver's answer to: does relation `code` (with some Range, where it has one) hold?"""

    @abstractmethod
    def robust_relation(self, backend: ExactBackend, code: int, ref: Entity, e: Entity) -> bool:
        """The solver's answer to: does it hold for every perturbation (is its violation unsat)?"""

    @abstractmethod
    def any_relation(self, backend: ExactBackend, ref: Entity, e: Entity) -> Formula:
        """A formula true iff some witness relation of e with ref holds (the monolithic baseline)."""

    def ask(self, backend: SolverBackend, code: int, ref: Entity, e: Entity) -> bool:
        """The oracle's question: does relation `code` hold between ref and e (for every perturbation, where
        either is uncertain)?"""
        if self.pair_is_robust(ref, e, backend.config):
            return self.robust_relation(backend.exact, code, ref, e)
        return self.relation(backend, code, ref, e)

    def ask_named(self, backend: SolverBackend, relation: str, ref: Entity, e: Entity) -> bool:
        """ask() by the relation's name (`POSITION.ask_named(backend, "ahead", ref, e)`: tests and tools)."""
        return self.ask(backend, self.relations.index(relation), ref, e)


class Part(Relations, Measured):
    """A statement part: its clause kinds, its relation table, Alg. 4's choice of clause, its grammar."""

    keyword: ClassVar[str]  # the Scenic specifier its clause becomes (at, facing, with speed)
    clauses: ClassVar[tuple[type[Clause], ...]]  # its clause kinds, grammar order
    # An optional part follows the required ones, after a comma, and is recognised by its first word (starts).
    optional: ClassVar[bool] = False

    def enabled(self, config: SynthConfig) -> bool:
        """Does a statement carry this part under the config (motion: with --motion)?"""
        return True

    @property
    def clause_kinds(self) -> tuple[ClauseKind, ...]:
        """Every kind of clause the part has, grammar order: the one classification the report, its plots and
        the pictures read (labels, costs, how a picture draws it)."""
        return tuple(k for c in self.clauses for k in c.kinds())

    @property
    def kinds(self) -> tuple[str, ...]:
        """The report labels of the part's relation kinds, grammar order."""
        return tuple(k.label for k in self.clause_kinds)

    # ------------------------------------------------------------------------------- Range values
    def exact_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...] | None:
        return None

    def solver_measure(self, backend: SolverBackend, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        return self.float_measure(quantity, target, ref)

    # ------------------------------------------------------------------------------- Alg. 4
    @abstractmethod
    def quantity(self, code: int) -> str | None:
        """What the clause written for `code` (NONE: the fallback) centres its Ranges on; None: it has none."""

    @abstractmethod
    def float_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        """The quantity from float geometry (the closed-form oracle)."""

    @abstractmethod
    def clause(self, code: int, ref_id: str, values: tuple[Fraction, ...], config: SynthConfig) -> Clause:
        """The clause of Alg. 4: relation `code` with ref, or the fallback (NONE), Ranges centred on values."""

    def clause_for(self, code: int, target: Entity, ref: Entity, values: tuple[Fraction, ...],
                   config: SynthConfig) -> Clause:
        """The clause Alg. 4 writes for `target` (what `clause` writes; a part whose fallback depends on the
        target itself, as the lane part's does, overrides it)."""
        return self.clause(code, ref.id, values, config)

    def fallback_cost(self, e: Entity, config: SynthConfig) -> int:
        """What the part costs for e without a witness (its fallback's cost; 1 for the paper's parts). The search
        weighs each part of each entity by it (synth.search.costs)."""
        return 1

    @abstractmethod
    def robust_clause(self, code: int, target: Entity, ref: Entity, config: SynthConfig) -> Clause:
        """The same with Ranges that cover every perturbation (robust synthesis)."""

    # ------------------------------------------------------------------------------- windows (synth.window.program)
    def window_fallback_cost(self, frames: Sequence[Entity], config: SynthConfig) -> int:
        """What the part costs for an entity without a window witness, `frames` its poses in the frames of the
        window it is in: the cost of the clause `merged` then writes. By default the most a frame's fallback costs
        (the paper's parts: 1, as their fallback is one form whose Ranges widen)."""
        return max(self.fallback_cost(e, config) for e in frames)

    def merged(self, clauses: Sequence[Clause], frames: Sequence[Entity], config: SynthConfig) -> Clause:
        """The window's clause of an entity: from the clause Alg. 4 wrote in each frame it is in (with the window's
        reference and relation) and its poses there, one clause that holds in each of those frames. By default the
        clauses widened into one (Clause.widened: the same form, each Range the hull of the frames' Ranges); a
        part whose fallback depends on where the entity is (lanes) overrides it."""
        out = clauses[0]
        for clause in clauses[1:]:
            wider = out.widened(clause)
            if wider is None:
                raise AssertionError(f"frames disagree on a {self.name} clause ({out}, {clause})")
            out = wider
        return out

    # ------------------------------------------------------------------------------- syntax, Scenic
    def parse(self, ln: Line, declared: set[str]) -> Clause:
        """The clause at the line's cursor (printing is the clause's own: Clause.text). By default each clause
        kind is asked in turn (Clause.read); a part whose forms share their first words parses them itself."""
        for kind in self.clauses:
            if (clause := kind.read(ln, declared)) is not None:
                return clause
        found = ln.peek()
        raise DslError(f"{ln.where()}: expected a {self.name} clause ({', '.join(sorted(self.first_words))}), "
                       f"found {'end of line' if found is None else repr(found)}")

    @property
    def first_words(self) -> frozenset[str]:
        """The words its clauses begin with (Clause.first_word)."""
        return frozenset(k.first_word for k in self.clauses if k.first_word is not None)

    def starts(self, ln: Line) -> bool:
        """Does an optional part's clause begin at the line's cursor?"""
        return ln.peek() in self.first_words

    def scenic_prelude(self, config: SynthConfig) -> str:
        """Helpers the part's Scenic values use beyond the paper's prelude (written once, with its first clause)."""
        return ""


@dataclass(frozen=True)
class ClauseKind:
    """One kind of clause, as the report counts it and a picture draws it: a clause class, narrowed to one value of
    a field where the class holds several kinds (the four directions, the two facings)."""

    label: str  # the report's name (relation_usage, docs/formats.md)
    clause: type  # the clause dataclass; its `cost` is the kind's
    drawn_as: str  # pipeline.variants.render: an arrow from the reference, or a mark on the entity (no reference)
    field: tuple[str, str] | None = None  # (clause field, value) that singles the kind out of its class

    @property
    def cost(self) -> int:
        return self.clause.cost

    def matches(self, clause: Clause) -> bool:
        return type(clause) is self.clause and (self.field is None or getattr(clause, self.field[0]) == self.field[1])


class Clause(ABC):
    """A clause kind: one form of a part's grammar, a frozen dataclass of its fields (`ref`: its reference, None
    for the forms without one), that knows everything the core asks of a clause. Subclasses declare their fields,
    `cost`, `text` and the report's `labels`, and implement the abstract methods.

      text         the DSL text, str.format'ed with the clause as `c` (printing; read or the part's parse reads it)
      holds        the paper's semantics read literally, in floats (the independent checker, synth.semantics)
      observed     what the checker reports of e when the clause does not hold
      decide       formula(), decided rigorously without a solver (None: the solver must)
      formula      the semantics as an SMT formula, Range bounds at their printed values (certification)
      violations   ways the clause could fail under a perturbation within the bounds: each must be unsat
      scenic       the Scenic value of the part's specifier (Part.keyword); `at` names the entity's position
      draws        what Scenic draws for it (synth.draws: the sampler's parameters)
      labels       the report's kinds: one, or one per value of the field `label_field` (four directions)
    """

    cost: ClassVar[int]
    text: ClassVar[str]
    labels: ClassVar[tuple[str, ...]]
    label_field: ClassVar[str | None] = None
    drawn_as: ClassVar[str]  # pipeline.variants.render: an arrow from the reference, or a mark on the entity
    first_word: ClassVar[str | None] = None  # the word its text begins with (how an optional part is recognised)
    ref: str | None  # a dataclass field, or a class attribute None where the form has no reference
    # (ref is never given a value here: dataclass would take it as every subclass's default)

    def __str__(self) -> str:
        return self.text.format(c=self)

    @property
    def kind(self) -> str:
        """The report label of this clause (one of its class's labels)."""
        return self.labels[0] if self.label_field is None else getattr(self, self.label_field)

    @classmethod
    def read(cls, ln: Line, declared: set[str]) -> Clause | None:
        """The clause at the line's cursor if it is of this kind, else None with nothing taken (what Part.parse
        asks by default; `declared` are the ids a reference may name)."""
        return None

    @classmethod
    def kinds(cls) -> tuple[ClauseKind, ...]:
        """The report's classification of this class: one kind, or one per value of label_field."""
        if cls.label_field is None:
            return (ClauseKind(cls.labels[0], cls, cls.drawn_as),)
        return tuple(ClauseKind(label, cls, cls.drawn_as, (cls.label_field, label)) for label in cls.labels)

    # ------------------------------------------------------------------------------- windows
    def widened(self, other: Clause) -> Clause | None:
        """The clause a window writes for two of its frames' clauses (synth.window.program): the same form with each Range
        field the hull of both (every clause's semantics only grow with its Ranges, so it holds wherever either
        does); None where they differ in anything else (kind, reference, direction), which a window never joins."""
        if type(other) is not type(self):
            return None
        wider = {}
        for f in dataclasses.fields(self):
            mine, theirs = getattr(self, f.name), getattr(other, f.name)
            if isinstance(mine, Range):
                wider[f.name] = self.hull(mine, theirs)
            elif mine != theirs:
                return None
        return dataclasses.replace(self, **wider)

    def hull(self, mine: Range, theirs: Range) -> Range:
        """The least Range holding both (a Range of a quantity on a line; angles override it)."""
        return Range(min(mine.lo, theirs.lo), max(mine.hi, theirs.hi))

    # ------------------------------------------------------------------------------- semantics
    @abstractmethod
    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        """The paper's semantics read literally, in floats (independent of the oracles)."""

    @abstractmethod
    def observed(self, e: Entity) -> str:
        """What the checker reports of e when the clause does not hold."""

    # ------------------------------------------------------------------------------- exact
    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        """formula(), decided rigorously without the solver (synth.intervals; exact rationals where cheap):
        True / False, or None where it cannot tell and the solver must."""
        return None

    @abstractmethod
    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Formula:
        """The clause's semantics on the scene, Range bounds at their printed values (certification)."""

    @abstractmethod
    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Formula]:
        """Ways the clause could fail under a perturbation within the bounds: each must be unsat."""

    # ------------------------------------------------------------------------------- Scenic
    @abstractmethod
    def scenic(self, at: str) -> str:
        """The Scenic value of its part's specifier (Part.keyword); `at` names the entity's own position."""

    def needs_own_position(self) -> bool:
        """Does the Scenic value refer to the entity's own position (which a specifier cannot name)?"""
        return False

    def scenic_requirements(self, entity: str) -> list[str]:
        """Scenic `require` lines that keep sampled values inside the clause where a value alone cannot."""
        return []

    # ------------------------------------------------------------------------------- sampler
    @abstractmethod
    def draws(self, config: SynthConfig) -> Draws:
        """What Scenic draws for the clause, in its own parameterisation (synth.draws)."""
