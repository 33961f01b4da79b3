"""LANE, the lane part (beyond the paper; `--lanes`): where each entity is on the recorded road.

    in lane of REF             cost 0    e's lane on the lane chain of REF's lane
    in lane left of REF        cost 0    e's lane on the chain of REF's lane's left neighbour (same direction)
    in lane right of REF       cost 0
    in oncoming lane of REF    cost 0    e's lane on the chain of REF's lane's oncoming lane
    in intersection            cost 1    in an intersection (an intersection feature or an intersection lane)
    on crosswalk               cost 1
    off road                   cost 1    in no lane and no drivable area
    off lane                   cost 1    in no lane, in a drivable area
    in lane "ID"               cost 2    e's lane is the lane ID of the map
    anywhere                   cost 2    no claim (robust synthesis, where the bounds leave the lane open)

An entity's lane is its chosen lane (synth.road.lane_facts), decided exactly at extraction; the relations between
lanes are facts of the map (synth.road.lane_relations). So every question is a lookup: the float table is the exact
one, no pair is ever UNDECIDED and no solver is asked. Without a witness, an entity pays its cheapest true
fact: 1 for the first of intersection, crosswalk, off road, off lane that holds, else 2 for its lane by id
(Part.fallback_cost: the search weighs it). Robust: a relation holds only if it holds for every lane the
entity (and its reference) may be in under the bounds (synth.road.lane_relations.places), and the fallback is the
first fact that holds wherever the entity may be, else its lane by id if it cannot leave it, else `anywhere`.
Over a window (synth.window.program), two relations may hold at once (a merged lane is on both chains: disjoint = False),
and the fallback is decided on the entity's place in every frame it is in (window_fallback, merged).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass
from fractions import Fraction
from typing import TYPE_CHECKING, Any

import numpy as np

from synth.config import SynthConfig
from synth.draws import Draws, Pose, Requirement
from synth.errors import InputError
from synth.parts.base import Clause, Part
from synth.perturbation import Bounds, bounds_of
from synth.road.lane_relations import RELATION_NAMES, SIDES, LaneGraph, Places, places
from synth.scene import Entity, Scene
from synth.syntax import DslError, Line
from synth.tables import NONE, SceneArrays, no_self_witness

if TYPE_CHECKING:
    from synth.smt.backend import ExactBackend, SolverBackend
    from synth.variants.scene_road import SceneRoad

# The facts a cost-1 clause names, in the order the fallback tries them (the Entity field or rule of each).
FACTS = ("intersection", "crosswalk", "off road", "off lane")


class LanesMissing(InputError, ValueError):
    """--lanes on a scene without a road, or with an entity whose lane facts are unknown. One line."""


def require_lanes(scene: Scene) -> None:
    """The LANE part describes every entity's place on the road: refuse a scene that cannot say it."""
    if scene.road is None:
        raise LanesMissing(f"scene {scene.frame_id!r} has no road, which lanes (--lanes) need (r2s scene writes it "
                           "for frames extracted with a map)")
    missing = [e.id for e in scene.entities if e.lanes is None or e.off_road is None or e.in_intersection is None
               or e.on_crosswalk is None]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise LanesMissing(f"entity {missing[0]!r}{more} has no lane facts (lanes, lane, in_intersection, "
                           "on_crosswalk, off_road), which lanes (--lanes) need")


def facts_of(e: Entity) -> frozenset[str]:
    """The cost-1 facts that hold for an entity as recorded."""
    if e.lanes is None:
        return frozenset()
    held = {"intersection": bool(e.in_intersection), "crosswalk": bool(e.on_crosswalk), "off road": bool(e.off_road),
            "off lane": not e.lanes and e.off_road is False}
    return frozenset(k for k, v in held.items() if v)


def _true(backend: SolverBackend, value: bool) -> Any:
    """A constant formula (the lane questions are lookups, so their formulas are their answers)."""
    const = backend.constant
    return const(0) <= const(0) if value else const(1) <= const(0)


