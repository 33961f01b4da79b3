"""A scene or variant as OpenSCENARIO 1.2 (.xosc), on an OpenDRIVE road (.xodr) built from the scene's recorded
lanes, both written with scenariogeneration (docs/formats.md, "Exported scenarios").

The road: the scene's road (the map features within r2s scene's radius of ego) as linked OpenDRIVE, recentred
(pipeline/export/opendrive.py, synth/road/opendrive.py; docs/formats.md "OpenDRIVE").

A scenario (`scenario`): every entity at its world pose less the road's offset (a TeleportAction to a
WorldPosition: x, y in the road's recentred frame, z = 0, h the yaw in radians; an entity in a lane, by its lane
fact on the scene's road, to a LanePosition on that lane's road instead: s, the offset from the lane's centre,
lane -1, h the same yaw, absolute), with its recorded speed along
its heading (an AbsoluteSpeedAction, step dynamics), as a Vehicle (car, truck, bus, trailer, motorbike, bicycle),
Pedestrian (pedestrian, animal) or MiscObject (barrier, obstacle) with its box; the scenario stops after
--steps x 0.1 s.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from pipeline.errors import UserError
from pipeline.export import slug
from pipeline.export.motion import STRAIGHT, Motion
from pipeline.export.opendrive import DATE, VENDOR, linked, opendrive, write_xml, xml_text
from pipeline.export.scenarionet import HEIGHTS
from pipeline.export.trajectory_story import story
from synth.road.lane_facts import RoadIndex
from synth.road.opendrive import Network, lane_position
from synth.road.roadmap import RoadMap
from synth.scene import Scene
from synth.version import __version__
from synth.world import WorldPose, in_world, road_in_world

SIGNATURE = f'="{VENDOR}'.encode()  # how an earlier export's file is told from a user's (OpenScenarioTarget.owns)
# Scenic class -> (what it is in OpenSCENARIO, its category)
CATEGORIES: dict[str, tuple[str, str]] = {
    "Car": ("vehicle", "car"), "Truck": ("vehicle", "truck"), "Bus": ("vehicle", "bus"),
    "Trailer": ("vehicle", "trailer"), "ConstructionVehicle": ("vehicle", "truck"),
    "EmergencyVehicle": ("vehicle", "van"), "Motorcycle": ("vehicle", "motorbike"),
    "Bicycle": ("vehicle", "bicycle"), "Pedestrian": ("pedestrian", "pedestrian"),
    "Animal": ("pedestrian", "animal"), "Barrier": ("misc", "barrier"), "TrafficCone": ("misc", "obstacle"),
    "PushableObject": ("misc", "obstacle"), "Debris": ("misc", "obstacle"), "BicycleRack": ("misc", "obstacle"),
    "Object": ("misc", "obstacle"),
}


def scenario(scene: Scene, name: str, world: WorldPose, road_file: str, motion: Motion, note: str,
             offset: tuple[float, float] = (0.0, 0.0), net: Network | None = None, road: RoadMap | None = None):
    """The OpenSCENARIO 1.2 scenario (scenariogeneration's Scenario) of one scene on the road in road_file, whose
    coordinates are the world's less `offset`; with the road's network `net` and the scene's road (ego frame),
    an entity in a lane (its lane fact on that road) is placed by a LanePosition on the road of that lane. The
    scene's entities start where it has them; `motion` (its first step the scene's) says what they do: on at their
    speed (STRAIGHT: an initial speed, no story), else a path and a speed profile each
    (pipeline/export/trajectory_story.py), an entity of the motion absent from the scene (a clip's, first seen
    later) removed in Init and added at its first pose at its time."""
    from scenariogeneration import xosc

    entities = xosc.Entities()
    init = xosc.Init()
    lanes = _lanes(scene, road) if net is not None and road is not None else {}
    placed = set()
    for e in scene.entities:
        w = in_world(world, e)
        placed.add(e.id)
        entities.add_scenario_object(e.id, _object(e.id, e.type, _box(e.type, w.length, w.width)))
        x, y = w.x - offset[0], w.y - offset[1]
        on = lane_position(net, lanes[e.id], x, y) if lanes.get(e.id) is not None else None
        if on is not None:  # the lane's road, s along it, the offset from the lane's centre; the yaw absolute
            road_id, s, t = on
            where = xosc.LanePosition(s, t, -1, road_id, xosc.Orientation(h=w.yaw,
                                                                       reference=xosc.ReferenceContext.absolute))
        else:
            where = xosc.WorldPosition(x, y, 0, w.yaw)
        init.add_init_action(e.id, xosc.TeleportAction(where))
        if CATEGORIES[e.type][0] != "misc":  # a MiscObject does not move (no speed action applies)
            init.add_init_action(e.id, xosc.AbsoluteSpeedAction(
                w.speed or 0.0, xosc.TransitionDynamics(xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0)))
    movable = {e.id for e in scene.entities if CATEGORIES[e.type][0] != "misc"}
    for t in motion.trajectories if motion.how != STRAIGHT else ():
        if t.id in placed:
            continue
        # first seen after the scene's frame: not in the scenario until its story adds it at its first pose
        entities.add_scenario_object(t.id, _object(t.id, t.type, _box(t.type, t.length, t.width)))
        init.add_global_action(xosc.DeleteEntityAction(t.id))
        if CATEGORIES[t.type][0] != "misc":
            movable.add(t.id)
    stop = xosc.ValueTrigger("stop", 0, xosc.ConditionEdge.rising,
                             xosc.SimulationTimeCondition(motion.end, xosc.Rule.greaterThan), "stop")
    board = xosc.StoryBoard(init, stop)
    moving = story(motion, movable, offset) if motion.how != STRAIGHT else None
    if moving is not None:
        board.add_story(moving)
    return xosc.Scenario(name, f"{VENDOR} {__version__}: {note}", xosc.ParameterDeclarations(), entities, board,
                         xosc.RoadNetwork(roadfile=road_file), xosc.Catalog(), osc_minor_version=2,
                         creation_date=DATE)


def _box(etype: str, length: float, width: float):
    from scenariogeneration import xosc

    return xosc.BoundingBox(width, length, HEIGHTS[etype], 0, 0, HEIGHTS[etype] / 2.0)


def _lanes(scene: Scene, road: RoadMap) -> dict[str, str | None]:
    """Each entity's lane fact on the scene's road (synth.road.lane_facts: its chosen lane, None in none)."""
    es = scene.entities
    facts = RoadIndex(road).facts([e.x for e in es], [e.y for e in es], [e.heading + 90.0 for e in es])
    return {e.id: f.lane for e, f in zip(es, facts)}


def _object(eid: str, etype: str, box) -> Any:
    from scenariogeneration import xosc

    kind, category = CATEGORIES[etype]
    if kind == "vehicle":
        length = box.boundingbox.length
        axle = xosc.Axle(0.5, 0.6, box.boundingbox.width, length * 0.3, 0.3)
        front = xosc.Axle(0.5, 0.6, box.boundingbox.width, length * 0.8, 0.3)
        return xosc.Vehicle(eid, getattr(xosc.VehicleCategory, category), box, front, axle, 70, 10, 10)
    if kind == "pedestrian":
        return xosc.Pedestrian(eid, 80, getattr(xosc.PedestrianCategory, category), box)
    return xosc.MiscObject(eid, 50, getattr(xosc.MiscObjectCategory, category), box)


class _Writer:
    def __init__(self, folder: Path, recorded: Scene, options) -> None:
        try:
            import scenariogeneration  # noqa: F401 (pinned in requirements.lock; optional for a pip install)
        except ImportError:
            raise UserError("--to openscenario needs scenariogeneration (pip install scenariogeneration==0.16.7)") \
                from None
        self.folder = folder
        self.options = options
        self.recorded_frame = recorded.frame_id
        self.road_file = f"{slug(recorded.frame_id)}.xodr"
        world = recorded.world or WorldPose.identity()
        net = linked(road_in_world(world, recorded.road), f"the scene {recorded.frame_id!r}")
        self.offset = net.offset
        self.net = net
        write_xml(opendrive(net, slug(recorded.frame_id)), folder / self.road_file)

    def add(self, item, world: WorldPose, road: RoadMap | None) -> None:
        what = ("the recorded frame" if item.variant is None else f"variant {item.variant}") if item.clip is None \
            else f"the clip of {item.clip.scene} ({len(item.clip.scenes)} frames) from"
        note = f"{what} of {self.recorded_frame}" + (f", program {self.options.program_file}"
                                                       if self.options.program_file else "")
        sc = scenario(item.scene, item.name, world, self.road_file, item.motion, xml_text(note), self.offset,
                      self.net, road)
        write_xml(sc.get_element(), self.folder / f"{item.name}.xosc")

    def close(self) -> None:
        pass


class OpenScenarioTarget:
    name = "openscenario"
    needs_road = True

    def owns(self, entry: os.DirEntry) -> bool:
        """An .xosc or .xodr file that says it was written by r2sgen (FileHeader's author, the header's vendor) in
        its first KB: a folder of someone else's OpenSCENARIO files is not replaced."""
        if not entry.name.endswith((".xosc", ".xodr")):
            return False
        try:
            with open(entry.path, "rb") as f:
                return SIGNATURE in f.read(1024)
        except OSError:
            return False

    def open(self, folder: Path, recorded: Scene, options) -> _Writer:
        return _Writer(folder, recorded, options)


TARGET = OpenScenarioTarget()
