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

from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from synth.config import SynthConfig
from synth.draws import SPEED, Draws, Pose, Reach
from synth.parts.base import Clause, Part
from synth.perturbation import Bounds, covering, speed_box
from synth.ranges import centred
from synth.scene import Entity
from synth.syntax import Line, Range, fmt_number, printed
from synth.tables import GUARD, NONE, UNDECIDED, SceneArrays, mark, no_self_witness

if TYPE_CHECKING:
    from synth.smt.backend import ExactBackend, SolverBackend
    from synth.variants.scene_road import SceneRoad

MOTION_NAMES = ("stationary", "like")  # index = code in the tables
STATIONARY, LIKE = 0, 1
SPEED_EPS = 1e-9  # m/s: the checker's slack for float rounding, as LENGTH_EPS for metres
UNIT_LO, UNIT_HI = (0.0,), (1.0,)  # the box of a speed's one parameter (SpeedDraws)


class MotionClause(Clause):
    """What the motion clauses share: the checker's view of an entity's speed, and Scenic's speed specifier."""

    def observed(self, e: Entity) -> str:
        return "no speed" if e.speed is None else f"speed {e.speed:.3f}"

    @staticmethod
    def _boxed(backend: ExactBackend, e: Entity) -> tuple[Any, list[Any]]:
        """A variable over every speed e may have had (speed_box), with its constraints."""
        lo, hi = speed_box(e, backend.config)
        v = backend.var("v")
        return v, [backend.constant(lo) <= v, v <= backend.constant(hi)]

    @staticmethod
    def _known(e: Entity, ref: Entity | None) -> bool:
        return e.speed is not None and (ref is None or ref.speed is not None)


@dataclass(frozen=True)
class Stationary(MotionClause):
    """`stationary`: speed at most V_STOP, cost 0, no reference."""

    cost = 0
    ref = None
    text = "stationary"
    first_word = "stationary"
    labels = ("stationary",)
    drawn_as = "stationary"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self._known(e, ref) and e.speed <= config.v_stop + SPEED_EPS

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        # formula() is linear in the speeds, whose terms are rationals of floats and printed bounds: exact.
        if not self._known(e, ref):
            return None  # formula's own business (the solver path reports it)
        return Fraction(e.speed) <= Fraction(config.v_stop)

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const = backend.constant
        return const(e.speed) <= const(backend.config.v_stop)

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        ve, box = self._boxed(backend, e)
        return [backend.And(*box, ve > backend.constant(backend.config.v_stop))]

    def scenic(self, at: str) -> str:
        # Scenic >= 3.1 derives velocity from speed along the heading; speeds are never negative.
        return "Range(0, dsl__V_STOP)"

    def draws(self, config: SynthConfig) -> SpeedDraws:
        return SpeedDraws(None, UNIT_LO, UNIT_HI, (0.0, config.v_stop))


@dataclass(frozen=True)
class MovingLike(MotionClause):
    """`moving like REF`: speed within DV of REF's, cost 0."""

    ref: str
    cost = 0
    text = "moving like {c.ref}"
    first_word = "moving"
    labels = ("moving like",)
    drawn_as = "moving_like"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self._known(e, ref) and abs(e.speed - ref.speed) <= config.dv + SPEED_EPS

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        if not self._known(e, ref):
            return None
        gap = Fraction(e.speed) - Fraction(ref.speed)
        return -Fraction(config.dv) <= gap <= Fraction(config.dv)

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const, dv = backend.constant, backend.config.dv
        gap = const(e.speed) - const(ref.speed)
        return backend.And(gap <= const(dv), -gap <= const(dv))

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        const, dv = backend.constant, backend.config.dv
        (ve, box), (vr, box_r) = self._boxed(backend, e), self._boxed(backend, ref)
        gap = ve - vr
        return [backend.And(*box, *box_r, bad) for bad in (gap > const(dv), -gap > const(dv))]

    def scenic(self, at: str) -> str:
        return f"dsl__speed_like({self.ref})"

    def draws(self, config: SynthConfig) -> SpeedDraws:
        return SpeedDraws(self.ref, UNIT_LO, UNIT_HI, (-config.dv, config.dv))


