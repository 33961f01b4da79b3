"""The semantics checker, against cases computed by hand from the paper's definitions."""

from __future__ import annotations

import math

from synth.config import SynthConfig
from synth.dsl import parse_program
from synth.scene import scene_from_dict
from synth.semantics import check


def scene(*ents):
    return scene_from_dict({"frame_id": "t", "entities": [{"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0}]
                            + [{"id": i, "type": t, "x": x, "y": y, "heading": h} for i, t, x, y, h in ents]})


def parts(result):
    return sorted((v.entity, v.part) for v in result.violations)


def test_direction_sector_and_distance_bounds():
    # car1 at bearing 9 deg left of ego's axis, 10 m: ahead of ego (delta1 = 10), distance 10.
    x, y = -10 * math.sin(math.radians(9)), 10 * math.cos(math.radians(9))
    s = scene(("car1", "Car", x, y, 0))
    assert check(parse_program("car1 = new Car ahead of ego by Range(7.5, 12.5), facing Range(0, 5) deg\n"), s).ok
    assert parts(check(parse_program("car1 = new Car ahead of ego by Range(10.01, 15), facing Range(0, 5) deg\n"), s)) == [("car1", "position")]
    assert parts(check(parse_program("car1 = new Car left of ego by Range(5, 15), facing Range(0, 5) deg\n"), s)) == [("car1", "position")]
    # With delta1 = 8 the same point is outside the ahead sector.
    tight = SynthConfig(delta1=8.0)
    assert parts(check(parse_program("car1 = new Car ahead of ego by Range(7.5, 12.5), facing Range(0, 5) deg\n"), s, tight)) == [("car1", "position")]


def test_sectors_turn_with_the_reference_heading():
    # car1 faces west (90); car2 is 5 m west of car1: ahead of car1; 5 m south of car1: left of car1.
    s = scene(("car1", "Car", 0, 10, 90), ("car2", "Car", -5, 10, 0), ("car3", "Car", 0, 5, 0))
    prog = parse_program(
        "car1 = new Car ahead of ego by Range(7.5, 12.5), facing Range(87.5, 92.5) deg\n"
        "car2 = new Car ahead of car1 by Range(2.5, 7.5), facing Range(-5, 5) deg\n"
        "car3 = new Car left of car1 by Range(2.5, 7.5), facing Range(-90, -85) deg relative to car1\n"
    )
    assert check(prog, s).ok


def test_local_coordinates_in_the_reference_frame():
    # Reference faces west (90): its right is +y (north), its forward is -x.
    s = scene(("car1", "Car", 0, 10, 90), ("car2", "Car", -4, 13, 0))
    # lx = dx cos t + dy sin t = -4*0 + 3*1 = 3; ly = dy cos t - dx sin t = 0 + 4 = 4.
    ok = "car2 = new Car on Range(2, 4) @ Range(3, 5) relative to car1, facing Range(-1, 1) deg\n"
    bad = "car2 = new Car on Range(-4, -2) @ Range(3, 5) relative to car1, facing Range(-1, 1) deg\n"
    head = "car1 = new Car on Range(-1, 1) @ Range(9, 11), facing Range(89, 91) deg\n"
    assert check(parse_program(head + ok), s).ok
    assert parts(check(parse_program(head + bad), s)) == [("car2", "position")]


def test_facing_toward_and_away_with_tolerance():
    s = scene(("car1", "Car", 0, 10, 184), ("car2", "Car", 0, 20, 6))
    base = "car1 = new Car ahead of ego by Range(7.5, 12.5), facing toward ego\n"
    assert check(parse_program(base + "car2 = new Car ahead of ego by Range(17.5, 22.5), facing Range(5, 10) deg\n"), s).ok
    # car2 heading 6: away from ego is 0 -> off by 6 > delta2 = 5.
    r = check(parse_program(base + "car2 = new Car ahead of ego by Range(17.5, 22.5), facing away from ego\n"), s)
    assert parts(r) == [("car2", "heading")]
    assert check(parse_program(base + "car2 = new Car ahead of ego by Range(17.5, 22.5), facing away from ego\n"), s,
                 SynthConfig(delta2=6.5)).ok


def test_heading_ranges_wrap_around_360():
    s = scene(("car1", "Car", 0, 10, 358))
    assert check(parse_program("car1 = new Car ahead of ego by Range(7.5, 12.5), facing Range(355, 365) deg\n"), s).ok
    assert check(parse_program("car1 = new Car ahead of ego by Range(7.5, 12.5), facing Range(-5, 0) deg\n"), s).ok
    assert not check(parse_program("car1 = new Car ahead of ego by Range(7.5, 12.5), facing Range(0, 5) deg\n"), s).ok


def test_scope_missing_extra_and_type():
    s = scene(("car1", "Car", 0, 10, 0), ("ped1", "Pedestrian", 3, 3, 0))
    from synth.dsl import DirectionPos, FacingRelation, Program, Range, Statement
    # Built by hand to bypass the parser's scoping: the checker must catch it too.
    early = Statement("car1", "Car", DirectionPos("ahead", "ped1", Range(0, 20)), FacingRelation("away", "ego"))
    r = check(Program((early,)), s)
    assert parts(r) == [("car1", "scope"), ("ped1", "missing")]
    wrong_type = parse_program("car1 = new Truck ahead of ego by Range(7.5, 12.5), facing away from ego\n"
                               "ghost = new Car ahead of ego by Range(7.5, 12.5), facing away from ego\n")
    assert parts(check(wrong_type, s)) == [("car1", "type"), ("ghost", "extra"), ("ped1", "missing")]


def test_coincident_points_have_no_relation():
    s = scene(("car1", "Car", 0, 0, 0))
    assert not check(parse_program("car1 = new Car ahead of ego by Range(0, 5), facing Range(0, 1) deg\n"), s).ok
    assert not check(parse_program("car1 = new Car on Range(0, 1) @ Range(0, 1), facing away from ego\n"), s).ok
    assert check(parse_program("car1 = new Car on Range(0, 1) @ Range(0, 1), facing Range(0, 1) deg\n"), s).ok
