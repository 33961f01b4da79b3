"""MOTION, the motion part (beyond the paper; `--motion`): who is parked, who drives with whom, and how fast.

    stationary                                    cost 0    speed(e) <= V_STOP
    moving like REF                               cost 0    |speed(e) - speed(REF)| <= DV
    moving Range(a, b) m/s relative to REF        cost 1    speed(e) - speed(REF) in [a, b], b - a = C_SPEED
    moving Range(a, b) m/s                        cost 2    speed(e) in [a, b], b - a = C_SPEED

speed is the magnitude of an entity's ground velocity (m/s). `stationary` needs no reference: like ego it is
always available, so it is recorded in ego's row of the relation table (Part.refless) and the search treats it as
a witness that is declared from the start; `moving like REF` is a witness edge REF -> e like any other. Every
question is linear in the speeds: floats decide it outside the guard band, exact rationals (or the solver, over
the same rationals) inside it. Robust: each speed may be anywhere in [max(0, s - sigma), s + sigma], so a
relation holds robustly iff it holds at the corners of those intervals, and a Range covers the whole interval.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from synth.config import SynthConfig
from synth.parts.base import Clause, ClauseKind, Part
from synth.perturbation import Bounds, covering, speed_box
from synth.ranges import centred
from synth.scene import Entity
from synth.syntax import Line, Range, fmt_number, printed
from synth.tables import GUARD, NONE, UNDECIDED, SceneArrays, mark, no_self_witness

if TYPE_CHECKING:
    from synth.smt.backend import ExactBackend, SolverBackend

MOTION_NAMES = ("stationary", "like")  # index = code in the tables
STATIONARY, LIKE = 0, 1
SPEED_EPS = 1e-9  # m/s: the checker's slack for float rounding, as LENGTH_EPS for metres


@dataclass(frozen=True)
class Stationary:
    """`stationary`: speed at most V_STOP, cost 0, no reference."""

    cost = 0
    ref = None

    def __str__(self) -> str:
        return "stationary"


@dataclass(frozen=True)
class MovingLike:
    """`moving like REF`: speed within DV of REF's, cost 0."""

    ref: str
    cost = 0

    def __str__(self) -> str:
        return f"moving like {self.ref}"


@dataclass(frozen=True)
class RelativeSpeed:
    """`moving Range m/s relative to REF`: speed minus REF's speed in the Range, cost 1."""

    speed: Range
    ref: str
    cost = 1

    def __str__(self) -> str:
        return f"moving {self.speed} m/s relative to {self.ref}"


@dataclass(frozen=True)
class AbsoluteSpeed:
    """`moving Range m/s`: speed in the Range, cost 2."""

    speed: Range
    cost = 2
    ref = None

    def __str__(self) -> str:
        return f"moving {self.speed} m/s"