@dataclass(frozen=True)
class RelativeSpeed(MotionClause):
    """`moving Range m/s relative to REF`: speed minus REF's speed in the Range, cost 1."""

    speed: Range
    ref: str
    cost = 1
    text = "moving {c.speed} m/s relative to {c.ref}"
    first_word = "moving"
    labels = ("relative speed",)
    drawn_as = "relative_speed"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self._known(e, ref) and self.speed.contains(e.speed - ref.speed, SPEED_EPS)

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        if not self._known(e, ref):
            return None
        return printed(self.speed.lo) <= Fraction(e.speed) - Fraction(ref.speed) <= printed(self.speed.hi)

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const = backend.constant
        gap = const(e.speed) - const(ref.speed)
        return backend.And(const(printed(self.speed.lo)) <= gap, gap <= const(printed(self.speed.hi)))

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        const = backend.constant
        (ve, box), (vr, box_r) = self._boxed(backend, e), self._boxed(backend, ref)
        gap = ve - vr
        bad = (gap < const(printed(self.speed.lo)), gap > const(printed(self.speed.hi)))
        return [backend.And(*box, *box_r, b) for b in bad]

    def scenic(self, at: str) -> str:
        return f"dsl__speed_relative({self.ref}, {fmt_number(self.speed.lo)}, {fmt_number(self.speed.hi)})"

    def scenic_requirements(self, entity: str) -> list[str]:
        # REF's speed + Range(a, b) holds no speed >= 0 when REF is slower than -b: such draws are rejected.
        if self.speed.hi < 0:
            return [f"require {self.ref}.speed >= {fmt_number(-self.speed.hi)}"]
        return []

    def draws(self, config: SynthConfig) -> SpeedDraws:
        return SpeedDraws(self.ref, UNIT_LO, UNIT_HI, (self.speed.lo, self.speed.hi))


@dataclass(frozen=True)
class AbsoluteSpeed(MotionClause):
    """`moving Range m/s`: speed in the Range, cost 2."""

    speed: Range
    cost = 2
    ref = None
    text = "moving {c.speed} m/s"
    first_word = "moving"
    labels = ("absolute speed",)
    drawn_as = "absolute_speed"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self._known(e, ref) and self.speed.contains(e.speed, SPEED_EPS)

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        if not self._known(e, ref):
            return None
        return printed(self.speed.lo) <= Fraction(e.speed) <= printed(self.speed.hi)

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        const, se = backend.constant, backend.constant(e.speed)
        return backend.And(const(printed(self.speed.lo)) <= se, se <= const(printed(self.speed.hi)))

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        const = backend.constant
        ve, box = self._boxed(backend, e)
        bad = (ve < const(printed(self.speed.lo)), ve > const(printed(self.speed.hi)))
        return [backend.And(*box, b) for b in bad]

    def scenic(self, at: str) -> str:
        # A Range below 0 describes no speed at all; its negative part is never drawn.
        return f"Range({fmt_number(max(self.speed.lo, 0.0))}, {fmt_number(max(self.speed.hi, 0.0))})"

    def draws(self, config: SynthConfig) -> SpeedDraws:
        return SpeedDraws(None, UNIT_LO, UNIT_HI, (self.speed.lo, self.speed.hi))


@dataclass(frozen=True)
class SpeedDraws(Draws):
    """What Scenic draws for a motion clause: the speed uniformly in [a, b], a and b following the reference's
    speed and clamped at 0 (`Range(0, dsl__V_STOP)`, dsl__speed_like, dsl__speed_relative, an absolute Range).
    The parameter is that uniform draw t in [0, 1], speed = a + (b - a) t: a fixed box, while the interval moves
    with the reference."""

    offsets: tuple[float, float]  # added to the reference's speed (0 without one), then clamped at 0
    writes = SPEED

    @property
    def reads(self) -> tuple[str, ...]:
        return () if self.ref is None else (SPEED,)

    def interval(self, ref: Pose | None) -> tuple[float, float]:
        base = 0.0 if ref is None else ref.speed
        return (max(0.0, base + self.offsets[0]), max(0.0, base + self.offsets[1]))

    def evaluate(self, p: Sequence[float], own: Pose, ref: Pose | None) -> None:
        a, b = self.interval(ref)
        own.speed = a + (b - a) * p[0]

    def invert(self, own: Pose, ref: Pose | None) -> tuple[float, ...]:
        a, b = self.interval(ref)
        return ((own.speed - a) / (b - a) if b > a else 0.0,)

    def area(self, p: Sequence[float], ref: Pose | None) -> float:
        a, b = self.interval(ref)
        return b - a

    @property
    def requires(self) -> bool:
        # A relative Range wholly below 0 holds no speed unless the reference is fast enough: the emitted text
        # requires it (RelativeSpeed.scenic_requirements), so Scenic rejects such draws.
        return self.ref is not None and self.offsets[1] < 0.0

    def allowed(self, own: Pose, ref: Pose | None, road: SceneRoad | None) -> bool:
        return not self.requires or ref.speed >= -self.offsets[1]

    def reach(self, own: Reach, ref: Reach | None) -> Reach:
        return own  # a speed places nothing


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
    clauses = (Stationary, MovingLike, RelativeSpeed, AbsoluteSpeed)
    optional = True  # `, MOTION` ends a statement when the program has motion

    def enabled(self, config: SynthConfig) -> bool:
        return config.motion

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

    def robust_relation(self, backend: ExactBackend, code: int, ref: Entity, e: Entity) -> bool:
        const, cfg = backend.constant, backend.config
        ve, box_e = MotionClause._boxed(backend, e)
        if code == STATIONARY:
            return not backend.check_quantified(*box_e, ve > const(cfg.v_stop))
        vr, box_r = MotionClause._boxed(backend, ref)
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
    def scenic_prelude(self, config: SynthConfig) -> str:
        return MOTION_PRELUDE.format(v_stop=fmt_number(config.v_stop), dv=fmt_number(config.dv))


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
