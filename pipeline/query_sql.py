"""A pattern compiled into one DuckDB query over the frames rows: self-joins per pattern name, one predicate builder
per clause kind, and a split of every candidate binding into *sure* and *to check*.

Exactness. synth.semantics decides with float atan2 bearings and fmod normalisation. Each builder writes the same
formula in SQL (same operations, in the same order; DuckDB's `%` on doubles is C fmod, exact as Python's) and
returns two conditions:
- `candidate`, the formula with every bound widened by SLACK: a superset of the true matches, used to join;
- `sure`, every bound narrowed by SLACK: only true matches.
The two evaluations differ only by libm rounding (atan2, sin, cos, sqrt vs hypot: an ulp or so, below 1e-9 for
coordinates up to WILD_XY metres and headings up to WILD_HEADING degrees), far below SLACK, so a binding that is a
candidate but not sure is re-checked by the semantics' own functions (a Python UDF, evaluated only for those rows),
and the matches are exactly the checker's. An entity beyond those magnitudes is *wild*: every clause it takes part in
is a candidate and never sure, so Python decides it.

Join order and memory are DuckDB's: statements that refer only to ego or to nothing filter each name's rows before
any join (they are per-row conditions, with ego joined in per frame), statements between names are join filters on
the frame, and DuckDB spills to its temporary directory under its memory limit.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from synth.config import SynthConfig
from synth.dsl import (
    DIRECTIONS,
    AbsoluteHeading,
    AbsoluteXYPos,
    DirectionPos,
    FacingRelation,
    LocalXYPos,
    RelativeHeading,
    Statement,
)
from synth.pattern import Pattern, matched_types
from synth.scene import EGO_ID
from synth.semantics import ANGLE_EPS, LENGTH_EPS

SLACK = 1e-6  # degrees; metres per metre of bound (at least 1 m)
WILD_XY = 1e6
WILD_HEADING = 1e4
ROWS = "r2s_rows"  # the view of the frames rows the query reads (pipeline.query creates it)
EXACT_UDF = "r2s_exact"

# SQL versions of synth.geometry's normalize / angular_difference / bearing, operation for operation.
MACROS = (
    "CREATE OR REPLACE TEMP MACRO r2s_norm(a) AS (CASE WHEN (a) % 360.0 >= 0.0 THEN (a) % 360.0 "
    "WHEN (a) % 360.0 + 360.0 >= 360.0 THEN 0.0 ELSE (a) % 360.0 + 360.0 END)",
    "CREATE OR REPLACE TEMP MACRO r2s_w(u, v) AS "
    "least(abs(r2s_norm(u) - r2s_norm(v)), 360.0 - abs(r2s_norm(u) - r2s_norm(v)))",
    "CREATE OR REPLACE TEMP MACRO r2s_bearing(fx, fy, tx, ty) AS r2s_norm(degrees(atan2(ty - fy, tx - fx)) - 90.0)",
)


def lit(v: float) -> str:
    """A double literal that DuckDB reads back to exactly v (a bare decimal would be typed DECIMAL)."""
    return f"'{float(v)!r}'::DOUBLE"


@dataclass(frozen=True)
class Condition:
    candidate: str  # true for every binding the semantics accept
    sure: str  # true only for bindings the semantics accept

    @staticmethod
    def all(conds: list[Condition]) -> Condition:
        if not conds:
            return Condition("TRUE", "TRUE")
        return Condition(" AND ".join(f"({c.candidate})" for c in conds), " AND ".join(f"({c.sure})" for c in conds))


def _slack_len(bound: float) -> float:
    return SLACK * max(1.0, abs(bound))


def _within(expr: str, lo: float, hi: float) -> Condition:
    """lo <= expr <= hi for bounds already carrying the semantics' own epsilon; lengths."""
    return Condition(f"{expr} >= {lit(lo - _slack_len(lo))} AND {expr} <= {lit(hi + _slack_len(hi))}",
                     f"{expr} >= {lit(lo + _slack_len(lo))} AND {expr} <= {lit(hi - _slack_len(hi))}")


def _angle_at_most(expr: str, bound: float) -> Condition:
    return Condition(f"{expr} <= {lit(bound + SLACK)}", f"{expr} <= {lit(bound - SLACK)}")


def _distinct_points(e: str, r: str) -> str:
    # Exact in both evaluations: a bearing between coincident points is undefined, no relation holds there.
    return f"NOT ({e}.x = {r}.x AND {e}.y = {r}.y)"


def _and_exact(exact: str, cond: Condition) -> Condition:
    return Condition(f"{exact} AND {cond.candidate}", f"{exact} AND {cond.sure}")


# ----------------------------------------------------------------------------- one builder per clause kind
# Each takes the clause, the SQL alias of the entity and of its reference (None when absolute), and the config.

