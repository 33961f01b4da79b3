"""The default strategy: zero-regret closure, then strongly connected components, then A* with B&B per component.

Why each step keeps the optimum (c(e, E) depends only on the set E and only falls as E grows):
1. Zero-regret closure. If c(e, E) == floor(e), some optimal completion of E declares e next: moving e forward
   cannot raise its own cost (already at its floor) and only adds a reference for those it overtakes.
2. Components. Draw r -> e when r witnesses e. Taking the strongly connected components in topological order,
   keeping each component's internal order, never raises anyone's cost (each entity then sees all of its
   upstream witnesses), so each component is solved alone with its upstream already declared.
3. A* over declared subsets of one component (CPA: key = set), zero-regret moves forced at every state, with
   f = g + max(h, h_closed) (below), an incumbent from greedy completion, and branch and bound on it: the
   best order found once no open node's f is below its cost is the answer. Anytime: on budget exhaustion, the
   incumbent and the bound at the component's root.

A state carries, per statement part, the set of entities that have a witness but none declared yet (CostModel.
unmet), so a move costs a few bitset operations: declaring e changes only the entities e witnesses.

h is the sum of floors + the least regret of any next move (no forced move means the next entity pays at least one
over its floor). A stronger bound (closed sources). Per part, a source component of the witness graph among the
undeclared entities whose members all lack a declared witness (two people facing each other whom nobody else
stands in line with, say; the cars of one lane chain, each `in lane of` every other) makes its first member pay
one over its floor; distinct sources are disjoint, so h_closed = sum of floors + the number of such sources, over
the parts, is admissible. (Per part it is the minimum spanning arborescence of the undeclared entities from a root
whose edges are the declared witnesses and the fallbacks: its witness edges cost 0, so the arborescence pays one
root edge per closed source; a lane fallback of weight 2 is two units, so a source pays its cheapest member's
weight.) It is also consistent: declaring e removes only the one source of each part that holds e, and then e pays
that part; no new source ever appears (a component that becomes a source was fed by what was just declared). So
the closed sources of a state are the root's that no declaration has touched, and h_closed costs a few bit
operations.

Why not replay the plain A* (issue 24). Until then a second pass replayed the A* on g + h, pruned by h_closed, to
return the very program that A* finds. But h_closed is exact where groups are independent: a state is then the
set of sources opened so far, every one of the 2^k subsets of k sources lies on an optimal path, and the A* on the
weaker h pops all of them before it meets a complete program (crowds of a dozen closed sources: 2^10 nodes; lane
chains join most cars of a street into sources: 2^15 nodes and half a minute on scene-0061/18). With h_closed
exact, the A* on it goes straight down, one node a source. So the answer is its own: the best order it has found
when no open node's f is below that order's cost (deeper nodes first among equal f, then first pushed). It is as
cheap as the replay's and may differ from it in order only; on the pinned crowds and frames
(tests/synth/test_crowd_golden.py, test_static_golden.py) it is the same program.
"""

from __future__ import annotations

import heapq

from synth.search.budget import Budget, BudgetExhausted
from synth.search.common import SearchResult, finish, floor_bound
from synth.search.costs import CostModel, bits

Unmet = int  # CostModel.unmet: per part, who has a witness but none declared, packed into one int


def _least_regret(cost_model: CostModel, unmet: Unmet, todo: int) -> tuple[int, int]:
    """(least regret over todo, the entities that have it), by counting set membership bit-parallel."""
    if not todo & ~cost_model.union(unmet):
        parts = cost_model.parts_of(unmet)
        at_least = [todo] + [0] * len(parts)
        for u in parts:
            for j in range(len(parts), 0, -1):
                at_least[j] |= at_least[j - 1] & u
        at_least.append(0)
        for j in range(1, len(parts) + 1):
            exactly = at_least[j] & ~at_least[j + 1]
            if exactly:
                return j, exactly
    if not todo:
        raise ValueError("empty todo")
    return 0, todo & ~cost_model.union(unmet)


def closure(cost_model: CostModel, order: tuple[int, ...], declared: int, unmet: Unmet,
            within: int) -> tuple[tuple[int, ...], int, Unmet, int]:
    """Declare zero-regret entities of `within` until none is left, in passes over the undeclared in index order
    (lowest first; within a pass each declaration counts for the entities after it).

    Returns (order, declared, unmet, cost added).
    """
    out, added = list(order), 0
    todo = within & ~declared
    while todo:
        above, progressed = todo, False
        while True:
            free = above & todo & ~cost_model.union(unmet)
            if not free:
                break
            low = free & -free
            e = low.bit_length() - 1
            out.append(e)
            declared |= low
            todo &= ~low
            unmet = cost_model.declare(unmet, e)
            added += cost_model.floor_of[e]
            above &= ~((low << 1) - 1)
            progressed = True
        if not progressed:
            break
    return tuple(out), declared, unmet, added


