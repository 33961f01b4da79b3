"""A scene's road for entities placed in it (its ego frame): the lane facts of one pose at a time, decided
exactly as extraction decides them (synth.road.lane_facts), and a scene with each entity's facts where it now is.
What the variant sampler asks of every pose it tries (a lane clause's requirement, synth.draws.Requirement) and
what every variant carries."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from synth.road.lane_facts import Banded, Cells, LaneFacts, RoadIndex
from synth.road.lane_relations import LaneGraph
from synth.road.roadmap import CROSSWALK, DRIVABLE_AREA, INTERSECTION, LANE, MapFeature, RoadMap
from synth.scene import Entity, Scene

MAX_REMEMBERED = 100_000  # lane facts of poses a SceneRoad keeps


class SceneRoad:
    """A scene's road (in its ego frame) and the lane facts of entities placed in it, headings as scenes give them
    (degrees counter-clockwise from +y, where the facts' directions are from +x): what the variant sampler asks
    of every pose it tries (a lane clause's requirement) and what every variant carries."""

    def __init__(self, road: RoadMap) -> None:
        self.road = road
        self.index = RoadIndex(road)
        # One pose at a time in plain Python (the sampler asks for one per move; numpy's per-call cost would
        # dominate): bounding boxes, then the exact crossing test over the edges of the point's band (Banded).
        self.areas = {kind: Cells([(Banded(f.polygon), f) for f in road.of_kind(kind)])
                      for kind in (LANE, CROSSWALK, INTERSECTION, DRIVABLE_AREA)}
        self._facts: dict[tuple[float, float, float], LaneFacts] = {}
        self._graph = None

    def _containing(self, kind: str, x: float, y: float) -> list[MapFeature]:
        return [f for ring, f in self.areas[kind].near(x, y) if ring.contains(x, y)]

    def facts(self, x: float, y: float, heading: float) -> LaneFacts:
        """The lane facts of one pose: RoadIndex.facts's, for one point (remembered: a chain asks for the same
        pose again, a reference's for each of its dependants)."""
        key = (x, y, heading)
        if key not in self._facts:
            if len(self._facts) >= MAX_REMEMBERED:
                self._facts.clear()
            self._facts[key] = self._decide(x, y, heading)
        return self._facts[key]

    def _decide(self, x: float, y: float, heading: float) -> LaneFacts:
        lanes = self._containing(LANE, x, y)
        chosen = self.index.choose_lane(lanes, x, y, (heading + 90.0) % 360.0)
        return LaneFacts(
            lanes=tuple(sorted(f.feature_id for f in lanes)),
            lane=chosen.feature_id if chosen is not None else None,
            in_intersection=bool(self._containing(INTERSECTION, x, y)) or any(f.is_intersection for f in lanes),
            on_crosswalk=bool(self._containing(CROSSWALK, x, y)),
            off_road=not lanes and not self._containing(DRIVABLE_AREA, x, y),
        )

    @property
    def graph(self):
        """The lane graph of the road (synth.road.lane_relations), built once: what a lane relation reads."""
        if self._graph is None:
            self._graph = LaneGraph(self.road)
        return self._graph

    def entity(self, pose) -> Entity:
        """A pose (x, y, heading: a synth.draws.Pose) as an entity on this road: its lane facts and the lane
        graph, all that a lane clause's semantics reads."""
        f = self.facts(pose.x, pose.y, pose.heading)
        return Entity("placed", "Car", pose.x, pose.y, pose.heading, lanes=f.lanes, lane=f.lane,
                      in_intersection=f.in_intersection, on_crosswalk=f.on_crosswalk, off_road=f.off_road,
                      lane_graph=self.graph)

    def placed(self, scene: Scene) -> Scene:
        """The scene on this road, every entity with its lane facts decided again where it now is (and the lane
        graph, built once for all variants)."""
        ents = scene.entities
        facts = self.index.facts(np.array([e.x for e in ents]), np.array([e.y for e in ents]),
                                 np.array([(e.heading + 90.0) % 360.0 for e in ents]))
        return replace(scene, road=self.road, entities=tuple(
            replace(e, lanes=f.lanes, lane=f.lane, in_intersection=f.in_intersection, on_crosswalk=f.on_crosswalk,
                    off_road=f.off_road, lane_graph=self.graph) for e, f in zip(ents, facts)))
