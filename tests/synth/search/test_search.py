"""Every strategy finds the optimum that an independent subset DP computes from the semantics alone."""

from __future__ import annotations

import random

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from synth.config import STRATEGIES, SynthConfig
from synth.dsl import parse_program
from synth.scene import scene_from_dict
from synth.semantics import check
from synth.synthesize import synthesize
from tests.support import shipped_frames
from tests.support.bruteforce import floor_sum, optimal_cost, random_scene_dict

# Strategies without CPA are O(N!): they are cross-checked on the frames they can finish.
PRUNED = ("auto", "bfs-cpa", "dfs-bnb-cpa", "dfs-cpa", "astar-cpa")
MAX_N = {"bfs": 7, "dfs": 7, "dfs-bnb": 9, "astar": 10, "monolithic": 9}


def assert_optimal_and_contained(result, scene, expected_cost):
    assert result.cost == expected_cost, (result.strategy if hasattr(result, "strategy") else "", str(result.program))
    assert result.status == "optimal"
    assert result.lower_bound == result.cost
    # The printed program, parsed back, is the same program and contains the scene.
    text = str(result.program)
    parsed = parse_program(text)
    assert parsed == result.program
    assert parsed.cost == result.cost
    verdict = check(parsed, scene, result.config)
    assert verdict.ok, [str(v) for v in verdict.violations]


REAL = [s for s in shipped_frames() if len(s.others) <= 12]


@pytest.mark.parametrize("scene", REAL, ids=[s.frame_id for s in REAL])
@pytest.mark.parametrize("strategy", STRATEGIES)
def test_real_frames_every_strategy_matches_brute_force(scene, strategy):
    if len(scene.others) > MAX_N.get(strategy, 99):
        pytest.skip(f"{strategy} is factorial; cross-checked up to {MAX_N[strategy]} entities")
    result = synthesize(scene, SynthConfig(strategy=strategy, oracle="closed-form"))
    assert_optimal_and_contained(result, scene, optimal_cost(scene))


@settings(max_examples=25)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_random_scenes_every_strategy_matches_brute_force(seed, n):
    scene = scene_from_dict(random_scene_dict(random.Random(seed), n))
    expected = optimal_cost(scene)
    for strategy in STRATEGIES:
        assert_optimal_and_contained(synthesize(scene, SynthConfig(strategy=strategy, oracle="closed-form")), scene, expected)


@settings(max_examples=40)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(7, 13))
def test_auto_on_larger_random_scenes_matches_brute_force(seed, n):
    scene = scene_from_dict(random_scene_dict(random.Random(seed), n))
    assert_optimal_and_contained(synthesize(scene, SynthConfig(oracle="closed-form")), scene, optimal_cost(scene))


@pytest.mark.parametrize("oracle", ["hybrid", "smt"])
def test_solver_oracles_agree_with_closed_form_and_certify(oracle, real_frames):
    for scene in [s for s in real_frames if len(s.others) <= 9][:4]:
        result = synthesize(scene, SynthConfig(oracle=oracle))
        assert_optimal_and_contained(result, scene, optimal_cost(scene))
        assert result.certified
        # The all-SMT oracle asks the solver everything; hybrid's clear facts are decided by intervals.
        assert (result.stats.smt_queries > 0) == (oracle == "smt")


def test_paper_bfs_cpa_with_smt_oracle_on_a_real_frame(real_frames):
    scene = next(s for s in real_frames if len(s.others) == 8)
    result = synthesize(scene, SynthConfig(strategy="bfs-cpa", oracle="smt"))
    assert_optimal_and_contained(result, scene, optimal_cost(scene))


def test_auto_proves_the_optimum_on_the_largest_real_frames(real_frames):
    for scene in [s for s in real_frames if len(s.others) > 40]:
        result = synthesize(scene)
        assert result.status == "optimal" and result.certified
        assert result.lower_bound == result.cost >= floor_sum(scene)
        assert check(parse_program(str(result.program)), scene).ok


def test_paper_figure_2_scene_costs_one():
    scene = scene_from_dict({"frame_id": "fig2", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 3, "y": 8, "heading": 0},
        {"id": "car2", "type": "Car", "x": 3, "y": 5, "heading": 0},
        {"id": "car3", "type": "Car", "x": 0, "y": 5, "heading": 0},
    ]})
    for strategy in STRATEGIES:
        result = synthesize(scene, SynthConfig(strategy=strategy))
        assert result.cost == 1
        by = {s.id: s for s in result.program.statements}
        assert str(by["car3"].position).startswith("ahead of ego") and str(by["car3"].heading) == "facing away from ego"
        assert str(by["car2"].position).startswith("right of car3")
        assert str(by["car2"].heading).endswith("deg relative to ego")
        assert str(by["car1"].position).startswith("ahead of car2")
        order = [s.id for s in result.program.statements]
        assert order.index("car3") < order.index("car2") < order.index("car1")