def closed_sources(cost_model: CostModel, unmet: Unmet, todo: int) -> list[int]:
    """Every closed source (see the module's note), of every part, as a bitset of its members."""
    out = []
    for k, u in enumerate(cost_model.parts_of(unmet)):
        a = u & todo
        if not a:
            continue
        # Every witness of an unmet entity is undeclared. One with a witness outside `a` is fed from elsewhere,
        # and so is everything downstream of it within `a`; the rest is closed under witnesses.
        pred = {x: cost_model._mask[k][x] for x in bits(a)}
        fed = 0
        for x, p in pred.items():
            if p & ~a:
                fed |= 1 << x
        changed = bool(fed)
        while changed:
            changed = False
            for x, p in pred.items():
                if not fed >> x & 1 and p & fed:
                    fed |= 1 << x
                    changed = True
        rest = a & ~fed
        anc = {x: pred[x] for x in bits(rest)}
        changed = True
        while changed:
            changed = False
            for x, ax in anc.items():
                grown = ax
                for y in bits(ax):
                    grown |= anc[y]
                if grown != ax:
                    anc[x] = grown
                    changed = True
        seen = 0
        for x in bits(rest):
            if seen >> x & 1:
                continue
            ax = anc[x]
            # x lies in a source component iff every ancestor has the same ancestors (x among them).
            if ax >> x & 1 and all(anc[y] == ax for y in bits(ax)):
                out.append(ax)
                seen |= ax
    return out


def components(cost_model: CostModel, rest: int) -> list[int]:
    """Strongly connected components of the witness graph on `rest` (r -> e when r witnesses e), as bitsets,
    upstream first: among the components whose upstream is already listed, the one with the lowest member."""
    preds = {e: cost_model.witness_mask(e) & rest for e in bits(rest)}
    succs = dict.fromkeys(preds, 0)
    for e, p in preds.items():
        for r in bits(p):
            succs[r] |= 1 << e

    def reach(x: int, step: dict[int, int], within: int) -> int:
        seen = frontier = 1 << x
        while frontier:
            grown = 0
            for y in bits(frontier):
                grown |= step[y]
            frontier = grown & within & ~seen
            seen |= frontier
        return seen

    comps, left = [], rest
    while left:
        x = (left & -left).bit_length() - 1
        comp = reach(x, succs, left) & reach(x, preds, left)  # what x reaches and what reaches x
        comps.append(comp)
        left &= ~comp
    upstream = [0] * len(comps)
    for i, comp in enumerate(comps):
        for e in bits(comp):
            upstream[i] |= preds[e]
        upstream[i] &= ~comp
    out, listed, todo = [], 0, list(range(len(comps)))
    while todo:
        # comps were found lowest member first, so the first ready one has the lowest member
        i = next(i for i in todo if not upstream[i] & ~listed)
        out.append(comps[i])
        listed |= comps[i]
        todo.remove(i)
    return out


def _greedy(cost_model: CostModel, order: tuple[int, ...], declared: int, unmet: Unmet,
            within: int) -> tuple[tuple[int, ...], int]:
    """common.greedy_completion within a component (the least regret, lowest index first), and its cost."""
    out, cost = list(order), 0
    todo = within & ~declared
    while todo:
        regret, who = _least_regret(cost_model, unmet, todo)
        low = who & -who
        e = low.bit_length() - 1
        out.append(e)
        cost += cost_model.floor_of[e] + regret
        todo &= ~low
        unmet = cost_model.declare(unmet, e)
    return tuple(out), cost


class _Bound:
    """h_closed of the states below one root: the closed sources at the root that no declaration has touched
    (declaring an entity removes only its own part's source, and no new one ever appears: module note)."""

    def __init__(self, cost_model: CostModel, comp: int, unmet: Unmet, todo: int):
        self.cost_model, self.comp = cost_model, comp
        self.sources = closed_sources(cost_model, unmet, todo)

    def __call__(self, declared: int) -> int:
        return self.cost_model.floor_sum(self.comp & ~declared) + sum(not (s & declared) for s in self.sources)

    def open_members(self, declared: int) -> int:
        """Entities whose declaration opens a closed source (one per part it opens, at most one per part)."""
        out = 0
        for s in self.sources:
            if not s & declared:
                out |= s
        return out


def _free_moves(paying: int, todo: int, opening: int) -> int:
    """The entities of todo that pay nothing over their floor, or belong to a closed source (`opening`): moving
    any other (it pays a part without opening a source) raises g + h_closed by at least one (module note).
    `paying`: the entities unmet in some part. An entity that pays one part and opens a source of another is
    kept too: the child's own bound decides it."""
    pays = paying & todo
    return (todo & ~pays) | (pays & opening)