class LaneClause(Clause):
    """What the lane clauses share: the checker's view of an entity's place, and formulas that are lookups."""

    def observed(self, e: Entity) -> str:
        if e.lanes is None:
            return "no lane facts"
        where = f"lane {e.lane}" if e.lane is not None else "in no lane"
        return ", ".join([where, *sorted(facts_of(e))])

    def decide(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool | None:
        return self.holds(e, ref, config)

    def formula(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> Any:
        return _true(backend, self.holds(e, ref, backend.config))

    def violations(self, backend: ExactBackend, e: Entity, ref: Entity | None) -> list[Any]:
        # A violation is satisfiable (the constant true) exactly when some perturbation breaks the clause.
        return [] if self.robustly(e, ref, backend.config) else [_true(backend, True)]

    def robustly(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        """Does the clause hold wherever the entity (and its reference) may be under the bounds?"""
        raise NotImplementedError

    # Scenic: the clause's text as a property of its object (a label), and a requirement over the road's regions
    # (synth.scenic.road) that keeps it there; the sampler asks the same of every pose it tries (LaneDraws).
    def scenic(self, at: str) -> str:
        return json.dumps(str(self))  # a Python string literal (lane ids hold no quote or backslash)

    def scenic_requirements(self, entity: str) -> list[str]:
        return [f"require {self.scenic_condition(entity)}"]

    def scenic_condition(self, entity: str) -> str:
        """The clause over the road's regions, in Scenic, for the object named `entity` (docs/scenic.md)."""
        raise NotImplementedError

    def draws(self, config: SynthConfig) -> Draws:
        return LaneDraws(self.ref, (), (), self, config)


def _robust_places(e: Entity, config: SynthConfig) -> Places:
    b = bounds_of(e, config)
    return places(e.lane_graph, e.x, e.y, e.lane, e.lanes or (), facts_of(e), b.pos, b.heading > 0.0)


@dataclass(frozen=True)
class LaneRelation(LaneClause):
    """`in lane of REF`, `in lane left of REF`, `in lane right of REF`, `in oncoming lane of REF`: cost 0."""

    side: str  # one of synth.road.lane_relations.SIDES
    ref: str
    cost = 0
    text = "{c.phrase} {c.ref}"
    first_word = "in"
    labels = RELATION_NAMES
    label_field = "label"
    drawn_as = "lane_relation"

    @property
    def phrase(self) -> str:
        return {"same": "in lane of", "left": "in lane left of", "right": "in lane right of",
                "oncoming": "in oncoming lane of"}[self.side]

    @property
    def label(self) -> str:
        return RELATION_NAMES[SIDES.index(self.side)]

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        if ref is None or ref.lane_graph is None or e.lane is None:
            return False
        return e.lane in ref.lane_graph.related(ref.lane, self.side)

    def robustly(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return LANE.robust_code(SIDES.index(self.side), ref, e, config)

    def scenic_condition(self, entity: str) -> str:
        return f"road__lane_related({entity}, {self.ref}, {self.side!r})"


@dataclass(frozen=True)
class LaneFact(LaneClause):
    """`in intersection`, `on crosswalk`, `off road`, `off lane`: cost 1, no reference."""

    fact: str  # one of FACTS
    cost = 1
    ref = None
    text = "{c.phrase}"
    labels = ("in intersection", "on crosswalk", "off road", "off lane")
    label_field = "label"
    drawn_as = "lane_fact"

    @property
    def phrase(self) -> str:
        return self.labels[FACTS.index(self.fact)]

    @property
    def label(self) -> str:
        return self.phrase

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self.fact in facts_of(e)

    def robustly(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return self.fact in _robust_places(e, config).sure

    def scenic_condition(self, entity: str) -> str:
        helper = {"intersection": "road__in_intersection", "crosswalk": "road__on_crosswalk",
                  "off road": "road__off_road", "off lane": "road__off_lane"}[self.fact]
        return f"{helper}({entity})"


@dataclass(frozen=True)
class InLane(LaneClause):
    """`in lane "ID"`: e's lane is the map's lane ID, cost 2."""

    lane: str
    cost = 2
    ref = None
    text = 'in lane "{c.lane}"'
    labels = ("lane by id",)
    drawn_as = "lane_fact"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return e.lane == self.lane

    def robustly(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        p = _robust_places(e, config)
        return not p.laneless and p.lanes == {self.lane}

    def scenic_condition(self, entity: str) -> str:
        return f"road__lane_of({entity}) == {self.lane!r}"


@dataclass(frozen=True)
class Anywhere(LaneClause):
    """`anywhere`: no claim on the entity's place, cost 2 (robust synthesis's last resort)."""

    cost = 2
    ref = None
    text = "anywhere"
    first_word = "anywhere"
    labels = ("anywhere",)
    drawn_as = "lane_fact"

    def holds(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return True

    def robustly(self, e: Entity, ref: Entity | None, config: SynthConfig) -> bool:
        return True

    def scenic_requirements(self, entity: str) -> list[str]:
        return []  # no claim, nothing to require


@dataclass(frozen=True)
class LaneDraws(Requirement):
    """What the sampler asks of a lane clause: nothing drawn; its entity (and its reference) placed where the
    clause holds, by the clause's own semantics on the lane facts of the poses (synth.variants.scene_road.SceneRoad)."""

    clause: LaneClause
    config: SynthConfig

    def allowed(self, own: Pose, ref: Pose | None, road: SceneRoad | None) -> bool:
        if road is None:
            return False  # never asked: lanes need a road (require_lanes)
        return self.clause.holds(road.entity(own), None if ref is None else road.entity(ref), self.config)


def _place(e: Entity, config: SynthConfig, robust: bool) -> tuple[frozenset[str], str | None]:
    """Where the fallback reads e to be: the cost-1 facts sure to hold of it, and the one lane it is sure to be in
    (None: in no lane, or, robustly, possibly in several or in none)."""
    if robust:
        p = _robust_places(e, config)
        return p.sure, (next(iter(p.lanes)) if not p.laneless and len(p.lanes) == 1 else None)
    return facts_of(e), e.lane


def _fallback_at(where: Sequence[tuple[frozenset[str], str | None]]) -> Clause:
    """The cheapest clause without a reference true at every one of these places: the first fact sure at all of
    them (cost 1), else `in lane "ID"` when all are surely in the one lane ID (and ID can be quoted), else
    anywhere (cost 2)."""
    sure = frozenset.intersection(*(facts for facts, _ in where))
    fact = next((f for f in FACTS if f in sure), None)
    if fact is not None:
        return LaneFact(fact)
    lanes = {lane for _, lane in where}
    lane = next(iter(lanes)) if len(lanes) == 1 else None
    return InLane(lane) if lane is not None and printable_id(lane) else Anywhere()


def printable_id(lane: str) -> bool:
    """Can `in lane "ID"` quote this id: 1-256 printable ASCII characters but the quote, the backslash (a Scenic
    string) and # (a DSL comment)?"""
    return 0 < len(lane) <= 256 and all(32 <= ord(ch) < 127 and ch not in '"\\#' for ch in lane)


class LanePart(Part):
    name = "lane"
    relations = RELATION_NAMES  # names unique across parts (the smt oracle asks by name)
    keyword = "with dsl__lane"
    clauses = (LaneRelation, LaneFact, InLane, Anywhere)
    optional = True  # `, LANE` ends a statement when the program has lanes
    disjoint = False  # a lane where two lanes merge is on both their chains: same lane and lane left at once

    def enabled(self, config: SynthConfig) -> bool:
        return config.lanes

    def perturbed(self, b: Bounds) -> bool:
        return b.pos != 0.0 or b.heading != 0.0

    # ------------------------------------------------------------------------------- tables (lookups: exact)
    def _table(self, entities: Sequence[Entity], decide) -> np.ndarray:
        n = len(entities)
        codes = np.full((n, n), NONE, dtype=np.int8)
        for r, ref in enumerate(entities):
            for t, e in enumerate(entities):
                if r != t:
                    codes[r, t] = next((c for c in range(len(SIDES)) if decide(c, ref, e)), NONE)
        return no_self_witness(codes)

    def closed_form(self, arrays: SceneArrays, config: SynthConfig) -> np.ndarray:
        # What `exact` decides for a pair depends only on the reference's graph and lane and the target's lane, so
        # each pair of lanes is decided once and fills the block of its entities (a street of 140 entities stands
        # on a few dozen lanes; pair by pair, this table was most of the time lanes added to synthesis: issue 24).
        # A reference or target in no lane, or a reference without a graph, witnesses nothing (LaneRelation.holds).
        refs: dict[tuple[int, str], tuple[LaneGraph, list[int]]] = {}
        targets: dict[str, list[int]] = {}
        for i, e in enumerate(arrays.entities):
            if e.lane is None:
                continue
            targets.setdefault(e.lane, []).append(i)
            if e.lane_graph is not None:
                refs.setdefault((id(e.lane_graph), e.lane), (e.lane_graph, []))[1].append(i)
        n = len(arrays.entities)
        codes = np.full((n, n), NONE, dtype=np.int8)
        for (_, lane), (graph, rows) in refs.items():
            related = [graph.related(lane, side) for side in SIDES]
            for target, cols in targets.items():
                code = next((c for c, lanes in enumerate(related) if target in lanes), NONE)
                if code != NONE:
                    codes[np.ix_(rows, cols)] = code
        return no_self_witness(codes)

    def robust_closed_form(self, arrays: SceneArrays, bounds: list[Bounds], config: SynthConfig) -> np.ndarray:
        return self._table(arrays.entities, lambda c, ref, e: self.robust_code(c, ref, e, config))

    def exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool:
        return LaneRelation(SIDES[code], ref.id).holds(e, ref, config)

    def robust_exact(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool | None:
        return self.robust_code(code, ref, e, config)

    def robust_code(self, code: int, ref: Entity, e: Entity, config: SynthConfig) -> bool:
        """Relation `code` for every lane e and ref may be in under their bounds (none of them laneless)."""
        if not self.pair_is_robust(ref, e, config):
            return self.exact(code, ref, e, config)
        pe, pr = _robust_places(e, config), _robust_places(ref, config)
        if pe.laneless or pr.laneless or not pe.lanes or not pr.lanes:
            return False
        graph, side = ref.lane_graph, SIDES[code]
        return all(pe.lanes <= graph.related(m, side) for m in pr.lanes)

    # ------------------------------------------------------------------------------- SMT (lookups too)
    def relation(self, backend: SolverBackend, code: int, ref: Entity, e: Entity) -> bool:
        return self.exact(code, ref, e, backend.config)

    def robust_relation(self, backend: ExactBackend, code: int, ref: Entity, e: Entity) -> bool:
        return self.robust_code(code, ref, e, backend.config)

    def any_relation(self, backend: ExactBackend, ref: Entity, e: Entity) -> Any:
        return _true(backend, any(self.exact(c, ref, e, backend.config) for c in range(len(SIDES))))

    # ------------------------------------------------------------------------------- Alg. 4
    def quantity(self, code: int) -> str | None:
        return None  # no Ranges: a lane clause names lanes and facts

    def float_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        return ()

    def measure_terms(self, backend: ExactBackend, quantity: str, target: Entity, ref: Entity) -> tuple[list, list]:
        return [], []

    def fallback(self, e: Entity, config: SynthConfig, robust: bool) -> Clause:
        """The clause of an entity without a witness: its first fact (cost 1), else its lane by id (cost 2), else
        (robust, when the bounds leave its lane open) anywhere."""
        return _fallback_at([_place(e, config, robust)])

    def fallback_cost(self, e: Entity, config: SynthConfig) -> int:
        return self.fallback(e, config, self.perturbed(bounds_of(e, config))).cost

    # ------------------------------------------------------------------------------- windows
    def window_fallback(self, frames: Sequence[Entity], config: SynthConfig) -> Clause:
        """The clause of an entity without a window witness, `frames` its poses in the frames it is in: the first
        fact that holds in every one of them (cost 1), else its lane by id if it is in that one lane in all of
        them, else anywhere (cost 2). Each frame's place is read as the frame's own fallback reads it (robustly
        where the entity's bounds are not zero), so one frame gives the single-frame fallback."""
        return _fallback_at([_place(e, config, self.perturbed(bounds_of(e, config))) for e in frames])

    def window_fallback_cost(self, frames: Sequence[Entity], config: SynthConfig) -> int:
        return self.window_fallback(frames, config).cost

    def merged(self, clauses: Sequence[Clause], frames: Sequence[Entity], config: SynthConfig) -> Clause:
        # A window witness is one relation with one reference in every frame (the frames' clauses are that one
        # clause); without one, each frame wrote its own fallback (a fact, a lane), which need not hold in the
        # others: the window's fallback is decided on every frame's place at once.
        if clauses[0].ref is not None:
            return super().merged(clauses, frames, config)
        return self.window_fallback(frames, config)

    def clause(self, code: int, ref_id: str, values: tuple[Fraction, ...], config: SynthConfig) -> Clause:
        if code == NONE:
            raise ValueError("the lane fallback depends on the entity: LanePart.clause_for")
        return LaneRelation(SIDES[code], ref_id)

    def clause_for(self, code: int, target: Entity, ref: Entity, values: tuple[Fraction, ...],
                   config: SynthConfig) -> Clause:
        return self.fallback(target, config, robust=False) if code == NONE else self.clause(code, ref.id, values,
                                                                                             config)

    def robust_clause(self, code: int, target: Entity, ref: Entity, config: SynthConfig) -> Clause:
        if code == NONE:
            return self.fallback(target, config, self.perturbed(bounds_of(target, config)))
        return LaneRelation(SIDES[code], ref.id)

    # ------------------------------------------------------------------------------- syntax
    def parse(self, ln: Line, declared: set[str]) -> Clause:
        where = ln.where()
        if ln.accept("anywhere"):
            return Anywhere()
        if ln.accept("on"):
            ln.take(text="crosswalk")
            return LaneFact("crosswalk")
        if ln.accept("off"):
            if ln.accept("road"):
                return LaneFact("off road")
            ln.take(text="lane")
            return LaneFact("off lane")
        if not ln.accept("in"):
            found = ln.peek()
            raise DslError(f"{where}: expected a lane clause (in, on, off, anywhere), found "
                           f"{'end of line' if found is None else repr(found)}")
        if ln.accept("intersection"):
            return LaneFact("intersection")
        if ln.accept("oncoming"):
            ln.take(text="lane")
            ln.take(text="of")
            return LaneRelation("oncoming", ln.reference(declared))
        ln.take(text="lane")
        if ln.peek() is not None and ln.peek().startswith('"'):
            lane = ln.take("str")[1:-1]
            if not printable_id(lane):
                raise DslError(f"{ln.where(back=1)}: a lane id is 1 to 256 printable characters")
            return InLane(lane)
        for side in ("left", "right"):
            if ln.accept(side):
                ln.take(text="of")
                return LaneRelation(side, ln.reference(declared))
        ln.take(text="of")
        return LaneRelation("same", ln.reference(declared))

    @property
    def first_words(self) -> frozenset[str]:
        return frozenset({"in", "on", "off", "anywhere"})

    # ------------------------------------------------------------------------------- Scenic
    def scenic_prelude(self, config: SynthConfig) -> str:
        return LANE_PRELUDE


LANE_PRELUDE = '''\
# Lanes (r2sgen's LANE clause): each object records its lane clause as the property dsl__lane, and a requirement
# after it keeps it there, over the recorded road's regions (the road section, below; docs/scenic.md).
'''

LANE = LanePart()
