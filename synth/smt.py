"""SMT backends: relation queries, exact Range values, and certification of whole programs.

Encoding (no atan2, no trigonometry in the formula): with v the offset between the two entities and u the
unit vector of the axis the relation names, "v within delta of u" is
    v.u > 0  and  (v.u)^2 >= cos^2(delta) |v|^2
over the exact rationals of the scene's floats. u and cos(delta) are the rationals of their correctly
rounded floats, the same constants the closed form uses (synth.geometry), so the two oracles answer the
same question. A distance Range [a, b] is encoded with d >= 0, d^2 = |v|^2, a <= d <= b: nonlinear real
arithmetic, exact in z3 (nlsat). dReal (optional) gets the same formula over doubles, delta-complete.

The backends own the solver and its primitives (q, var, offset, cone, distance_in, angle_in, check, ...); each
statement part (synth.parts) builds its formulas from them, so a backend knows no relation by name.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property
from typing import Any

from synth.config import SynthConfig
from synth.dsl import Program, Statement
from synth.geometry import exact_cos_squared, exact_heading_vector
from synth.parts import HEADING, POSITION, MeasureRequest, Part
from synth.parts.heading import FACING_NAMES
from synth.parts.position import DIRECTION_NAMES
from synth.robust import robust_parts
from synth.scene import Entity, Scene


class SolverUnavailable(RuntimeError):
    """The chosen solver cannot be loaded here. One line, fit for a user."""


@dataclass
class SolverStats:
    queries: int = 0
    seconds: float = 0.0


# What a backend measures for a program: per statement, per wanted quantity, its exact values.
Measurements = list[tuple[tuple[Fraction, ...], ...]]


def _frac(v: float | str | Fraction) -> Fraction:
    return v if isinstance(v, Fraction) else Fraction(v)


def make_backend(config: SynthConfig) -> Z3Backend | DrealBackend:
    if config.solver == "dreal":
        return DrealBackend(config)
    return Z3Backend(config)


def _statement_refs(st: Statement, by_id: dict[str, Entity]) -> list[tuple[Part, Any, Entity | None]]:
    return [(part, clause, by_id[clause.ref] if clause.ref is not None else None) for part, clause in st.clauses()]


class _ByName:
    """The paper's two relation questions by name (tests and tools ask them so)."""

    def relation(self, part: Part, code: int, ref: Entity, e: Entity) -> bool:
        raise NotImplementedError

    def position_relation(self, direction: str, ref: Entity, e: Entity) -> bool:
        return self.relation(POSITION, DIRECTION_NAMES.index(direction), ref, e)

    def heading_relation(self, mode: str, ref: Entity, e: Entity) -> bool:
        return self.relation(HEADING, FACING_NAMES.index(mode), ref, e)


