"""z3 (the default solver): the encoding over the exact rationals of the scene's floats, decided exactly."""

from __future__ import annotations

import time
from dataclasses import dataclass
from fractions import Fraction
from functools import cached_property
from typing import Any

from synth.geometry import exact_cos_squared, exact_heading_vector
from synth.scene import Entity
from synth.smt.backend import ExactBackend, Formula, Measurements, MeasureRequest, SolverUnavailable, as_fraction
from synth.smt.measure import measure


@dataclass
class Z3Backend(ExactBackend):

    def __post_init__(self) -> None:
        try:
            import z3
        except ImportError as exc:  # pragma: no cover - z3 is a core dependency
            raise SolverUnavailable(f"z3 is not installed ({exc}); pip install z3-solver") from None
        self.z3 = z3  # public: the monolithic baseline builds its own optimisation problem with it
        self.And, self.Or, self.Not = z3.And, z3.Or, z3.Not
        self._fresh = 0

    # One solver per frame (this backend's), reused with push / pop, and made only when a question needs it:
    # with the default oracle most frames ask none.
    @cached_property
    def _solver(self) -> Any:
        return self.z3.SolverFor("QF_NRA")

    @cached_property
    def _nlsat(self) -> Any:
        return self.z3.Tactic("qfnra-nlsat")  # robust questions; see check_quantified

    # --------------------------------------------------------------------------------- encoding primitives
    def constant(self, v: float | str | Fraction) -> Any:
        # RealVal from a "p/q" string is a single numeral; z3.Q builds a division and simplifies it (7x slower).
        f = as_fraction(v)
        return self.z3.RealVal(f"{f.numerator}/{f.denominator}")

    def var(self, stem: str) -> Any:
        self._fresh += 1
        return self.z3.Real(f"{stem}{self._fresh}")

    def offset(self, ref: Entity, e: Entity) -> tuple[Any, Any]:
        return (self.constant(as_fraction(e.x) - as_fraction(ref.x)),
                self.constant(as_fraction(e.y) - as_fraction(ref.y)))

    def cone(self, vx: Any, vy: Any, axis_heading: float, delta: float) -> Formula:
        ux, uy = (self.constant(c) for c in exact_heading_vector(axis_heading))
        dot = vx * ux + vy * uy
        return self.z3.And(dot > 0, dot * dot >= self.constant(exact_cos_squared(delta)) * (vx * vx + vy * vy))

    def distance_in(self, vx: Any, vy: Any, lo: Any, hi: Any) -> Formula:
        d = self.var("d")
        return self.z3.And(d >= 0, d * d == vx * vx + vy * vy, lo <= d, d <= hi)

    def angle_in(self, heading: float, base: float, lo: Fraction, hi: Fraction) -> Formula:
        """heading = N(base + alpha) for some alpha in [lo, hi].

        The whole number of turns k is the certificate: with hi - lo < 360 at most one k can work, the one that
        puts heading - base - 360 k just above lo, so it is computed here and the solver decides the rest.
        """
        gap = as_fraction(heading) - as_fraction(base)
        k = (gap - lo) // 360
        alpha = gap - 360 * k
        return self.z3.And(self.constant(lo) <= self.constant(alpha), self.constant(alpha) <= self.constant(hi))

    def perturbed_offset(self, c: tuple[Fraction, Fraction], radius: Fraction) -> tuple[Any, Any, list[Formula]]:
        vx, vy = self.constant(c[0]), self.constant(c[1])
        if radius == 0:
            return vx, vy, []
        wx, wy = self.var("wx"), self.var("wy")
        return vx + wx, vy + wy, [wx * wx + wy * wy <= self.constant(radius * radius)]

    def cone_fails(self, vx: Any, vy: Any, cons: list[Formula], axis: float, cone: float | None) -> Formula:
        return self.z3.BoolVal(True) if cone is None else self.z3.And(*cons, self.z3.Not(self.cone(vx, vy, axis, cone)))

    # --------------------------------------------------------------------------------- deciding
    def check(self, *constraints: Formula) -> bool:
        started = time.perf_counter()
        solver = self._solver
        solver.push()
        solver.add(*constraints)
        result = solver.check()
        solver.pop()
        return self._verdict(result, solver, started)

    def _verdict(self, result: Any, solver: Any, started: float) -> bool:
        """Count one query and its time; sat -> True. unknown would be a guess either way: refuse it."""
        self.stats.record(1, started)
        if result == self.z3.unknown:
            raise RuntimeError(f"z3 returned unknown: {solver.reason_unknown()}")
        return result == self.z3.sat

    def check_quantified(self, *constraints: Formula) -> bool:
        """On a fresh nlsat solver. z3's incremental (push/pop) solver does not run nlsat, and on these questions
        it can take seconds where nlsat takes milliseconds; the qfnra-nlsat tactic (complete for nonlinear real
        arithmetic) skips SolverFor's portfolio set-up, 3x faster again."""
        started = time.perf_counter()
        solver = self._nlsat.solver()
        solver.add(*constraints)
        return self._verdict(solver.check(), solver, started)

    def robust_cone(self, c: tuple[Fraction, Fraction], radius: Fraction, axis: float, cone: float | None) -> bool:
        """The existentially quantified violation is asked (synth.perturbation): a v in the disc outside the cone.
        unsat = it holds."""
        if cone is None:
            return False
        cx, cy = self.constant(c[0]), self.constant(c[1])
        if radius == 0:
            return self.check(self.cone(cx, cy, axis, cone))
        wx, wy = self.var("wx"), self.var("wy")
        return not self.check_quantified(
            wx * wx + wy * wy <= self.constant(radius * radius),
            self.z3.Not(self.cone(cx + wx, cy + wy, axis, cone)),
        )

    def check_together(self, formulas: list[Formula], started: float) -> bool:
        solver = self.z3.SolverFor("QF_NRA")
        solver.add(*formulas)
        holds = solver.check() == self.z3.sat
        self.stats.record(len(formulas), started)
        return holds

    def model_values(self, constraints: list[Formula], variables: list[Any], queries: int,
                     started: float) -> list[Fraction]:
        solver = self.z3.SolverFor("QF_NRA")
        solver.add(*constraints)
        result = solver.check()
        if result != self.z3.sat:
            self.stats.record(queries, started)
            raise RuntimeError(f"z3 found no values for the program's Ranges ({result})")
        model = solver.model()
        values = [self._value(model, v) for v in variables]
        self.stats.record(queries, started)
        return values

    def distance_value(self, vx: float, vy: float) -> Fraction:
        started = time.perf_counter()
        vx_term, vy_term, d = self.constant(vx), self.constant(vy), self.var("d")
        return self.model_values([d >= 0, d * d == vx_term * vx_term + vy_term * vy_term], [d], 1, started)[0]

    def _value(self, model: Any, var: Any) -> Fraction:
        v = model.eval(var, model_completion=True)
        if self.z3.is_algebraic_value(v):
            # An irrational distance: 12 decimals are far below the 0.01 printing resolution.
            v = v.approx(12)
        return v.as_fraction()

    # --------------------------------------------------------------------------------- Range values
    def measure(self, requests: list[MeasureRequest]) -> Measurements:
        return measure(self, requests)
