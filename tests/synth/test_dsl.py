"""The DSL printer and parser round-trip exactly; anything else is a one-line DslError."""

from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from synth.dsl import (
    AbsoluteHeading,
    AbsoluteSpeed,
    AbsoluteXYPos,
    DirectionPos,
    DslError,
    FacingRelation,
    LocalXYPos,
    MovingLike,
    Program,
    Range,
    RelativeHeading,
    RelativeSpeed,
    Statement,
    Stationary,
    fmt_number,
    parse_program,
)
from synth.scene import ENTITY_TYPES

cents = st.integers(-100000, 100000).map(lambda c: c / 100)


@st.composite
def ranges(draw):
    a, b = sorted((draw(cents), draw(cents)))
    return Range(a, b)


@st.composite
def programs(draw):
    n = draw(st.integers(0, 8))
    statements = []
    for i in range(n):
        refs = ["ego"] + [s.id for s in statements]
        ref = draw(st.sampled_from(refs))
        pos = draw(st.one_of(
            st.builds(DirectionPos, st.sampled_from(["ahead", "behind", "left", "right"]), st.just(ref), ranges()),
            st.builds(LocalXYPos, ranges(), ranges(), st.just(ref)),
            st.builds(AbsoluteXYPos, ranges(), ranges()),
        ))
        head = draw(st.one_of(
            st.builds(FacingRelation, st.sampled_from(["toward", "away"]), st.sampled_from(refs)),
            st.builds(RelativeHeading, ranges(), st.sampled_from(refs)),
            st.builds(AbsoluteHeading, ranges()),
        ))
        motion = draw(st.one_of(
            st.none(), st.builds(Stationary), st.builds(MovingLike, st.sampled_from(refs)),
            st.builds(RelativeSpeed, ranges(), st.sampled_from(refs)), st.builds(AbsoluteSpeed, ranges()),
        ))
        statements.append(Statement(f"e{i}", draw(st.sampled_from(sorted(ENTITY_TYPES))), pos, head, motion))
    return Program(tuple(statements))


@given(programs())
def test_print_then_parse_is_the_identity(program):
    text = str(program)
    assert parse_program(text) == program
    assert str(parse_program(text)) == text


def test_costs_follow_the_grammar():
    p = parse_program(
        "a = new Car ahead of ego by Range(0, 5), facing toward ego\n"              # 0 + 0
        "b = new Car on Range(1, 6) @ Range(2, 7) relative to a, facing away from a\n"  # 1 + 0
        "c = new Truck on Range(1, 6) @ Range(2, 7), facing Range(-2.5, 2.5) deg relative to b\n"  # 2 + 1
        "d = new Pedestrian behind c by Range(3, 8), facing Range(10, 15) deg\n"    # 0 + 2
    )
    assert [s.cost for s in p.statements] == [0, 1, 3, 2]
    assert p.cost == 6


def test_comments_and_blank_lines_are_allowed():
    p = parse_program("# a program\n\na = new Car left of ego by Range(1, 6), facing away from ego  # left\n")
    assert len(p.statements) == 1 and p.statements[0].position.direction == "left"


@pytest.mark.parametrize("text,needle", [
    ("a = new Car ahead of b by Range(0, 5), facing toward ego", "neither ego nor declared"),
    ("a = new Car ahead of ego by Range(5, 0), facing toward ego", "empty"),
    ("a = new Car ahead of ego by Range(0, 5) facing toward ego", "expected ,"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego extra", "unexpected 'extra'"),
    ("ego = new Car ahead of ego by Range(0, 5), facing toward ego", "never declared"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego\na = new Car behind ego by Range(0, 5), facing toward ego", "twice"),
    ("a = new Rocket ahead of ego by Range(0, 5), facing toward ego", "unknown type"),
    ("__import__ = new Car ahead of ego by Range(0, 5), facing toward ego", "identifier"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego; import os", "unexpected character"),
    ("a = new Car above ego by Range(0, 5), facing toward ego", "expected a position"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego, moving fast", "expected Range"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego, moving Range(1, 3) km/h", "expected m"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego, moving like b", "neither ego nor declared"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego, stationary, stationary", "expected a lane clause"),
    ("a = new Car ahead of ego by Range(0, 5), facing toward ego,", "expected one of: anywhere, in, moving, off, on, stationary"),
    ("a = new Car ahead of ego by Range(0, 1e999), facing toward ego", "out of range"),
])
def test_parse_errors_are_one_line_with_a_position(text, needle):
    with pytest.raises(DslError) as err:
        parse_program(text)
    msg = str(err.value)
    assert needle in msg and "\n" not in msg and re.match(r"line \d+ column \d+: ", msg)


@given(st.text(max_size=300))
def test_arbitrary_text_is_parsed_or_refused_with_dsl_error(text):
    try:
        parse_program(text)
    except DslError as exc:
        assert "\n" not in str(exc)


@pytest.mark.parametrize("v,s", [(0.0, "0"), (-0.001, "0"), (2.5, "2.5"), (-2.5, "-2.5"), (7.499, "7.5"), (10.0, "10"), (1.23, "1.23")])
def test_numbers_print_with_at_most_two_decimals(v, s):
    assert fmt_number(v) == s