@dataclass
class Z3Backend(_ByName):
    config: SynthConfig
    stats: SolverStats = field(default_factory=SolverStats)

    def __post_init__(self) -> None:
        try:
            import z3
        except ImportError as exc:  # pragma: no cover - z3 is a core dependency
            raise SolverUnavailable(f"z3 is not installed ({exc}); pip install z3-solver") from None
        self.z3 = z3
        self.And, self.Or, self.Not, self.BoolVal = z3.And, z3.Or, z3.Not, z3.BoolVal
        self._fresh = 0

    # One solver per frame (this backend's), reused with push / pop, and made only when a question needs it:
    # with the default oracle most frames ask none.
    @cached_property
    def _solver(self) -> Any:
        return self.z3.SolverFor("QF_NRA")

    @cached_property
    def _nlsat(self) -> Any:
        return self.z3.Tactic("qfnra-nlsat")  # robust questions; see fresh_check

    # --------------------------------------------------------------------------------- building blocks
    def q(self, v: float | str | Fraction) -> Any:
        # RealVal from a "p/q" string is a single numeral; z3.Q builds a division and simplifies it (7x slower).
        f = _frac(v)
        return self.z3.RealVal(f"{f.numerator}/{f.denominator}")

    def var(self, stem: str) -> Any:
        self._fresh += 1
        return self.z3.Real(f"{stem}{self._fresh}")

    def offset(self, ref: Entity, e: Entity) -> tuple[Any, Any]:
        return self.q(_frac(e.x) - _frac(ref.x)), self.q(_frac(e.y) - _frac(ref.y))

    def cone(self, vx: Any, vy: Any, axis_heading: float, delta: float) -> Any:
        z3 = self.z3
        ux, uy = (self.q(c) for c in exact_heading_vector(axis_heading))
        dot = vx * ux + vy * uy
        return z3.And(dot > 0, dot * dot >= self.q(exact_cos_squared(delta)) * (vx * vx + vy * vy))

    def distance_in(self, vx: Any, vy: Any, lo: Any, hi: Any) -> Any:
        d = self.var("d")
        return self.z3.And(d >= 0, d * d == vx * vx + vy * vy, lo <= d, d <= hi)

    def angle_in(self, heading: float, base: float, lo: Fraction, hi: Fraction) -> Any:
        """heading = N(base + alpha) for some alpha in [lo, hi].

        The whole number of turns k is the certificate: with hi - lo < 360 at most one k can work, the one that
        puts heading - base - 360 k just above lo, so it is computed here and the solver decides the rest.
        """
        gap = _frac(heading) - _frac(base)
        k = (gap - lo) // 360
        alpha = gap - 360 * k
        return self.z3.And(self.q(lo) <= self.q(alpha), self.q(alpha) <= self.q(hi))

    def perturbed_offset(self, c: tuple[Fraction, Fraction], radius: Fraction) -> tuple[Any, Any, list[Any]]:
        """The offset c moved anywhere in the disc of the given radius: (vx, vy, the disc's constraints)."""
        vx, vy = self.q(c[0]), self.q(c[1])
        if radius == 0:
            return vx, vy, []
        wx, wy = self.var("wx"), self.var("wy")
        return vx + wx, vy + wy, [wx * wx + wy * wy <= self.q(radius * radius)]

    def cone_fails(self, vx: Any, vy: Any, cons: list[Any], axis: float, cone: float | None) -> Any:
        """Some v (under cons) outside the cone; no cone left at all (None) always fails."""
        return self.z3.BoolVal(True) if cone is None else self.z3.And(*cons, self.z3.Not(self.cone(vx, vy, axis, cone)))

    def check(self, *constraints: Any) -> bool:
        t = time.perf_counter()
        s = self._solver
        s.push()
        s.add(*constraints)
        result = s.check()
        s.pop()
        return self._verdict(result, s, t)

    def _verdict(self, result: Any, s: Any, started: float) -> bool:
        """Count one query and its time; sat -> True. unknown would be a guess either way: refuse it."""
        self.stats.queries += 1
        self.stats.seconds += time.perf_counter() - started
        if result == self.z3.unknown:
            raise RuntimeError(f"z3 returned unknown: {s.reason_unknown()}")
        return result == self.z3.sat

    def fresh_check(self, *constraints: Any) -> bool:
        """A quantified question's check on a fresh nlsat solver. z3's incremental (push/pop) solver does not run
        nlsat, and on these questions it can take seconds where nlsat takes milliseconds; the qfnra-nlsat tactic
        (complete for nonlinear real arithmetic) skips SolverFor's portfolio set-up, 3x faster again."""
        t = time.perf_counter()
        s = self._nlsat.solver()
        s.add(*constraints)
        return self._verdict(s.check(), s, t)

    def robust_cone(self, c: tuple[Fraction, Fraction], radius: Fraction, axis: float, cone: float | None) -> bool:
        """Does every v in the disc D(c, radius) lie within `cone` degrees of the axis (synth.perturbation)?

        The existentially quantified violation is asked: a v in the disc outside the cone. unsat = it holds.
        """
        if cone is None:
            return False
        cx, cy = self.q(c[0]), self.q(c[1])
        if radius == 0:
            return self.check(self.cone(cx, cy, axis, cone))
        wx, wy = self.var("wx"), self.var("wy")
        return not self.fresh_check(
            wx * wx + wy * wy <= self.q(radius * radius),
            self.z3.Not(self.cone(cx + wx, cy + wy, axis, cone)),
        )

    # ------------------------------------------------------------------------------------ relation queries
    def relation(self, part: Part, code: int, ref: Entity, e: Entity) -> bool:
        """Does part's relation `code` hold between ref and e (for every perturbation, where either is uncertain)?"""
        if part.pair_is_robust(ref, e, self.config):
            return part.robust_relation(self, code, ref, e)
        return part.relation(self, code, ref, e)

    # ------------------------------------------------------------------------------------ range values
    def measure(self, requests: list[MeasureRequest]) -> Measurements:
        """The exact quantities the Ranges of many statements are centred on.

        The paper's all-SMT mode (oracle smt) reads them all from one model of the solver; otherwise each part
        computes its ground quantities in exact arithmetic (Part.exact_measure), and only those it leaves go to
        the solver, from one model.
        """
        if self.config.oracle == "smt":
            return self._model_measure(requests)
        exact = [tuple(w.part.exact_measure(w.quantity, req.target, w.ref) for w in req.wants) for req in requests]
        left = [i for i, values in enumerate(exact) if any(v is None for v in values)]
        for i, values in zip(left, self._model_measure([requests[i] for i in left])):
            exact[i] = values
        return exact

    def _model_measure(self, requests: list[MeasureRequest]) -> Measurements:
        z3 = self.z3
        if not requests:
            return []
        t = time.perf_counter()
        cons, wanted = [], []
        for req in requests:
            slots = []
            for want in req.wants:
                c, variables = want.part.measure_terms(self, want.quantity, req.target, want.ref)
                cons += c
                slots.append(variables)
            wanted.append(slots)
        s = z3.SolverFor("QF_NRA")
        s.add(*cons)
        result = s.check()
        self.stats.queries += len(requests)
        if result != z3.sat:
            self.stats.seconds += time.perf_counter() - t
            raise RuntimeError(f"z3 found no values for the program's Ranges ({result})")
        m = s.model()
        out = [tuple(tuple(self._value(m, v) for v in variables) for variables in slots) for slots in wanted]
        self.stats.seconds += time.perf_counter() - t
        return out

    def _value(self, model: Any, var: Any) -> Fraction:
        v = model.eval(var, model_completion=True)
        if self.z3.is_algebraic_value(v):
            # An irrational distance: 12 decimals are far below the 0.01 printing resolution.
            v = v.approx(12)
        return v.as_fraction()

    # ------------------------------------------------------------------------------------ certification
    def statement_formula(self, st: Statement, by_id: dict[str, Entity], skip: frozenset[str] = frozenset()) -> Any:
        """The statement's semantics on the scene, as printed (Range bounds at their printed values); the parts
        named in `skip` are left out (certified robustly instead)."""
        e = by_id[st.id]
        return self.z3.And(*(part.formula(self, clause, e, ref) for part, clause, ref in _statement_refs(st, by_id)
                             if part.name not in skip))

    def certify(self, program: Program, scene: Scene) -> list[str]:
        """Ids of the statements that cannot be shown to hold on the scene (empty: certified).

        Plain parts, in the paper's all-SMT mode (oracle smt): the solver checks the whole program at once, and
        only when that fails is each statement asked alone, to name it. Otherwise each clause is first decided by
        rigorous interval arithmetic (Part.decide, synth.intervals): a clause it proves holds needs nothing more,
        one it refutes fails, and the clauses it cannot decide (within rounding of a boundary) go to the solver,
        statement by statement. Robust parts: each clause's violations over every perturbation must be unsat.
        """
        robust = robust_parts(scene, self.config)
        by_id = scene.by_id()
        failed: set[str] = set()
        plain = [st for st in program.statements if any(p.name not in robust for p, _ in st.clauses())]
        if plain and self.config.oracle == "smt":
            t = time.perf_counter()  # building the formulas is solver work too: it is counted
            formulas = [self.statement_formula(st, by_id, robust) for st in plain]
            s = self.z3.SolverFor("QF_NRA")
            s.add(*formulas)
            ok = s.check() == self.z3.sat
            self.stats.queries += len(formulas)
            self.stats.seconds += time.perf_counter() - t
            if not ok:
                failed |= {st.id for st, f in zip(plain, formulas) if not self.check(f)}
        elif plain:
            failed |= {st.id for st in plain if not self._decided_or_checked(st, by_id, robust)}
        if robust:
            failed |= {st.id for st in program.statements if not self.robust_holds(st, by_id, robust)}
        return [st.id for st in program.statements if st.id in failed]

    def _decided_or_checked(self, st: Statement, by_id: dict[str, Entity], skip: frozenset[str]) -> bool:
        """Does the statement hold? Intervals first, the solver for the clauses they leave undecided."""
        e = by_id[st.id]
        left = []
        for part, clause, ref in _statement_refs(st, by_id):
            if part.name in skip:
                continue
            fact = part.decide(clause, e, ref, self.config)
            if fact is False:
                return False
            if fact is None:
                left.append(part.formula(self, clause, e, ref))
        return not left or self.check(*left)

    # ------------------------------------------------------------------------------------ robust certification
    def robust_violations(self, st: Statement, by_id: dict[str, Entity], parts: frozenset[str] | None = None) -> list[Any]:
        """Ways `st` (as printed) could fail under a perturbation of the scene within its bounds: the statement
        fails for some perturbation iff one of these is satisfiable (each part's, Part.violations)."""
        e = by_id[st.id]
        return [f for part, clause, ref in _statement_refs(st, by_id) if parts is None or part.name in parts
                for f in part.violations(self, clause, e, ref)]

    def robust_holds(self, st: Statement, by_id: dict[str, Entity], parts: frozenset[str] | None = None) -> bool:
        """Is every violation of `st` (of the named parts; default all) unsat?"""
        return not any(self.fresh_check(f) for f in self.robust_violations(st, by_id, parts))


