"""Certification without the solver (synth.intervals, Part.decide) and Range values without it
(Part.exact_measure), against the solver itself.

Whenever the interval arithmetic decides a clause, z3 deciding the clause's formula (Part.formula, what
certification asked before) must agree; clauses are built around every boundary (distances a hair inside and
outside a printed bound, targets on a sector's or a facing cone's edge, headings at a Range's end), where a
float decision would be wrong. The exact Range values must centre every Range where the solver's model does.
"""

from __future__ import annotations

import math
from fractions import Fraction

from hypothesis import given
from hypothesis import strategies as st

from synth.config import SynthConfig
from synth.parts import HEADING, POSITION, MeasureRequest, Want
from synth.parts.heading import AbsoluteHeading, FacingRelation, RelativeHeading
from synth.parts.position import DIRECTION_NAMES, DIRECTIONS, AbsoluteXYPos, DirectionPos, LocalXYPos
from synth.scene import Entity
from synth.smt import Z3Backend
from synth.smt.certify import certify
from synth.smt.measure import model_measure
from synth.syntax import Range, fmt_number

CFG = SynthConfig()


def entity(eid: str, x: float, y: float, h: float) -> Entity:
    return Entity(eid, "Car", x, y, h % 360.0)


def z3_holds(backend: Z3Backend, clause, e, ref) -> bool:
    return backend.check(clause.formula(backend, e, ref))


def near(v: float, nudge: int) -> float:
    """v rounded to 2 decimals, then moved by `nudge` cents' hundredths: bounds on, just in and just out."""
    return float(fmt_number(v)) + nudge * 0.0001


def rng(a: float, b: float) -> Range:
    return Range(min(a, b), max(a, b))


coords = st.floats(-60, 60, allow_nan=False)
angles = st.floats(0, 360, allow_nan=False, exclude_max=True)
nudges = st.integers(-2, 2)


@given(rx=coords, ry=coords, rh=angles, ex=coords, ey=coords, eh=angles, code=st.integers(0, 3),
       edge=st.sampled_from([-1.0, 1.0]), slack=st.floats(-1e-6, 1e-6), n_lo=nudges, n_hi=nudges,
       on_edge=st.booleans())
def test_direction_clauses_are_decided_as_the_solver_decides(rx, ry, rh, ex, ey, eh, code, edge, slack, n_lo, n_hi,
                                                              on_edge):
    ref = entity("r", rx, ry, rh)
    if on_edge:
        # The target on (or a hair off) the sector's edge: reference heading + phi +- delta1.
        axis = math.radians(rh + DIRECTIONS[DIRECTION_NAMES[code]][1] + edge * (CFG.delta1 + slack))
        d = math.hypot(ex - rx, ey - ry) + 1.0
        ex, ey = rx - d * math.sin(axis), ry + d * math.cos(axis)
    e = entity("e", ex, ey, eh)
    dist = math.hypot(e.x - ref.x, e.y - ref.y)
    clause = DirectionPos(DIRECTION_NAMES[code], "r", rng(max(0.0, near(dist - 2.5, n_lo)), near(dist, n_hi)))
    backend = Z3Backend(CFG)
    fact = clause.decide(e, ref, CFG)
    assert fact is None or fact == z3_holds(backend, clause, e, ref)


@given(rx=coords, ry=coords, rh=angles, ex=coords, ey=coords, n=st.tuples(nudges, nudges, nudges, nudges),
       absolute=st.booleans())
def test_coordinate_clauses_are_decided_as_the_solver_decides(rx, ry, rh, ex, ey, n, absolute):
    ref, e = entity("r", rx, ry, rh), entity("e", ex, ey, 0.0)
    backend = Z3Backend(CFG)
    if absolute:
        clause = AbsoluteXYPos(rng(near(ex, n[0]), near(ex, n[1])), rng(near(ey, n[2]), near(ey, n[3])))
        ref = None
    else:
        t = math.radians(rh)
        lx = (ex - rx) * math.cos(t) + (ey - ry) * math.sin(t)
        ly = (ey - ry) * math.cos(t) - (ex - rx) * math.sin(t)
        clause = LocalXYPos(rng(near(lx, n[0]), near(lx, n[1]) + 5), rng(near(ly, n[2]) - 5, near(ly, n[3])), "r")
    fact = clause.decide(e, ref, CFG)
    assert fact is None or fact == z3_holds(backend, clause, e, ref)