def direction_pos(pos: DirectionPos, e: str, r: str | None, config: SynthConfig) -> Condition:
    dx, dy = f"({e}.x - {r}.x)", f"({e}.y - {r}.y)"
    dist = _within(f"sqrt({dx} * {dx} + {dy} * {dy})", pos.distance.lo - LENGTH_EPS, pos.distance.hi + LENGTH_EPS)
    phi = DIRECTIONS[pos.direction][1]
    angle = _angle_at_most(f"r2s_w(r2s_bearing({r}.x, {r}.y, {e}.x, {e}.y), {r}.heading + {lit(phi)})",
                           config.delta1 + ANGLE_EPS)
    return _and_exact(_distinct_points(e, r), Condition.all([dist, angle]))


def local_xy_pos(pos: LocalXYPos, e: str, r: str | None, config: SynthConfig) -> Condition:
    dx, dy = f"({e}.x - {r}.x)", f"({e}.y - {r}.y)"
    c, s = f"cos(radians({r}.heading))", f"sin(radians({r}.heading))"
    lx, ly = f"({dx} * {c} + {dy} * {s})", f"({dy} * {c} - {dx} * {s})"
    return Condition.all([_within(lx, pos.lateral.lo - LENGTH_EPS, pos.lateral.hi + LENGTH_EPS),
                          _within(ly, pos.forward.lo - LENGTH_EPS, pos.forward.hi + LENGTH_EPS)])


def absolute_xy_pos(pos: AbsoluteXYPos, e: str, r: str | None, config: SynthConfig) -> Condition:
    return Condition.all([_within(f"{e}.x", pos.x.lo - LENGTH_EPS, pos.x.hi + LENGTH_EPS),
                          _within(f"{e}.y", pos.y.lo - LENGTH_EPS, pos.y.hi + LENGTH_EPS)])


def facing_relation(head: FacingRelation, e: str, r: str | None, config: SynthConfig) -> Condition:
    if head.mode == "toward":
        target = f"r2s_bearing({e}.x, {e}.y, {r}.x, {r}.y)"
    else:
        target = f"r2s_bearing({r}.x, {r}.y, {e}.x, {e}.y)"
    return _and_exact(_distinct_points(e, r), _angle_at_most(f"r2s_w({e}.heading, {target})", config.delta2 + ANGLE_EPS))


def _angle_range(heading: str, base: str | None, lo: float, hi: float) -> Condition:
    """synth.semantics._in_angle_range: heading = N(base + alpha) for some alpha in [lo, hi]."""
    if hi - lo >= 360.0:
        return Condition("TRUE", "TRUE")
    offset = f"({heading} - {base})" if base is not None else heading
    past = f"r2s_norm({offset} - {lit(lo)})"
    width, wrap = (hi - lo) + ANGLE_EPS, 360.0 - ANGLE_EPS
    return Condition(f"({past} <= {lit(width + SLACK)} OR {past} >= {lit(wrap - SLACK)})",
                     f"({past} <= {lit(width - SLACK)} OR {past} >= {lit(wrap + SLACK)})")