@dataclass
class DrealBackend(_ByName):
    """dReal 4 (delta-complete, the paper's solver): the same encoding over doubles.

    The PyPI wheel needs the system library libibex; where it is missing this raises SolverUnavailable.
    """

    config: SynthConfig
    stats: SolverStats = field(default_factory=SolverStats)
    _z3: Z3Backend | None = field(default=None, init=False, repr=False)  # made on the first robust question

    def __post_init__(self) -> None:
        try:
            import dreal
        except ImportError as exc:
            raise SolverUnavailable(
                f"dReal cannot be imported here ({exc}); it needs the system library libibex. Use --solver z3"
            ) from None
        self.dreal = dreal
        self.And, self.Or, self.Not = dreal.And, dreal.Or, dreal.Not
        self._fresh = 0

    def q(self, v: float | str | Fraction) -> float:
        return float(v)

    def var(self, stem: str) -> Any:
        self._fresh += 1
        return self.dreal.Variable(f"{stem}{self._fresh}")

    def offset(self, ref: Entity, e: Entity) -> tuple[float, float]:
        return e.x - ref.x, e.y - ref.y

    def cone(self, vx: Any, vy: Any, axis_heading: float, delta: float) -> Any:
        ux, uy = (float(c) for c in exact_heading_vector(axis_heading))
        dot = vx * ux + vy * uy
        cos_sq = float(exact_cos_squared(delta))
        # Constants only: dReal still decides the (ground) formula, as the paper has it do.
        z = self.var("z")
        return self.dreal.And(z == dot, z > 0, z * z >= cos_sq * (vx * vx + vy * vy))

    def distance_in(self, vx: Any, vy: Any, lo: Any, hi: Any) -> Any:
        d = self.var("d")
        return self.dreal.And(d >= 0, d * d == vx * vx + vy * vy, lo <= d, d <= hi)

    def _sat(self, formula: Any) -> Any:
        t = time.perf_counter()
        box = self.dreal.CheckSatisfiability(formula, self.config.dreal_delta)
        self.stats.queries += 1
        self.stats.seconds += time.perf_counter() - t
        return box

    def check(self, *constraints: Any) -> bool:
        return self._sat(self.dreal.And(*constraints) if len(constraints) > 1 else constraints[0]) is not None

    def distance_value(self, vx: float, vy: float) -> Fraction:
        d = self.var("d")
        box = self._sat(self.dreal.And(d >= 0, d * d == vx * vx + vy * vy))
        if box is None:
            raise RuntimeError("dReal found no distance")
        return Fraction(box[d].mid())

    def _exact(self) -> Z3Backend:
        # Robust questions are about every point of a disc: z3 decides them exactly (dReal only delta-close).
        if self._z3 is None:
            self._z3 = Z3Backend(self.config, self.stats)
        return self._z3

    def relation(self, part: Part, code: int, ref: Entity, e: Entity) -> bool:
        if part.pair_is_robust(ref, e, self.config):
            return self._exact().relation(part, code, ref, e)
        return part.relation(self, code, ref, e)

    def measure(self, requests: list[MeasureRequest]) -> Measurements:
        return [tuple(w.part.solver_measure(self, w.quantity, req.target, w.ref) for w in req.wants)
                for req in requests]

    def certify(self, program: Program, scene: Scene) -> list[str]:
        # dReal is delta-complete: it can confirm the delta-weakening of a formula, not refute it exactly.
        # Certification therefore rests on z3 where it is present, the solver of record for exactness.
        return Z3Backend(self.config).certify(program, scene)