@given(rx=coords, ry=coords, rh=angles, ex=coords, ey=coords, eh=angles, mode=st.sampled_from(["toward", "away"]),
       edge=st.sampled_from([-1.0, 1.0]), slack=st.floats(-1e-6, 1e-6), on_edge=st.booleans())
def test_facing_clauses_are_decided_as_the_solver_decides(rx, ry, rh, ex, ey, eh, mode, edge, slack, on_edge):
    ref = entity("r", rx, ry, rh)
    if on_edge:
        # The target's heading on (or a hair off) the edge of the cone around the bearing.
        b = math.degrees(math.atan2(ry - ey, rx - ex)) - 90.0 if mode == "toward" else \
            math.degrees(math.atan2(ey - ry, ex - rx)) - 90.0
        eh = b + edge * (CFG.delta2 + slack)
    e = entity("e", ex, ey, eh)
    clause = FacingRelation(mode, "r")
    backend = Z3Backend(CFG)
    fact = clause.decide(e, ref, CFG)
    assert fact is None or fact == z3_holds(backend, clause, e, ref)


@given(rh=angles, eh=angles, n_lo=nudges, n_hi=nudges, turns=st.integers(-2, 2), relative=st.booleans())
def test_angle_clauses_are_decided_exactly(rh, eh, n_lo, n_hi, turns, relative):
    ref, e = entity("r", 0, 0, rh), entity("e", 3, 4, eh)
    gap = (e.heading - (ref.heading if relative else 0.0)) % 360 + 360 * turns
    angle = Range(near(gap, n_lo), near(gap, n_hi) + 5)
    clause = RelativeHeading(angle, "r") if relative else AbsoluteHeading(angle)
    backend = Z3Backend(CFG)
    fact = clause.decide(e, ref if relative else None, CFG)
    assert fact is not None  # rational comparisons: always decided
    assert fact == z3_holds(backend, clause, e, ref if relative else None)


def test_a_distance_on_its_printed_bound_is_decided_exactly():
    ref, e = entity("r", 0.0, 0.0, 90.0), entity("e", -3.0, 4.0, 0.0)  # |v| = 5, bearing within the left sector?
    assert DirectionPos("left", "r", Range(0.0, 5.0)).decide(e, ref, CFG) is False  # 53 deg off
    ahead = entity("a", 0.0, 5.0, 0.0)
    ref0 = entity("r", 0.0, 0.0, 0.0)
    assert DirectionPos("ahead", "r", Range(0.0, 5.0)).decide(ahead, ref0, CFG) is True
    assert DirectionPos("ahead", "r", Range(5.0, 10.0)).decide(ahead, ref0, CFG) is True
    assert DirectionPos("ahead", "r", Range(0.0, 4.99)).decide(ahead, ref0, CFG) is False


def test_certification_asks_the_solver_only_what_intervals_leave(monkeypatch, real_frames):
    from synth.synthesize import synthesize

    scene = max(real_frames, key=lambda s: len(s.others))
    result = synthesize(scene, CFG)
    assert result.certified and result.stats.smt_queries == 0
    backend = Z3Backend(CFG)
    # Intervals that can decide nothing: every clause goes to the solver, and it certifies the same program.
    for kind in {k.clause for k in POSITION.clause_kinds + HEADING.clause_kinds}:
        monkeypatch.setattr(kind, "decide", lambda *a: None)
    assert certify(backend, result.program, scene) == []
    assert backend.stats.queries == len(result.program.statements)