def relative_heading(head: RelativeHeading, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _angle_range(f"{e}.heading", f"{r}.heading", head.angle.lo, head.angle.hi)


def absolute_heading(head: AbsoluteHeading, e: str, r: str | None, config: SynthConfig) -> Condition:
    return _angle_range(f"{e}.heading", None, head.angle.lo, head.angle.hi)


Builder = Callable[[object, str, "str | None", SynthConfig], Condition]
BUILDERS: dict[type, Builder] = {
    DirectionPos: direction_pos,
    LocalXYPos: local_xy_pos,
    AbsoluteXYPos: absolute_xy_pos,
    FacingRelation: facing_relation,
    RelativeHeading: relative_heading,
    AbsoluteHeading: absolute_heading,
}


def clause_condition(clause, e: str, r: str | None, config: SynthConfig) -> Condition:
    """A clause's condition, with wild entities always to check (see the module docstring)."""
    cond = BUILDERS[type(clause)](clause, e, r, config)
    wild = f"{e}.wild" + (f" OR {r}.wild" if r is not None else "")
    return Condition(f"({cond.candidate}) OR {wild}", f"({cond.sure}) AND NOT ({wild})")


# ----------------------------------------------------------------------------------------- the whole query

def _alias(k: int) -> str:
    return f"t{k}"


def _quote(name: str) -> str:
    return f'"{name}"'  # names are identifiers (the parser checks them), so quoting is enough


def clauses(st: Statement) -> tuple:
    """The parts of a statement that relate it to a reference (or to nothing): its position and its heading."""
    return (st.position, st.heading)


def compile_pattern(pattern: Pattern, config: SynthConfig, all_bindings: bool) -> str:
    """The query: one row per matching frame (frame_id, scene, timestamp_us, n_matches, binding = the first
    binding), or with all_bindings one row per binding; frames in input order, bindings in lexicographic order of
    their entities' input rows. It calls r2s_exact(numbers, types) on the candidates that are not sure: numbers are
    ego's x, y, heading, then x, y, heading per name; types one per name."""
    names = pattern.names
    alias = {name: _alias(k) for k, name in enumerate(names)} | {EGO_ID: "g"}
    ctes = [f"ego AS (SELECT frame_id, ord AS frame_ord, scene, timestamp_us, x, y, heading, wild FROM {ROWS} "
            "WHERE is_ego)"]
    joins, sure_parts, candidate_parts = [], [], []
    for k, st in enumerate(pattern.statements):
        a = alias[st.id]
        # Clauses on ego or on nothing filter the name's rows (ego joined per frame); the others filter the join.
        unary = [clause_condition(c, "f", None if c.ref is None else "g", config)
                 for c in clauses(st) if c.ref in (None, EGO_ID)]
        binary = [clause_condition(c, a, alias[c.ref], config) for c in clauses(st) if c.ref not in (None, EGO_ID)]
        where = ["NOT f.is_ego"]
        types = matched_types(st.type)
        if types is not None:
            where.append(f"f.type IN ({', '.join(repr(t) for t in sorted(types))})")
        cond = Condition.all(unary)
        where.append(f"({cond.candidate})")
        ego_cols = ", g.x AS ego_x, g.y AS ego_y, g.heading AS ego_heading, g.frame_ord, g.scene, g.timestamp_us" if k == 0 else ""
        join_ego = " JOIN ego g ON f.frame_id = g.frame_id" if k == 0 or any(
            c.ref == EGO_ID for c in clauses(st)) else ""
        ctes.append(f"{a} AS (SELECT f.frame_id, f.ord, f.entity_id, f.type, f.x, f.y, f.heading, f.wild, "
                    f"({cond.sure}) AS sure{ego_cols} FROM {ROWS} f{join_ego} WHERE {' AND '.join(where)})")
        sure_parts.append(f"{a}.sure")
        if k == 0:
            continue
        on = [f"{a}.frame_id = {alias[names[0]]}.frame_id"]
        # Injective: a different input row from every earlier name whose types can coincide.
        on += [f"{a}.ord <> {alias[other.id]}.ord" for other in pattern.statements[:k] if _overlap(st.type, other.type)]
        bcond = Condition.all(binary)
        on.append(f"({bcond.candidate})")
        sure_parts.append(f"({bcond.sure})")
        candidate_parts.append(f"({bcond.candidate})")
        joins.append(f"JOIN {a} ON {' AND '.join(on)}")
    first = alias[names[0]]
    numbers = [f"{first}.ego_x", f"{first}.ego_y", f"{first}.ego_heading"]
    numbers += [f"{alias[n]}.{c}" for n in names for c in ("x", "y", "heading")]
    types = [f"{alias[n]}.type" for n in names]
    key = "[" + ", ".join(f"{alias[n]}.ord" for n in names) + "]"
    binding = "struct_pack(" + ", ".join(f"{_quote(n)} := {alias[n]}.entity_id" for n in names) + ")"
    ctes.append(
        f"m AS (SELECT {first}.frame_id, {first}.frame_ord, {first}.scene, {first}.timestamp_us, {key} AS key, "
        f"{binding} AS binding FROM {first} {' '.join(joins)} "
        # CASE, not OR: DuckDB reorders a filter's conjuncts adaptively, and the exact check must only ever see
        # candidates that are not sure.
        f"WHERE CASE WHEN {' AND '.join(sure_parts)} THEN TRUE WHEN {' AND '.join(candidate_parts) or 'TRUE'} "
        f"THEN {EXACT_UDF}([{', '.join(numbers)}], [{', '.join(types)}]) ELSE FALSE END)")
    if all_bindings:
        select = ("SELECT frame_id, scene, timestamp_us, count(*) OVER (PARTITION BY frame_ord) AS n_matches, binding "
                  "FROM m ORDER BY frame_ord, key")
    else:
        select = ("SELECT frame_id, any_value(scene) AS scene, any_value(timestamp_us) AS timestamp_us, "
                  "count(*) AS n_matches, arg_min(binding, key) AS binding FROM m GROUP BY frame_ord, frame_id "
                  "ORDER BY frame_ord")
    return "WITH " + ",\n".join(ctes) + "\n" + select


def _overlap(t1: str, t2: str) -> bool:
    a, b = matched_types(t1), matched_types(t2)
    return a is None or b is None or bool(a & b)
