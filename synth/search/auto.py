"""The default strategy: zero-regret closure, then strongly connected components, then A* with B&B per component.

Why each step keeps the optimum (c(e, E) depends only on the set E and only falls as E grows):
1. Zero-regret closure. If c(e, E) == floor(e), some optimal completion of E declares e next: moving e forward
   cannot raise its own cost (already at its floor) and only adds a reference for those it overtakes.
2. Components. Draw r -> e when r witnesses e. Taking the strongly connected components in topological order,
   keeping each component's internal order, never raises anyone's cost (each entity then sees all of its
   upstream witnesses), so each component is solved alone with its upstream already declared.
3. A* over declared subsets of one component (CPA: key = set), zero-regret moves forced at every state, with
   h = sum of floors + the least regret of any next move (no forced move means the next entity pays at least
   one over its floor), an incumbent from greedy completion, and branch and bound on it. Anytime: on budget
   exhaustion, the incumbent and the least f in the open list.
"""

from __future__ import annotations

import heapq

from synth.search.budget import Budget, BudgetExhausted
from synth.search.common import SearchResult, finish, floor_bound, greedy_completion
from synth.search.costs import CostModel, bits


def closure(cm: CostModel, order: tuple[int, ...], declared: int, within: int) -> tuple[tuple[int, ...], int, int]:
    """Declare zero-regret entities of `within` (lowest index first) until none is left.

    Returns (order, declared, cost added).
    """
    floors = cm.floors()
    out, added = list(order), 0
    todo = within & ~declared
    progress = True
    while progress and todo:
        progress = False
        for e in bits(todo):
            if cm.delta(e, declared) == floors[e]:
                out.append(e)
                declared |= 1 << e
                todo &= ~(1 << e)
                added += floors[e]
                progress = True
    return tuple(out), declared, added


def components(cm: CostModel, rest: int) -> list[int]:
    """Strongly connected components of the witness graph on `rest`, upstream first, as bitsets."""
    if not rest:
        return []
    import networkx as nx  # only when the closure leaves work: most real frames never get here

    g = nx.DiGraph()
    nodes = list(bits(rest))
    g.add_nodes_from(nodes)
    g.add_edges_from((r, e) for e in nodes for r in bits(cm.witness_mask(e) & rest))
    dag = nx.condensation(g)
    members = dag.graph["mapping"]
    first = {}
    for node, comp in members.items():
        first[comp] = min(first.get(comp, node), node)
    out = []
    for comp in nx.lexicographical_topological_sort(dag, key=lambda c: first[c]):
        out.append(sum(1 << e for e in dag.nodes[comp]["members"]))
    return out


def solve_component(
    cm: CostModel, comp: int, base: int, budget: Budget
) -> tuple[tuple[int, ...], int, int, str | None]:
    """Optimal order of one component given `base` declared. Returns (order, cost, lower bound, stop reason)."""
    floors = cm.floors()

    def h(declared: int) -> int:
        todo = comp & ~declared
        if not todo:
            return 0
        least_regret = min(cm.delta(e, declared) - floors[e] for e in bits(todo))
        return sum(floors[e] for e in bits(todo)) + least_regret

    root_order, root_declared, root_g = closure(cm, (), base, comp)
    if root_declared & comp == comp:
        return root_order, root_g, root_g, None
    ub_order = greedy_completion(cm, root_order, root_declared, within=comp)
    ub = _cost_from(cm, ub_order, base)
    heap = [(root_g + h(root_declared), 0, 0, root_g, root_declared, root_order)]
    best_g = {root_declared: root_g}
    tie = 0
    try:
        while heap and heap[0][0] < ub:
            budget.tick()
            f, _, _, g, declared, order = heapq.heappop(heap)
            if g > best_g.get(declared, g):
                continue
            for e in bits(comp & ~declared):
                g1 = g + cm.delta(e, declared)
                order2, declared2, forced = closure(cm, order + (e,), declared | (1 << e), comp)
                g2 = g1 + forced
                if declared2 & comp == comp:
                    if g2 < ub:
                        ub, ub_order = g2, order2
                    continue
                if declared2 in best_g and best_g[declared2] <= g2:
                    continue
                f2 = g2 + h(declared2)
                if f2 >= ub:
                    continue
                best_g[declared2] = g2
                tie += 1
                heapq.heappush(heap, (f2, -len(order2), tie, g2, declared2, order2))
        return ub_order, ub, ub, None
    except BudgetExhausted as stop:
        lb = min(heap[0][0], ub) if heap else ub
        return ub_order, ub, lb, stop.reason


def _cost_from(cm: CostModel, order: tuple[int, ...], base: int) -> int:
    declared, total = base, 0
    for e in order:
        total += cm.delta(e, declared)
        declared |= 1 << e
    return total


def auto(cm: CostModel, budget: Budget) -> SearchResult:
    order, declared, lb = closure(cm, (), 0, cm.all)
    stopped: str | None = None
    for comp in components(cm, cm.all & ~declared):
        if stopped is None:
            sub, _cost, sub_lb, stopped = solve_component(cm, comp, declared, budget)
        else:
            # Out of budget: later components get a greedy order and the floor bound.
            sub = greedy_completion(cm, (), declared, within=comp)
            sub_lb = floor_bound(cm, comp)
        order += sub
        lb += sub_lb
        declared |= comp
    return finish(cm, order, lb, budget.nodes, stopped)