def test_a_program_that_misses_the_scene_is_refuted_both_ways(monkeypatch, real_frames):
    from dataclasses import replace

    from synth.dsl import Program
    from synth.synthesize import synthesize

    scene = next(s for s in real_frames if len(s.others) >= 5)
    program = synthesize(scene, CFG).program
    st0 = program.statements[0]
    h = scene.by_id()[st0.id].heading
    wrong = Program((replace(st0, heading=AbsoluteHeading(Range(round(h) + 10.0, round(h) + 15.0))),)
                    + program.statements[1:])
    assert certify(Z3Backend(CFG), wrong, scene) == [st0.id]
    monkeypatch.setattr(AbsoluteHeading, "decide", lambda *a: None)
    assert certify(Z3Backend(CFG), wrong, scene) == [st0.id]


def test_exact_range_values_centre_ranges_as_the_solver_model_does(real_frames):
    from synth.ranges import centred

    backend = Z3Backend(CFG)
    for scene in real_frames[:6]:
        ents = (scene.ego,) + scene.others
        requests = [MeasureRequest(e, (Want(POSITION, "distance", r), Want(POSITION, "local", r), Want(HEADING, "angle", r)))
                    for e in ents[1:] for r in ents[:3] if r is not e]
        model = model_measure(backend, requests)
        exact = [tuple(w.part.exact_measure(w.quantity, q.target, w.ref) for w in q.wants) for q in requests]
        for m, x in zip(model, exact):
            for vm, vx in zip(m, x):
                for a, b in zip(vm, vx):
                    assert abs(a - b) <= Fraction(1, 10**12)
                    assert centred(a, 5.0) == centred(b, 5.0)


def test_sqrt_rational_is_exact_where_it_can_be_and_close_below_elsewhere():
    from synth.geometry import sqrt_rational

    assert sqrt_rational(Fraction(25, 16)) == Fraction(5, 4)
    r = sqrt_rational(Fraction(2))
    assert r * r < 2 < (r + Fraction(1, 10**15)) ** 2


def _centred_by_definition(value, width, clamp=False) -> Range:
    """Range(a, a + w), w = width rounded to cents, a = value - w / 2 rounded to cents (half to even), a >= 0 when
    clamped: the definition, in Fractions, step by step."""
    cent = Fraction(1, 100)
    w = Fraction(round(Fraction(width) / cent)) * cent
    lo = Fraction(round((Fraction(value) - w / 2) / cent)) * cent
    if clamp and lo < 0:
        lo = Fraction(0)
    return Range(float(lo), float(lo + w))


@given(value=st.one_of(st.floats(-500, 500), st.fractions(max_denominator=10**6).filter(lambda f: abs(f) < 500),
                       st.integers(-100000, 100000).map(lambda k: Fraction(k, 200))),
       width=st.sampled_from([5.0, 2.0, 0.5, 4.99, 0.015, 3.333]), clamp=st.booleans())
def test_centred_is_its_definition_at_every_tie(value, width, clamp):
    from synth.ranges import centred

    assert centred(value, width, clamp) == _centred_by_definition(value, width, clamp)


@given(rx=coords, ry=coords, rh=angles, ex=coords, ey=coords, local=st.booleans())
def test_centring_values_centre_every_range_as_the_exact_value(rx, ry, rh, ex, ey, local):
    from synth.ranges import centred

    ref, e = entity("r", rx, ry, rh), entity("e", ex, ey, 0.0)
    quantity = "local" if local else "distance"
    fast = POSITION.exact_measure(quantity, e, ref)
    exact = POSITION._exact(quantity, e, ref)
    for a, b in zip(fast, exact):
        for width in (5.0, 2.0, 0.01):
            assert centred(a, width, not local) == centred(b, width, not local)


def test_a_centre_on_a_cell_edge_is_computed_exactly():
    from flint import arb

    from synth.intervals import centring_value

    assert centring_value(arb(2.5), lambda: Fraction(5, 2)) == Fraction(5, 2)  # exactly on a multiple of 1/200
    assert centring_value(arb(1) / 3, lambda: Fraction(1, 3)) != Fraction(1, 3)  # inside a cell: the midpoint
