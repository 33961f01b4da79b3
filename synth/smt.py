"""SMT backends: relation queries, exact Range values, and certification of whole programs.

Encoding (no atan2, no trigonometry in the formula): with v the offset between the two entities and u the
unit vector of the axis the relation names, "v within delta of u" is
    v.u > 0  and  (v.u)^2 >= cos^2(delta) |v|^2
over the exact rationals of the scene's floats. u and cos(delta) are the rationals of their correctly
rounded floats, the same constants the closed form uses (synth.geometry), so the two oracles answer the
same question. A distance Range [a, b] is encoded with d >= 0, d^2 = |v|^2, a <= d <= b: nonlinear real
arithmetic, exact in z3 (nlsat). dReal (optional) gets the same formula over doubles, delta-complete.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any

from synth.config import SynthConfig
from synth.dsl import (
    DIRECTIONS,
    AbsoluteHeading,
    AbsoluteXYPos,
    DirectionPos,
    FacingRelation,
    Program,
    RelativeHeading,
    Statement,
    fmt_number,
)
from synth.geometry import exact_cos_squared, exact_heading_vector
from synth.robust import bounds_of, is_robust, narrowed, pair_is_robust, radius_of
from synth.scene import Entity, Scene


class SolverUnavailable(RuntimeError):
    """The chosen solver cannot be loaded here. One line, fit for a user."""


@dataclass
class SolverStats:
    queries: int = 0
    seconds: float = 0.0


@dataclass(frozen=True)
class Measurement:
    """Exact values the Ranges of one statement are centred on (None where the statement has no such part)."""

    distance: Fraction | None = None
    lateral: Fraction | None = None
    forward: Fraction | None = None
    angle: Fraction | None = None  # heading offset in (-180, 180]


@dataclass(frozen=True)
class MeasureRequest:
    """What to measure for one statement: target, position reference and kind, heading reference and kind."""

    target: Entity
    position_ref: Entity | None
    position_kind: str  # direction | local | absolute
    heading_ref: Entity | None
    heading_kind: str  # facing | relative | absolute


def _frac(v: float | str | Fraction) -> Fraction:
    return v if isinstance(v, Fraction) else Fraction(v)


def _printed(v: float) -> Fraction:
    """The exact value a Range bound has once printed: certification is about the text users get."""
    return Fraction(fmt_number(v))


def make_backend(config: SynthConfig) -> Z3Backend | DrealBackend:
    if config.solver == "dreal":
        return DrealBackend(config)
    return Z3Backend(config)


@dataclass
class Z3Backend:
    config: SynthConfig
    stats: SolverStats = field(default_factory=SolverStats)

    def __post_init__(self) -> None:
        try:
            import z3
        except ImportError as exc:  # pragma: no cover - z3 is a core dependency
            raise SolverUnavailable(f"z3 is not installed ({exc}); pip install z3-solver") from None
        self.z3 = z3
        self._solver = z3.SolverFor("QF_NRA")
        self._nlsat = z3.Tactic("qfnra-nlsat")  # robust questions; see _fresh_check
        self._fresh = 0

    # --------------------------------------------------------------------------------- building blocks
    def q(self, v: float | str | Fraction) -> Any:
        # RealVal from a "p/q" string is a single numeral; z3.Q builds a division and simplifies it (7x slower).
        f = _frac(v)
        return self.z3.RealVal(f"{f.numerator}/{f.denominator}")

    def _var(self, stem: str) -> Any:
        self._fresh += 1
        return self.z3.Real(f"{stem}{self._fresh}")

    def _offset(self, ref: Entity, e: Entity) -> tuple[Any, Any]:
        return self.q(_frac(e.x) - _frac(ref.x)), self.q(_frac(e.y) - _frac(ref.y))

    def _cone(self, vx: Any, vy: Any, axis_heading: float, delta: float) -> Any:
        z3 = self.z3
        ux, uy = (self.q(c) for c in exact_heading_vector(axis_heading))
        dot = vx * ux + vy * uy
        return z3.And(dot > 0, dot * dot >= self.q(exact_cos_squared(delta)) * (vx * vx + vy * vy))

    def _distance_in(self, vx: Any, vy: Any, lo: Any, hi: Any) -> Any:
        d = self._var("d")
        return self.z3.And(d >= 0, d * d == vx * vx + vy * vy, lo <= d, d <= hi)

    def _angle_in(self, heading: float, base: float, lo: Fraction, hi: Fraction) -> Any:
        """heading = N(base + alpha) for some alpha in [lo, hi].

        The whole number of turns k is the certificate: with hi - lo < 360 at most one k can work, the one that
        puts heading - base - 360 k just above lo, so it is computed here and the solver decides the rest.
        """
        gap = _frac(heading) - _frac(base)
        k = (gap - lo) // 360
        alpha = gap - 360 * k
        return self.z3.And(self.q(lo) <= self.q(alpha), self.q(alpha) <= self.q(hi))

    def _check(self, *constraints: Any) -> bool:
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

    # ------------------------------------------------------------------------------------ relation queries
    def position_relation(self, direction: str, ref: Entity, e: Entity) -> bool:
        """Is there a Range(a, a + C_dist), a >= 0, such that `e = ... direction ref by Range(a, ...)` holds?

        Robust (either entity uncertain): does it hold for every perturbation? The Range then widens to cover
        every distance (synth.robust), so only the sector is in question.
        """
        if pair_is_robust(ref, e, self.config):
            cone = narrowed(self.config.delta1, bounds_of(ref, self.config).heading)
            return self.robust_cone(_exact_offset(ref, e), radius_of(ref, e, self.config),
                                    ref.heading + DIRECTIONS[direction][1], cone)
        vx, vy = self._offset(ref, e)
        a = self._var("a")
        return self._check(
            a >= 0,
            self._distance_in(vx, vy, a, a + self.q(self.config.c_dist)),
            self._cone(vx, vy, ref.heading + DIRECTIONS[direction][1], self.config.delta1),
        )

    def heading_relation(self, mode: str, ref: Entity, e: Entity) -> bool:
        if pair_is_robust(ref, e, self.config):
            cx, cy = _exact_offset(ref, e)
            sign = -1 if mode == "toward" else 1
            cone = narrowed(self.config.delta2, bounds_of(e, self.config).heading)
            return self.robust_cone((sign * cx, sign * cy), radius_of(ref, e, self.config), e.heading, cone)
        vx, vy = self._offset(ref, e)
        if mode == "toward":
            vx, vy = -vx, -vy
        return self._check(self._cone(vx, vy, e.heading, self.config.delta2))

    def robust_cone(self, c: tuple[Fraction, Fraction], radius: Fraction, axis: float, cone: float | None) -> bool:
        """Does every v in the disc D(c, radius) lie within `cone` degrees of the axis (synth.robust)?

        The existentially quantified violation is asked: a v in the disc outside the cone. unsat = it holds.
        """
        if cone is None:
            return False
        cx, cy = self.q(c[0]), self.q(c[1])
        if radius == 0:
            return self._check(self._cone(cx, cy, axis, cone))
        wx, wy = self._var("wx"), self._var("wy")
        return not self._fresh_check(
            wx * wx + wy * wy <= self.q(radius * radius),
            self.z3.Not(self._cone(cx + wx, cy + wy, axis, cone)),
        )

    # ------------------------------------------------------------------------------------ range values
    def measure(self, requests: list[MeasureRequest]) -> list[Measurement]:
        """Exact distances, local coordinates and heading offsets for many statements, from one model."""
        z3 = self.z3
        if not requests:
            return []
        t = time.perf_counter()
        cons, wanted = [], []
        for req in requests:
            slots: dict[str, Any] = {}
            if req.position_kind == "direction":
                vx, vy = self._offset(req.position_ref, req.target)
                d = self._var("d")
                cons += [d >= 0, d * d == vx * vx + vy * vy]
                slots["distance"] = d
            elif req.position_kind == "local":
                vx, vy = self._offset(req.position_ref, req.target)
                ux, uy = (self.q(c) for c in exact_heading_vector(req.position_ref.heading))
                # cos t = uy, sin t = -ux for the heading vector (-sin t, cos t).
                lx, ly = self._var("lx"), self._var("ly")
                cons += [lx == vx * uy - vy * ux, ly == vy * uy + vx * ux]
                slots["lateral"], slots["forward"] = lx, ly
            if req.heading_kind in ("relative", "absolute"):
                base = req.heading_ref.heading if req.heading_kind == "relative" else 0.0
                # The offset in (-180, 180]: headings are in [0, 360), so one of three turns fits.
                gap = _frac(req.target.heading) - _frac(base)
                alpha = self._var("alpha")
                cons += [alpha > -180, alpha <= 180,
                         z3.Or(*(alpha == self.q(gap - 360 * k) for k in (-1, 0, 1)))]
                slots["angle"] = alpha
            wanted.append(slots)
        s = z3.SolverFor("QF_NRA")
        s.add(*cons)
        result = s.check()
        self.stats.queries += len(requests)
        if result != z3.sat:
            self.stats.seconds += time.perf_counter() - t
            raise RuntimeError(f"z3 found no values for the program's Ranges ({result})")
        m = s.model()
        out = [Measurement(**{k: self._value(m, v) for k, v in slots.items()}) for slots in wanted]
        self.stats.seconds += time.perf_counter() - t
        return out

    def _value(self, model: Any, var: Any) -> Fraction:
        v = model.eval(var, model_completion=True)
        if self.z3.is_algebraic_value(v):
            # An irrational distance: 12 decimals are far below the 0.01 printing resolution.
            v = v.approx(12)
        return v.as_fraction()

    # ------------------------------------------------------------------------------------ certification
    def statement_formula(self, st: Statement, by_id: dict[str, Entity]) -> Any:
        """The statement's semantics on the scene, as printed (Range bounds at their printed values)."""
        z3 = self.z3
        e = by_id[st.id]
        pos, head = st.position, st.heading
        if isinstance(pos, AbsoluteXYPos):
            p = z3.And(*(self.q(_printed(b.lo)) <= self.q(v) for b, v in ((pos.x, e.x), (pos.y, e.y))),
                       *(self.q(v) <= self.q(_printed(b.hi)) for b, v in ((pos.x, e.x), (pos.y, e.y))))
        else:
            ref = by_id[pos.ref]
            vx, vy = self._offset(ref, e)
            if isinstance(pos, DirectionPos):
                lo, hi = _printed(pos.distance.lo), _printed(pos.distance.hi)
                # lo <= |v| <= hi with 0 <= lo, squared: no square root, a ground formula.
                p = z3.And(
                    self.q(max(lo, Fraction(0)) ** 2) <= vx * vx + vy * vy, vx * vx + vy * vy <= self.q(hi * hi),
                    self._cone(vx, vy, ref.heading + DIRECTIONS[pos.direction][1], self.config.delta1),
                )
            else:
                ux, uy = (self.q(c) for c in exact_heading_vector(ref.heading))
                lx, ly = vx * uy - vy * ux, vy * uy + vx * ux
                p = z3.And(
                    self.q(_printed(pos.lateral.lo)) <= lx, lx <= self.q(_printed(pos.lateral.hi)),
                    self.q(_printed(pos.forward.lo)) <= ly, ly <= self.q(_printed(pos.forward.hi)),
                )
        if isinstance(head, AbsoluteHeading):
            h = self._angle_in(e.heading, 0.0, _printed(head.angle.lo), _printed(head.angle.hi))
        else:
            ref = by_id[head.ref]
            if isinstance(head, RelativeHeading):
                h = self._angle_in(e.heading, ref.heading, _printed(head.angle.lo), _printed(head.angle.hi))
            else:
                vx, vy = self._offset(ref, e)
                if head.mode == "toward":
                    vx, vy = -vx, -vy
                h = self._cone(vx, vy, e.heading, self.config.delta2)
        return z3.And(p, h)

    def certify(self, program: Program, scene: Scene) -> list[str]:
        """Ids of the statements the solver cannot show to hold on the scene (empty: certified).

        One check for the whole program; only when it fails is each statement asked alone, to name it.
        Robust: each statement's violations over every perturbation must be unsat (robust_violations).
        """
        if is_robust(scene, self.config):
            by_id = scene.by_id()
            return [st.id for st in program.statements if not self.robust_holds(st, by_id)]
        t = time.perf_counter()  # building the formulas is solver work too: it is counted
        by_id = scene.by_id()
        formulas = [self.statement_formula(st, by_id) for st in program.statements]
        s = self.z3.SolverFor("QF_NRA")
        s.add(*formulas)
        ok = s.check() == self.z3.sat
        self.stats.queries += len(formulas)
        self.stats.seconds += time.perf_counter() - t
        if ok:
            return []
        return [st.id for st, f in zip(program.statements, formulas) if not self._check(f)]


    # ------------------------------------------------------------------------------------ robust certification
    def robust_violations(self, st: Statement, by_id: dict[str, Entity]) -> list[Any]:
        """Ways `st` (as printed) could fail under a perturbation of the scene within its bounds (synth.robust).

        The statement fails for some perturbation iff one of these is satisfiable: each is one part (distance,
        sector, coordinates, heading) over the perturbations of the entities that part depends on. A position
        part depends on p_e - p_r only, which ranges over the disc of radius rho_e + rho_r (Minkowski sum);
        the reference frame of a local position turns by (c, s) on the unit circle with c >= cos(eta), the
        rational of the float cos(eta) (the constant synth.robust widens by); heading offsets move linearly;
        sectors narrow by reduction 1 of synth.robust.
        """
        z3, cfg = self.z3, self.config
        e = by_id[st.id]
        out: list[Any] = []

        def offset(ref: Entity, sign: int = 1) -> tuple[Any, Any, list[Any]]:
            cx, cy = _exact_offset(ref, e)
            vx, vy = self.q(sign * cx), self.q(sign * cy)
            radius = radius_of(ref, e, cfg)
            if radius == 0:
                return vx, vy, []
            wx, wy = self._var("wx"), self._var("wy")
            return vx + wx, vy + wy, [wx * wx + wy * wy <= self.q(radius * radius)]

        def outside(v: Any, rng: Any) -> list[Any]:
            return [v < self.q(_printed(rng.lo)), v > self.q(_printed(rng.hi))]

        def cone_fails(vx: Any, vy: Any, cons: list[Any], axis: float, cone: float | None) -> None:
            out.append(z3.BoolVal(True) if cone is None else z3.And(*cons, z3.Not(self._cone(vx, vy, axis, cone))))

        pos, head = st.position, st.heading
        if isinstance(pos, AbsoluteXYPos):
            rho = Fraction(bounds_of(e, cfg).pos)
            wx, wy = self._var("wx"), self._var("wy")
            disc = wx * wx + wy * wy <= self.q(rho * rho)
            x, y = self.q(e.x) + wx, self.q(e.y) + wy
            out += [z3.And(disc, bad) for bad in outside(x, pos.x) + outside(y, pos.y)]
        elif isinstance(pos, DirectionPos):
            ref = by_id[pos.ref]
            vx, vy, cons = offset(ref)
            lo, hi = max(_printed(pos.distance.lo), Fraction(0)), _printed(pos.distance.hi)
            sq = vx * vx + vy * vy
            out += [z3.And(*cons, sq < self.q(lo * lo)), z3.And(*cons, sq > self.q(hi * hi))]
            cone_fails(vx, vy, cons, ref.heading + DIRECTIONS[pos.direction][1],
                       narrowed(cfg.delta1, bounds_of(ref, cfg).heading))
        else:
            # Local coordinates: Rot(c, s) L_u (c0 + w) = Rot(c, s) a + b, where a = L_u c0 is the observed local
            # vector and b = Rot(c, s) L_u w runs over the disc of radius |u| R (L_u is |u| times a rotation, and
            # rotations map a disc about 0 onto itself). Same set, but no products of unknowns: nlsat takes ms
            # here where the literal product of the turn and the disc took it up to a minute.
            ref = by_id[pos.ref]
            cx, cy = _exact_offset(ref, e)
            ux, uy = exact_heading_vector(ref.heading)
            ax, ay = cx * uy - cy * ux, cy * uy + cx * ux
            lx, ly, cons = self.q(ax), self.q(ay), []
            eta = bounds_of(ref, cfg).heading
            if eta > 0:
                c, s = self._var("c"), self._var("s")
                cons += [c * c + s * s == 1, c >= self.q(Fraction(math.cos(math.radians(eta))))]
                lx, ly = c * self.q(ax) - s * self.q(ay), s * self.q(ax) + c * self.q(ay)
            radius = radius_of(ref, e, cfg)
            if radius > 0:
                bx, by = self._var("bx"), self._var("by")
                cons.append(bx * bx + by * by <= self.q(radius * radius * (ux * ux + uy * uy)))
                lx, ly = lx + bx, ly + by
            out += [z3.And(*cons, bad) for bad in outside(lx, pos.lateral) + outside(ly, pos.forward)]
        if isinstance(head, FacingRelation):
            vx, vy, cons = offset(by_id[head.ref], -1 if head.mode == "toward" else 1)
            cone_fails(vx, vy, cons, e.heading, narrowed(cfg.delta2, bounds_of(e, cfg).heading))
        else:
            ref = by_id[head.ref] if isinstance(head, RelativeHeading) else None
            lo, hi = _printed(head.angle.lo), _printed(head.angle.hi)
            # The branch k that puts the observed offset just above lo (as _angle_in): the perturbed offsets
            # move continuously by less than half a turn, so within the Range they stay on that branch.
            gap = _frac(e.heading) - _frac(ref.heading if ref else 0.0)
            alpha = gap - 360 * ((gap - lo) // 360)
            eta = _frac(bounds_of(e, cfg).heading) + (_frac(bounds_of(ref, cfg).heading) if ref else 0)
            turn = self._var("theta")
            out += [z3.And(-self.q(eta) <= turn, turn <= self.q(eta), bad) for bad in outside(self.q(alpha) + turn, head.angle)]
        return out

    def robust_holds(self, st: Statement, by_id: dict[str, Entity]) -> bool:
        """Is every violation of `st` unsat?"""
        return not any(self._fresh_check(f) for f in self.robust_violations(st, by_id))

    def _fresh_check(self, *constraints: Any) -> bool:
        """A quantified question's check on a fresh nlsat solver. z3's incremental (push/pop) solver does not run
        nlsat, and on these questions it can take seconds where nlsat takes milliseconds; the qfnra-nlsat tactic
        (complete for nonlinear real arithmetic) skips SolverFor's portfolio set-up, 3x faster again."""
        t = time.perf_counter()
        s = self._nlsat.solver()
        s.add(*constraints)
        return self._verdict(s.check(), s, t)


def _exact_offset(ref: Entity, e: Entity) -> tuple[Fraction, Fraction]:
    return _frac(e.x) - _frac(ref.x), _frac(e.y) - _frac(ref.y)


@dataclass
class DrealBackend:
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
        self._fresh = 0

    def _var(self, stem: str) -> Any:
        self._fresh += 1
        return self.dreal.Variable(f"{stem}{self._fresh}")

    def _cone(self, vx: float, vy: float, axis_heading: float, delta: float) -> Any:
        ux, uy = (float(c) for c in exact_heading_vector(axis_heading))
        dot = vx * ux + vy * uy
        cos_sq = float(exact_cos_squared(delta))
        # Constants only: dReal still decides the (ground) formula, as the paper has it do.
        z = self._var("z")
        return self.dreal.And(z == dot, z > 0, z * z >= cos_sq * (vx * vx + vy * vy))

    def _sat(self, formula: Any) -> Any:
        t = time.perf_counter()
        box = self.dreal.CheckSatisfiability(formula, self.config.dreal_delta)
        self.stats.queries += 1
        self.stats.seconds += time.perf_counter() - t
        return box

    def _exact(self) -> Z3Backend:
        # Robust questions are about every point of a disc: z3 decides them exactly (dReal only delta-close).
        if self._z3 is None:
            self._z3 = Z3Backend(self.config, self.stats)
        return self._z3

    def position_relation(self, direction: str, ref: Entity, e: Entity) -> bool:
        if pair_is_robust(ref, e, self.config):
            return self._exact().position_relation(direction, ref, e)
        vx, vy = e.x - ref.x, e.y - ref.y
        d, a = self._var("d"), self._var("a")
        f = self.dreal.And(
            a >= 0, d >= 0, d * d == vx * vx + vy * vy, a <= d, d <= a + self.config.c_dist,
            self._cone(vx, vy, ref.heading + DIRECTIONS[direction][1], self.config.delta1),
        )
        return self._sat(f) is not None

    def heading_relation(self, mode: str, ref: Entity, e: Entity) -> bool:
        if pair_is_robust(ref, e, self.config):
            return self._exact().heading_relation(mode, ref, e)
        vx, vy = e.x - ref.x, e.y - ref.y
        if mode == "toward":
            vx, vy = -vx, -vy
        return self._sat(self._cone(vx, vy, e.heading, self.config.delta2)) is not None

    def measure(self, requests: list[MeasureRequest]) -> list[Measurement]:
        out = []
        for req in requests:
            vals: dict[str, Fraction] = {}
            if req.position_kind == "direction":
                vx, vy = req.target.x - req.position_ref.x, req.target.y - req.position_ref.y
                d = self._var("d")
                box = self._sat(self.dreal.And(d >= 0, d * d == vx * vx + vy * vy))
                if box is None:
                    raise RuntimeError("dReal found no distance")
                vals["distance"] = Fraction(box[d].mid())
            elif req.position_kind == "local":
                from synth.geometry import to_local

                lx, ly = to_local(req.target.x - req.position_ref.x, req.target.y - req.position_ref.y,
                                  req.position_ref.heading)
                vals["lateral"], vals["forward"] = Fraction(lx), Fraction(ly)
            if req.heading_kind in ("relative", "absolute"):
                from synth.geometry import signed

                base = req.heading_ref.heading if req.heading_kind == "relative" else 0.0
                vals["angle"] = Fraction(signed(req.target.heading - base))
            out.append(Measurement(**vals))
        return out

    def certify(self, program: Program, scene: Scene) -> list[str]:
        # dReal is delta-complete: it can confirm the delta-weakening of a formula, not refute it exactly.
        # Certification therefore rests on z3 where it is present, the solver of record for exactness.
        return Z3Backend(self.config).certify(program, scene)
