"""The paper's Pure-SMT baseline: declaration order and geometry in one z3 optimisation problem.

Each entity gets an integer position o_e in the order; each part of e (position, heading) costs 0 when ego, or
some r with o_r < o_e, satisfies one of the part's witness formulas (Part.any_relation). z3's Optimize
minimises the summed cost under the time limit. Kept as the paper's reference point: it is exact but scales badly.

Under robust synthesis the formulas are still the plain geometry's (a robust witness is a question over every
position in a box, which this one problem does not encode), so z3's optimum is only an order there: its cost is
taken under the robust table and it is not claimed optimal unless the floor bound meets it.
"""

from __future__ import annotations

from synth.robust import robust_parts
from synth.search.budget import Budget
from synth.search.common import SearchResult, finish, floor_bound, greedy_completion
from synth.search.costs import CostModel
from synth.smt import Z3Backend


def monolithic(cost_model: CostModel, budget: Budget) -> SearchResult:
    oracle = cost_model.oracle
    # The frame's exact backend (z3) where a solver oracle made one; its encoding, z3's Optimize around it.
    smt = oracle.backend.exact if oracle.backend is not None else Z3Backend(oracle.config)
    z3 = smt.z3
    entities = oracle.entities()  # 0 is ego
    n = cost_model.n
    place = [z3.Int(f"o{e}") for e in range(n)]  # o_e: e's position in the declaration order
    opt = z3.Optimize()
    remaining = budget.remaining()
    if remaining is not None:
        opt.set(timeout=max(1, int(remaining * 1000)))
    opt.add(z3.Distinct(*place), *(z3.And(0 <= v, v < n) for v in place))

    costs = []
    for e in range(n):
        target = entities[e + 1]
        for part in oracle.parts:
            witnessed = z3.Or(part.any_relation(smt, entities[0], target),
                              *(z3.And(place[r] < place[e], part.any_relation(smt, entities[r + 1], target))
                                for r in range(n) if r != e))
            costs.append(z3.If(witnessed, 0, part.fallback_cost(target, oracle.config)))
    total = z3.Sum(*costs) if costs else z3.IntVal(0)
    opt.minimize(total)
    budget.tick()
    result = opt.check()
    if result == z3.sat:
        model = opt.model()
        order = tuple(sorted(range(n), key=lambda e: model.eval(place[e]).as_long()))
        robust = robust_parts(oracle.scene, oracle.config, oracle.parts)
        bound = floor_bound(cost_model, cost_model.all) if robust else cost_model.order_cost(order)
        return finish(cost_model, order, bound, budget.nodes, None)
    # unknown: out of time (z3 keeps no usable incumbent we can trust here).
    order = greedy_completion(cost_model, (), 0) if result == z3.unknown else ()
    return finish(cost_model, order, floor_bound(cost_model, cost_model.all), budget.nodes, "timeout")