def _moves(cost_model: CostModel, bound: _Bound, todo: int, declared: int, unmet: Unmet, may_waste: bool) -> int:
    """The entities worth declaring next: all of todo, or only those that waste nothing (_free_moves)."""
    return todo if may_waste else _free_moves(cost_model.union(unmet), todo, bound.open_members(declared))


def _move(cost_model: CostModel, comp: int, g: int, order: tuple[int, ...], declared: int, unmet: Unmet,
          e: int) -> tuple[int, tuple[int, ...], int, Unmet]:
    """Declare e, then the closure: the child's (g, order, declared, unmet)."""
    order2, declared2, unmet2, forced = closure(cost_model, order + (e,), declared | 1 << e,
                                                cost_model.declare(unmet, e), comp)
    return g + cost_model.floor_of[e] + cost_model.regret(unmet, e) + forced, order2, declared2, unmet2


def _optimum(cost_model: CostModel, comp: int, root: tuple, ub: int, bound: _Bound,
             budget: Budget) -> tuple[int, tuple | None]:
    """The optimum of the component, by A* on g + max(h, h_closed) (admissible) with branch and bound on the
    incumbent of cost ub. Returns (cost, an order reaching it; None when nothing beats the incumbent)."""
    root_order, root_declared, root_unmet, root_g = root
    best_order = None
    heap = [(root_g + bound(root_declared), 0, 0, root_g, root_declared, root_order, root_unmet)]
    best_g = {root_declared: root_g}
    tie = 0
    while heap and heap[0][0] < ub:
        budget.tick()
        f, _, _, g, declared, order, unmet = heapq.heappop(heap)
        if g > best_g.get(declared, g):
            continue
        # A move that wastes one over h_closed reaches the incumbent when the slack is one.
        for e in bits(_moves(cost_model, bound, comp & ~declared, declared, unmet, ub - (g + bound(declared)) > 1)):
            g2, order2, declared2, unmet2 = _move(cost_model, comp, g, order, declared, unmet, e)
            if declared2 & comp == comp:
                if g2 < ub:
                    ub, best_order = g2, order2
                continue
            if declared2 in best_g and best_g[declared2] <= g2:
                continue
            todo2 = comp & ~declared2
            f2 = g2 + max(bound(declared2), cost_model.floor_sum(todo2) + _least_regret(cost_model, unmet2, todo2)[0])
            if f2 >= ub:
                continue
            best_g[declared2] = g2
            tie += 1
            heapq.heappush(heap, (f2, -len(order2), tie, g2, declared2, order2, unmet2))
    return ub, best_order


def solve_component(
    cost_model: CostModel, comp: int, base: int, budget: Budget
) -> tuple[tuple[int, ...], int, int, str | None]:
    """Optimal order of one component given `base` declared. Returns (order, cost, lower bound, stop reason).

    The answer is the greedy incumbent when nothing beats it (the closed group bound meets it, or the A* finds no
    cheaper order), else the A*'s best order once no open node's f is below its cost (module note)."""
    root = closure(cost_model, (), base, cost_model.unmet(base), comp)
    root_order, root_declared, root_unmet, root_g = root
    if root_declared & comp == comp:
        return root_order, root_g, root_g, None
    ub_order, rest = _greedy(cost_model, root_order, root_declared, root_unmet, comp)
    ub = root_g + rest
    bound = _Bound(cost_model, comp, root_unmet, comp & ~root_declared)
    if root_g + bound(root_declared) >= ub:
        return ub_order, ub, ub, None  # the greedy incumbent meets the bound
    try:
        opt, opt_order = _optimum(cost_model, comp, root, ub, bound, budget)
    except BudgetExhausted as stop:
        return ub_order, ub, root_g + bound(root_declared), stop.reason
    if opt_order is None:
        return ub_order, ub, ub, None  # no improvement on the incumbent exists
    return opt_order, opt, opt, None


def auto(cost_model: CostModel, budget: Budget) -> SearchResult:
    order, declared, unmet, lb = closure(cost_model, (), 0, cost_model.unmet(0), cost_model.all)
    stopped: str | None = None
    for comp in components(cost_model, cost_model.all & ~declared):
        if stopped is None:
            sub, _cost, sub_lb, stopped = solve_component(cost_model, comp, declared, budget)
        else:
            # Out of budget: later components get a greedy order and the floor bound.
            sub, _ = _greedy(cost_model, (), declared, cost_model.unmet(declared), comp)
            sub_lb = floor_bound(cost_model, comp)
        order += sub
        lb += sub_lb
        declared |= comp
    return finish(cost_model, order, lb, budget.nodes, stopped)
