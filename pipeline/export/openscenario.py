"""A scene or variant as OpenSCENARIO 1.2 (.xosc), on an OpenDRIVE road (.xodr) built from the scene's recorded
lanes, both written with scenariogeneration (docs/formats.md, "Exported scenarios").

The road (`road_network`): one OpenDRIVE road per recorded lane of the scene's road (the map features within
r2s scene's radius of ego), in the world frame. Its reference line is the lane's centre line, point to point
(one `line` geometry per segment: the recorded polyline, not a smooth curve, so headings jump at its vertices);
its one driving lane (-1, right-hand traffic, in the centre line's direction) is centred on it (a lane offset of
half its width) with a constant width: the lane polygon's area over the centre line's length (a mean width; the
recorded polygon itself is not kept). Roads are not linked (no junctions): successors, neighbours, road lines,
crosswalks and drivable areas are left out.

A scenario (`scenario`): every entity at its world pose (a TeleportAction to a WorldPosition: x, y, z = 0, h the
yaw in radians), with its recorded speed along its heading (an AbsoluteSpeedAction, step dynamics), as a Vehicle
(car, truck, bus, trailer, motorbike, bicycle), Pedestrian (pedestrian, animal) or MiscObject (barrier,
obstacle) with its box; the scenario stops after --steps x 0.1 s.
"""

from __future__ import annotations

import datetime
import math
import os
import re
from pathlib import Path
from typing import Any

from pipeline.errors import UserError
from pipeline.export import slug
from pipeline.export.scenarionet import HEIGHTS, STEP_S
from synth.road.roadmap import LANE, MapFeature, RoadMap
from synth.scene import Scene
from synth.version import __version__
from synth.world import WorldPose, in_world, road_in_world

# Every file says it was made at this date (the real one would make the output depend on when it ran).
DATE = datetime.datetime(2000, 1, 1)
MIN_WIDTH, MAX_WIDTH = 1.0, 10.0  # metres: a mean lane width outside these is a degenerate polygon, clamped
MIN_SEGMENT = 1e-6  # metres: shorter centre-line segments (repeated points) are skipped
HEADING_TOLERANCE = 1e-6  # radians: ASAM's redundancy check's tolerance
# Line geometries in one .xodr at most: each is ~190 bytes of XML and ~1.6 KB while scenariogeneration builds it
# (10^6 took 1.6 GB and 54 s for a 186 MB file); real roads within 50 m of ego have up to ~1,100 (nuScenes-mini).
MAX_GEOMETRIES = 100_000
VENDOR = "r2sgen"  # the .xodr header's vendor; the .xosc's FileHeader author starts with it too
NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")  # outside XML 1.0's Char
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


def xml_text(text: str) -> str:
    """Text as XML 1.0 can hold it: each character it cannot (control characters, lone surrogates as a file name
    undecodable in UTF-8 gives them, U+FFFE, U+FFFF) as its Python escape (\\x01, \\udcff): a file name or a path
    in a note must not make the file one no XML parser reads."""
    return NOT_XML.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), text)


def lane_width(polygon, line) -> float:
    """A lane's mean width: its polygon's area over its centre line's length (shoelace; clamped)."""
    n = len(polygon)
    area = abs(sum(polygon[i][0] * polygon[(i + 1) % n][1] - polygon[(i + 1) % n][0] * polygon[i][1]
                   for i in range(n))) / 2.0
    length = sum(math.dist(a, b) for a, b in zip(line, line[1:]))
    return min(MAX_WIDTH, max(MIN_WIDTH, area / length)) if length > 0 else MIN_WIDTH


def straight_runs(line) -> list[tuple[tuple[float, float], tuple[float, float]]]:
    """A centre line as line geometries: its segments (shorter than MIN_SEGMENT dropped), runs of them in one
    direction (within HEADING_TOLERANCE) as one line, as OpenDRIVE would have it (ASAM's check flags two line
    geometries in a row with the same heading as redundant)."""
    pts = [line[0]] + [b for a, b in zip(line, line[1:]) if math.dist(a, b) > MIN_SEGMENT] if line else []
    runs: list[tuple[tuple[float, float], tuple[float, float]]] = []
    start, heading = None, None
    for a, b in zip(pts, pts[1:]):
        h = math.atan2(b[1] - a[1], b[0] - a[0])
        if start is not None and abs(math.remainder(h - heading, math.tau)) < HEADING_TOLERANCE:
            runs[-1] = (start, b)
            continue
        start, heading = a, h
        runs.append((a, b))
    return runs


def lane_runs(road: RoadMap) -> list[tuple[MapFeature, list]]:
    """The lanes of a road whose centre line has a segment, each with its line geometries (straight_runs)."""
    lanes = [(f, straight_runs(f.line)) for f in road.features if f.kind == LANE]
    return [(f, runs) for f, runs in lanes if runs]


