"""z3 and the closed form answer every relation question alike, including points on the tolerance edges."""

from __future__ import annotations

import math
import random

import pytest

from synth.config import SynthConfig
from synth.dsl import DIRECTIONS
from synth.geometry import heading_vector
from synth.parts import HEADING, POSITION
from synth.relations import DIRECTION_NAMES, FACING_NAMES, NONE, UNDECIDED, closed_form_table, settle_exactly
from synth.scene import Entity, make_scene
from synth.smt import Z3Backend

# Offsets from the exact tolerance edge, in degrees: on it, a hair inside / outside, and clearly off.
EDGE_OFFSETS = (0.0, 0.0, 1e-12, -1e-12, 1e-9, -1e-9, 1e-6, -1e-6, 0.3, -0.3, 5.0, -5.0)


def _pair_scene(ref: Entity, target: Entity):
    ego = Entity("ego", "Car", 1000.0, 1000.0, 0.0)  # far away: the pair under test is what matters
    return make_scene("q", [ego, ref, target])


def _position_cases(rng: random.Random, n: int, delta1: float):
    for _ in range(n):
        ref = Entity("r", "Car", rng.uniform(-50, 50), rng.uniform(-50, 50), rng.choice([0.0, 90.0, rng.uniform(0, 360)]))
        phi = rng.choice(list(DIRECTIONS.values()))[1]
        side = rng.choice((-1, 1))
        angle = ref.heading + phi + side * (delta1 + rng.choice(EDGE_OFFSETS))
        d = rng.choice([rng.uniform(0.1, 60), 1.0, 10.0])
        ux, uy = heading_vector(angle)
        yield ref, Entity("t", "Car", ref.x + d * ux, ref.y + d * uy, rng.uniform(0, 360)), phi


def _heading_cases(rng: random.Random, n: int, delta2: float):
    for _ in range(n):
        ref = Entity("r", "Car", rng.uniform(-50, 50), rng.uniform(-50, 50), rng.uniform(0, 360))
        target_x, target_y = ref.x + rng.uniform(-30, 30), ref.y + rng.uniform(-30, 30)
        toward = math.degrees(math.atan2(ref.y - target_y, ref.x - target_x)) - 90.0
        base = toward + rng.choice((0.0, 180.0))
        h = (base + rng.choice((-1, 1)) * (delta2 + rng.choice(EDGE_OFFSETS))) % 360.0
        yield ref, Entity("t", "Car", target_x, target_y, h)


@pytest.mark.parametrize("delta1,delta2,cases", [(10.0, 5.0, 600), (7.5, 2.0, 200)])
def test_z3_and_closed_form_agree_on_thousands_of_queries(delta1, delta2, cases):
    config = SynthConfig(delta1=delta1, delta2=delta2)
    z3b = Z3Backend(config)
    rng = random.Random(20261122)
    undecided = 0
    checked = 0
    for ref, tgt, phi in _position_cases(rng, cases, delta1):
        scene = _pair_scene(ref, tgt)
        raw = closed_form_table(scene, config)
        undecided += int(raw.position[1, 2] == UNDECIDED)
        code = settle_exactly(raw, scene, config).position[1, 2]
        # The direction whose edge the point sits on, and one other (sectors are disjoint).
        edge = next(c for c, name in enumerate(DIRECTION_NAMES) if DIRECTIONS[name][1] == phi)
        for c in (edge, (edge + 1 + rng.randrange(3)) % 4):
            assert POSITION.ask_named(z3b, DIRECTION_NAMES[c], ref, tgt) == (code == c), (c, ref, tgt, code)
            checked += 1
    for ref, tgt in _heading_cases(rng, cases, delta2):
        scene = _pair_scene(ref, tgt)
        raw = closed_form_table(scene, config)
        undecided += int(raw.heading[1, 2] == UNDECIDED)
        code = settle_exactly(raw, scene, config).heading[1, 2]
        for c, name in enumerate(FACING_NAMES):
            assert HEADING.ask_named(z3b, name, ref, tgt) == (code == c), (name, ref, tgt, code)
            checked += 1
    assert checked == 4 * cases
    # The edge cases really reached the guard band, so the exact path was exercised, not just floats.
    assert undecided > cases // 20


def test_coincident_entities_have_no_direction_or_facing_relation():
    config = SynthConfig()
    a, b = Entity("r", "Car", 3.0, 4.0, 0.0), Entity("t", "Car", 3.0, 4.0, 0.0)
    table = settle_exactly(closed_form_table(_pair_scene(a, b), config), _pair_scene(a, b), config)
    assert table.position[1, 2] == NONE and table.heading[1, 2] == NONE
    z3b = Z3Backend(config)
    assert not any(POSITION.ask_named(z3b, d, a, b) for d in DIRECTION_NAMES)
    assert not any(HEADING.ask_named(z3b, m, a, b) for m in FACING_NAMES)


def test_relations_by_hand():
    """A few cases worked out on paper (ego at the origin facing +y)."""
    config = SynthConfig()
    ego = Entity("ego", "Car", 0.0, 0.0, 0.0)
    cases = [
        # (x, y, heading) -> (direction of target from ego, facing relation to ego)
        ((0.0, 10.0, 0.0), ("ahead", "away")),
        ((0.0, 10.0, 180.0), ("ahead", "toward")),
        ((-10.0, 0.0, 90.0), ("left", "away")),  # heading 90 = facing -x, i.e. away from ego
        ((10.0, 0.0, 90.0), ("right", "toward")),
        ((0.0, -10.0, 0.0), ("behind", "toward")),
        ((10.0 * math.sin(math.radians(11)), 10.0 * math.cos(math.radians(11)), 0.0), (None, None)),
        ((-10.0 * math.sin(math.radians(9)), 10.0 * math.cos(math.radians(9)), 354.0), ("ahead", None)),
    ]
    for (x, y, h), (direction, facing) in cases:
        scene = make_scene("hand", [ego, Entity("car1", "Car", x, y, h)])
        t = settle_exactly(closed_form_table(scene, config), scene, config)
        got_dir = DIRECTION_NAMES[t.position[0, 1]] if t.position[0, 1] != NONE else None
        got_face = FACING_NAMES[t.heading[0, 1]] if t.heading[0, 1] != NONE else None
        assert (got_dir, got_face) == (direction, facing), (x, y, h)


def test_hybrid_sends_only_the_edge_pairs_to_the_solver():
    from synth.oracle import make_oracle

    config = SynthConfig()
    ego = Entity("ego", "Car", 0.0, 0.0, 0.0)
    ux, uy = heading_vector(10.0)  # exactly on the edge of ego's ahead sector
    on_edge = Entity("car1", "Car", 20 * ux, 20 * uy, 45.0)
    clear = Entity("car2", "Car", 0.0, -30.0, 45.0)
    scene = make_scene("edge", [ego, on_edge, clear])
    oracle = make_oracle(scene, config)
    assert oracle.backend.stats.queries >= 1
    asked = {(target, ref) for (_, target, ref) in oracle.cache}
    assert asked == {(1, 0)}  # only (car1 relative to ego) was near a boundary
    exact = settle_exactly(closed_form_table(scene, config), scene, config)
    assert (oracle.table.position == exact.position).all() and (oracle.table.heading == exact.heading).all()