def test_output_is_deterministic(real_frames):
    scene = max(real_frames, key=lambda s: len(s.others))
    a, b = synthesize(scene), synthesize(scene)
    assert str(a.program) == str(b.program) and a.scenic == b.scenic


def test_mutual_witnesses_form_a_component_that_a_star_solves():
    # car1 and car2 face each other, 5 m apart, 45 degrees off ego's axes: each witnesses the other (ahead of,
    # facing toward) and ego witnesses neither. Whoever is declared first pays 2; the optimum is 2.
    from synth.oracle import make_oracle
    from synth.search.auto import closed_sources, closure, components
    from synth.search.costs import CostModel

    scene = scene_from_dict({"frame_id": "cycle", "entities": [
        {"id": "ego", "type": "Car", "x": 0, "y": 0, "heading": 0},
        {"id": "car1", "type": "Car", "x": 20, "y": 20, "heading": 0},
        {"id": "car2", "type": "Car", "x": 20, "y": 25, "heading": 180},
    ]})
    cost_model = CostModel(make_oracle(scene, SynthConfig(oracle="closed-form")))
    assert cost_model.floors() == [0, 0]
    order, declared, _, _ = closure(cost_model, (), 0, cost_model.unmet(0), cost_model.all)
    assert declared == 0 and components(cost_model, cost_model.all) == [0b11]
    # Two closed sources (the pair for position, the pair for heading): the closed-group bound is the optimum.
    assert len(closed_sources(cost_model, cost_model.unmet(0), cost_model.all)) == 2
    assert_optimal_and_contained(synthesize(scene, SynthConfig(oracle="closed-form")), scene, 2)
    assert optimal_cost(scene) == 2


def _cost_to_go(cost_model, declared: int) -> int:
    """The least cost of declaring everything not in `declared` (dynamic programming over subsets)."""
    from functools import cache

    @cache
    def best(d: int) -> int:
        if d == cost_model.all:
            return 0
        return min(cost_model.delta(e, d) + best(d | 1 << e) for e in range(cost_model.n) if not d >> e & 1)

    return best(declared)


@settings(max_examples=40)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(3, 9), crowd=st.booleans())
def test_the_closed_group_bound_is_admissible_and_consistent(seed, n, crowd):
    # A* may prune with it only because it never overestimates the cost to go and never drops by more than a
    # move costs (then pruning keeps every node that leads below the incumbent, in the same order).
    from synth.oracle import make_oracle
    from synth.search.auto import closed_sources
    from synth.search.costs import CostModel
    from tests.support.crowds import crowd_scene

    rng = random.Random(seed)
    scene = crowd_scene(seed % 1000, pedestrians=n, barriers=1, cones=0, cars=0) if crowd else \
        scene_from_dict(random_scene_dict(rng, n))
    cost_model = CostModel(make_oracle(scene, SynthConfig(oracle="closed-form")))

    def h(d: int) -> int:
        todo = cost_model.all & ~d
        return cost_model.floor_sum(todo) + len(closed_sources(cost_model, cost_model.unmet(d), todo))

    root = closed_sources(cost_model, cost_model.unmet(0), cost_model.all)
    for _ in range(6):
        d = rng.getrandbits(cost_model.n) & cost_model.all
        assert h(d) <= _cost_to_go(cost_model, d)
        # Declarations only remove sources, never add one: the search counts the root's untouched ones.
        sources = closed_sources(cost_model, cost_model.unmet(d), cost_model.all & ~d)
        assert sorted(sources) == sorted(x for x in root if not x & d)
        for e in range(cost_model.n):
            if not d >> e & 1:
                assert h(d) <= cost_model.delta(e, d) + h(d | 1 << e)


@settings(max_examples=80)
@given(n=st.integers(1, 30), p=st.sampled_from([0.03, 0.1, 0.3]), seed=st.integers(0, 2**32 - 1))
def test_components_are_networkx_condensation_in_lexicographic_topological_order(n, p, seed):
    # auto orders the witness graph's strongly connected components itself (networkx cost a cold process a
    # quarter second to import); networkx stays the reference.
    import networkx as nx

    from synth.search.auto import components
    from synth.search.costs import bits

    rng = random.Random(seed)
    masks = [sum(1 << r for r in range(n) if r != e and rng.random() < p) for e in range(n)]
    rest = rng.getrandbits(n) | 1

    class Witnesses:
        def witness_mask(self, e):
            return masks[e]

    g = nx.DiGraph()
    g.add_nodes_from(bits(rest))
    g.add_edges_from((r, e) for e in bits(rest) for r in bits(masks[e] & rest))
    dag = nx.condensation(g)
    first = {c: min(dag.nodes[c]["members"]) for c in dag.nodes}
    expected = [sum(1 << e for e in dag.nodes[c]["members"])
                for c in nx.lexicographical_topological_sort(dag, key=lambda c: first[c])]
    assert components(Witnesses(), rest) == expected