def road_network(lanes: list[tuple[MapFeature, list]], name: str):
    """The OpenDRIVE road network (scenariogeneration's OpenDrive) of a road's lanes in the world frame
    (lane_runs): one road per lane (the module docstring says what is approximated)."""
    from scenariogeneration import xodr

    odr = xodr.OpenDrive(name, revMinor="7")  # 1.7: the newest every ASAM check applies to
    for road_id, (f, segments) in enumerate(lanes, start=1):
        plan = xodr.PlanView()
        for (x0, y0), (x1, y1) in segments:
            plan.add_fixed_geometry(xodr.Line(math.dist((x0, y0), (x1, y1))), x0, y0, math.atan2(y1 - y0, x1 - x0))
        width = lane_width(f.polygon, f.line)
        centre = xodr.Lane(a=0)
        centre.add_roadmark(xodr.RoadMark(xodr.RoadMarkType.none))
        section = xodr.LaneSection(0, centre)
        lane = xodr.Lane(xodr.LaneType.driving, a=width)
        lane.add_roadmark(xodr.RoadMark(xodr.RoadMarkType.solid))
        section.add_right_lane(lane)
        profile = xodr.Lanes()
        profile.add_lanesection(section)
        profile.add_laneoffset(xodr.LaneOffset(0, width / 2.0))  # lane -1 centred on the centre line
        r = xodr.Road(road_id, plan, profile, name=xml_text(f.feature_id))
        r.add_elevation(0, 0, 0, 0, 0)  # flat: scene JSON is 2D (the schema wants an elevation in the profile)
        odr.add_road(r)
    return odr


def write_xml(element, path: Path) -> None:
    """An XML tree to a file, indented. Dates are written as DATE: the same inputs give the same bytes."""
    import xml.etree.ElementTree as ET

    ET.indent(element, space="    ")
    ET.ElementTree(element).write(path, encoding="utf-8", xml_declaration=True)


def scenario(scene: Scene, name: str, world: WorldPose, road_file: str, steps: int, note: str):
    """The OpenSCENARIO 1.2 scenario (scenariogeneration's Scenario) of one scene on the road in road_file."""
    from scenariogeneration import xosc

    entities = xosc.Entities()
    init = xosc.Init()
    for e in scene.entities:
        w = in_world(world, e)
        box = xosc.BoundingBox(w.width, w.length, HEIGHTS[e.type], 0, 0, HEIGHTS[e.type] / 2.0)
        entities.add_scenario_object(e.id, _object(e.id, e.type, box))
        init.add_init_action(e.id, xosc.TeleportAction(xosc.WorldPosition(w.x, w.y, 0, w.yaw)))
        if CATEGORIES[e.type][0] != "misc":  # a MiscObject does not move (no speed action applies)
            init.add_init_action(e.id, xosc.AbsoluteSpeedAction(
                w.speed or 0.0, xosc.TransitionDynamics(xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0)))
    stop = xosc.ValueTrigger("stop", 0, xosc.ConditionEdge.rising,
                             xosc.SimulationTimeCondition(steps * STEP_S, xosc.Rule.greaterThan), "stop")
    board = xosc.StoryBoard(init, stop)
    return xosc.Scenario(name, f"{VENDOR} {__version__}: {note}", xosc.ParameterDeclarations(), entities, board,
                         xosc.RoadNetwork(roadfile=road_file), xosc.Catalog(), osc_minor_version=2,
                         creation_date=DATE)


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
        lanes = lane_runs(road_in_world(world, recorded.road))
        if not lanes:
            raise UserError(f"the scene {recorded.frame_id!r} has no lane with a centre line: OpenDRIVE needs a road")
        geometries = sum(len(runs) for _, runs in lanes)
        if geometries > MAX_GEOMETRIES:
            raise UserError(f"the road of the scene {recorded.frame_id!r} would be {geometries:,} OpenDRIVE line "
                            f"geometries, more than {MAX_GEOMETRIES:,} (a real scene's road has about 1,000): export "
                            "a scene with a smaller road (r2s scene --radius)")
        odr = road_network(lanes, slug(recorded.frame_id))
        element = odr.get_element()
        header = element.find("header")
        header.set("date", DATE.isoformat())
        header.set("vendor", VENDOR)
        write_xml(element, folder / self.road_file)

    def add(self, item, world: WorldPose, road: RoadMap | None) -> None:
        what = "the recorded frame" if item.variant is None else f"variant {item.variant}"
        note = f"{what} of {self.recorded_frame}" + (f", program {self.options.program_file}"
                                                       if self.options.program_file else "")
        sc = scenario(item.scene, item.name, world, self.road_file, self.options.steps, xml_text(note))
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