def _decide(margin: np.ndarray, scale: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(holds, undecided) of `margin >= 0`, with a guard band relative to the speeds' size."""
    tol = GUARD * (1.0 + scale)
    with np.errstate(invalid="ignore"):  # NaN (no speed): neither holds nor undecided
        return margin > tol, np.abs(margin) <= tol


class MotionPart(Part):
    name = "motion"
    relations = MOTION_NAMES
    refless = frozenset({STATIONARY})
    keyword = "with speed"
    clause_kinds = (
        ClauseKind("stationary", Stationary, "stationary"),
        ClauseKind("moving like", MovingLike, "moving_like"),
        ClauseKind("relative speed", RelativeSpeed, "relative_speed"),
        ClauseKind("absolute speed", AbsoluteSpeed, "absolute_speed"),
    )

    def perturbed(self, b: Bounds) -> bool:
        return b.speed != 0.0

    # ------------------------------------------------------------------------------- float table, exact
    def _table(self, lo: np.ndarray, hi: np.ndarray, config: SynthConfig) -> np.ndarray:
        """Codes when each speed may be anywhere in [lo, hi] (lo = hi: the plain question)."""
        # |s_e - s_r| <= DV for every pair of speeds in the boxes: the farthest corners decide. [r, e].
        gap = np.maximum(hi[None, :] - lo[:, None], hi[:, None] - lo[None, :])
        scale = np.abs(hi)[None, :] + np.abs(hi)[:, None]
        codes = np.full(gap.shape, NONE, dtype=np.int8)
        mark(codes, LIKE, *_decide(config.dv - gap, scale))
        # stationary needs no reference and goes first (Part.codes_from): ego's row, over `moving like ego`.
        holds, unsure = _decide(config.v_stop - hi, np.abs(hi))
        row = codes[0]
        row[holds] = STATIONARY
        row[unsure] = UNDECIDED
        return no_self_witness(codes)

    def closed_form(self, arrays: SceneArrays, config: SynthConfig) -> np.ndarray:
        return self._table(arrays.speed, arrays.speed, config)

    def robust_closed_form(self, arrays: SceneArrays, bounds: list[Bounds], config: SynthConfig) -> np.ndarray:
        sigma = np.array([b.speed for b in bounds])
        return self._table(np.maximum(arrays.speed - sigma, 0.0), arrays.speed + sigma, config)

    def exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool:
        se = Fraction(e.speed)
        if code == STATIONARY:
            return se <= Fraction(config.v_stop)
        return abs(se - Fraction(ref.speed)) <= Fraction(config.dv)

    # ------------------------------------------------------------------------------- SMT
    def _speed(self, backend: SolverBackend, e: Entity) -> Any:
        """A solver variable pinned to e's speed (a term, so that every backend gets a formula, not a bool)."""
        v = backend.var("v")
        return v, v == backend.constant(e.speed)

    def relation(self, backend: SolverBackend, code: int, ref: Entity, e: Entity) -> bool:
        const, cfg = backend.constant, backend.config
        ve, pin_e = self._speed(backend, e)
        if code == STATIONARY:
            return backend.check(pin_e, ve <= const(cfg.v_stop))
        vr, pin_r = self._speed(backend, ref)
        return backend.check(pin_e, pin_r, ve - vr <= const(cfg.dv), vr - ve <= const(cfg.dv))

    def _boxed(self, backend: ExactBackend, e: Entity) -> tuple[Any, list[Any]]:
        """A variable over every speed e may have had (speed_box), with its constraints."""
        lo, hi = speed_box(e, backend.config)
        v = backend.var("v")
        return v, [backend.constant(lo) <= v, v <= backend.constant(hi)]

    def robust_relation(self, backend: ExactBackend, code: int, ref: Entity, e: Entity) -> bool:
        const, cfg = backend.constant, backend.config
        ve, box_e = self._boxed(backend, e)
        if code == STATIONARY:
            return not backend.check_quantified(*box_e, ve > const(cfg.v_stop))
        vr, box_r = self._boxed(backend, ref)
        apart = backend.Or(ve - vr > const(cfg.dv), vr - ve > const(cfg.dv))
        return not backend.check_quantified(*box_e, *box_r, apart)

    def any_relation(self, backend: ExactBackend, ref: Entity, e: Entity) -> Any:
        const, cfg = backend.constant, backend.config
        speed_e, speed_r = const(e.speed), const(ref.speed)
        like = backend.And(speed_e - speed_r <= const(cfg.dv), speed_r - speed_e <= const(cfg.dv))
        return backend.Or(speed_e <= const(cfg.v_stop), like) if ref.is_ego else like

    def measure_terms(self, backend: ExactBackend, quantity: str, target: Entity, ref: Entity) -> tuple[list, list]:
        v = backend.var("v")
        base = backend.constant(ref.speed) if quantity == "speed_offset" else backend.constant(0)
        return [v == backend.constant(target.speed) - base], [v]

    def formula(self, backend: ExactBackend, clause: Clause, e: Entity, ref: Entity | None) -> Any:
        const, cfg = backend.constant, backend.config
        se = const(e.speed)
        if isinstance(clause, Stationary):
            return se <= const(cfg.v_stop)
        if isinstance(clause, AbsoluteSpeed):
            return backend.And(const(printed(clause.speed.lo)) <= se, se <= const(printed(clause.speed.hi)))
        gap = se - const(ref.speed)
        if isinstance(clause, MovingLike):
            return backend.And(gap <= const(cfg.dv), -gap <= const(cfg.dv))
        return backend.And(const(printed(clause.speed.lo)) <= gap, gap <= const(printed(clause.speed.hi)))

    def violations(self, backend: ExactBackend, clause: Clause, e: Entity, ref: Entity | None) -> list[Any]:
        const, cfg = backend.constant, backend.config
        ve, box = self._boxed(backend, e)
        if isinstance(clause, Stationary):
            return [backend.And(*box, ve > const(cfg.v_stop))]
        if isinstance(clause, AbsoluteSpeed):
            bad = (ve < const(printed(clause.speed.lo)), ve > const(printed(clause.speed.hi)))
            return [backend.And(*box, b) for b in bad]
        vr, box_r = self._boxed(backend, ref)
        gap = ve - vr
        if isinstance(clause, MovingLike):
            bad = (gap > const(cfg.dv), -gap > const(cfg.dv))
        else:
            bad = (gap < const(printed(clause.speed.lo)), gap > const(printed(clause.speed.hi)))
        return [backend.And(*box, *box_r, b) for b in bad]

    # ------------------------------------------------------------------------------- exact, without a solver
    def decide(self, clause: Clause, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        # formula() is linear in the speeds, whose terms are rationals of floats and printed bounds: exact.
        if e.speed is None or (ref is not None and ref.speed is None):
            return None  # formula's own business (the solver path reports it)
        se = Fraction(e.speed)
        if isinstance(clause, Stationary):
            return se <= Fraction(config.v_stop)
        if isinstance(clause, AbsoluteSpeed):
            return printed(clause.speed.lo) <= se <= printed(clause.speed.hi)
        gap = se - Fraction(ref.speed)
        if isinstance(clause, MovingLike):
            return -Fraction(config.dv) <= gap <= Fraction(config.dv)
        return printed(clause.speed.lo) <= gap <= printed(clause.speed.hi)

    def exact_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        return self.float_measure(quantity, target, ref)  # already exact: a difference of two floats

    # ------------------------------------------------------------------------------- Alg. 4
    def quantity(self, code: int) -> str | None:
        return None if code != NONE else "speed_offset"

    def float_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        # A difference of two floats is exact in rationals: no reason to round it.
        base = Fraction(ref.speed) if quantity == "speed_offset" else Fraction(0)
        return (Fraction(target.speed) - base,)

    def clause(self, code: int, ref_id: str, values: tuple[Fraction, ...], config: SynthConfig) -> Clause:
        if code == STATIONARY:
            return Stationary()
        if code == LIKE:
            return MovingLike(ref_id)
        return RelativeSpeed(centred(values[0], config.c_speed), ref_id)

    def robust_clause(self, code: int, target: Entity, ref: Entity, config: SynthConfig) -> Clause:
        if code == STATIONARY:
            return Stationary()
        if code == LIKE:
            return MovingLike(ref.id)
        (lo_e, hi_e), (lo_r, hi_r) = speed_box(target, config), speed_box(ref, config)
        return RelativeSpeed(covering(lo_e - hi_r, hi_e - lo_r, config.c_speed), ref.id)

    # ------------------------------------------------------------------------------- semantics
    def holds(self, clause: Clause, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        if e.speed is None or (ref is not None and ref.speed is None):
            return False
        if isinstance(clause, Stationary):
            return e.speed <= config.v_stop + SPEED_EPS
        if isinstance(clause, AbsoluteSpeed):
            return clause.speed.contains(e.speed, SPEED_EPS)
        assert ref is not None
        if isinstance(clause, MovingLike):
            return abs(e.speed - ref.speed) <= config.dv + SPEED_EPS
        if isinstance(clause, RelativeSpeed):
            return clause.speed.contains(e.speed - ref.speed, SPEED_EPS)
        raise TypeError(f"not a motion: {clause!r}")

    def observed(self, e: Entity) -> str:
        return "no speed" if e.speed is None else f"speed {e.speed:.3f}"

    # ------------------------------------------------------------------------------- syntax
    def parse(self, ln: Line, declared: set[str]) -> Clause:
        if ln.accept("stationary"):
            return Stationary()
        ln.take(text="moving")
        if ln.accept("like"):
            return MovingLike(ln.reference(declared))
        speed = ln.range_()
        for word in ("m", "/", "s"):
            ln.take(text=word)
        if ln.accept("relative"):
            ln.take(text="to")
            return RelativeSpeed(speed, ln.reference(declared))
        return AbsoluteSpeed(speed)

    # ------------------------------------------------------------------------------- Scenic
    def scenic(self, clause: Clause, at: str) -> str:
        # Scenic >= 3.1 derives velocity from speed along the heading; speeds are never negative.
        if isinstance(clause, Stationary):
            return "Range(0, dsl__V_STOP)"
        if isinstance(clause, MovingLike):
            return f"dsl__speed_like({clause.ref})"
        if isinstance(clause, RelativeSpeed):
            return f"dsl__speed_relative({clause.ref}, {fmt_number(clause.speed.lo)}, {fmt_number(clause.speed.hi)})"
        if isinstance(clause, AbsoluteSpeed):
            # A Range below 0 describes no speed at all; its negative part is never drawn.
            return f"Range({fmt_number(max(clause.speed.lo, 0.0))}, {fmt_number(max(clause.speed.hi, 0.0))})"
        raise TypeError(f"not a DSL motion: {clause!r}")

    def scenic_requirements(self, clause: Clause, entity: str) -> list[str]:
        # REF's speed + Range(a, b) holds no speed >= 0 when REF is slower than -b: such draws are rejected.
        if isinstance(clause, RelativeSpeed) and clause.speed.hi < 0:
            return [f"require {clause.ref}.speed >= {fmt_number(-clause.speed.hi)}"]
        return []

    def scenic_prelude(self, config: SynthConfig) -> str:
        return MOTION_PRELUDE.format(v_stop=fmt_number(config.v_stop), dv=fmt_number(config.dv))

    # ------------------------------------------------------------------------------- report

MOTION_PRELUDE = '''\
# Motion (r2sgen's MOTION clause): every object gets its speed; Scenic derives its velocity along its heading.
dsl__V_STOP = {v_stop}  # m/s: stationary means at most this fast
dsl__DV = {dv}  # m/s: moving like R means within this of R's speed

def dsl__speed_like(ref):
    """A speed within DV of ref's, never negative."""
    return Range(max(0, ref.speed - dsl__DV), ref.speed + dsl__DV)

def dsl__speed_relative(ref, lo, hi):
    """ref's speed plus an offset in [lo, hi], never negative (an empty case is required away)."""
    return Range(max(0, ref.speed + lo), max(0, ref.speed + hi))
'''

MOTION = MotionPart()
