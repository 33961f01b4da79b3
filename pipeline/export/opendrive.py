"""A linked road network (synth.road.opendrive.Network) as OpenDRIVE 1.7 XML, written with scenariogeneration
(docs/formats.md, "OpenDRIVE"): one road per Network road, its reference line as line geometries, its driving
lanes (-1, and -2, ... for lanes side by side) with lane -1 centred on it by a lane offset of half its width,
widths and offsets linear between the reference line's points; road marks on both lane edges; crosswalks as objects with their outline; road and lane
links; junctions with their connections; the header offset (the recentring offset, or a scene's ego pose). `r2s export --to opendrive` writes this alone; `--to openscenario` writes it beside its scenarios."""

from __future__ import annotations

import datetime
import math
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from pipeline.cli.inputs import read_scene
from pipeline.errors import UserError
from pipeline.outputs import writing
from storage.atomic import atomic_path
from synth.road.opendrive import MAP_SUFFIX, Crosswalk, Network, Road, TooManyGeometries, network, straight_runs
from synth.road.roadmap import RoadMap
from synth.scene import Scene
from synth.world import WorldPose, road_in_world

FRAME_TOLERANCE = 1e-9  # metres, radians: a file's header offset this near a scene's ego pose is its frame
DATE = datetime.datetime(2000, 1, 1)  # every file says it was made then: the same inputs give the same bytes
VENDOR = "r2sgen"  # the header's vendor: how an earlier export's file is told from a user's
SAME = 2.5e-6  # metres (and m/m): width pieces this close are one (ASAM: 1e-6; halved for the offsets, still one)
# Line geometries in one .xodr at most: each is ~190 bytes of XML and ~1.6 KB while scenariogeneration builds it
# (10^6 took 1.6 GB and 54 s for a 186 MB file); real roads within 50 m of ego have up to ~1,100 (nuScenes-mini).
MAX_GEOMETRIES = 100_000
NOT_XML = re.compile("[^\t\n\r\x20-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")  # outside XML 1.0's Char


def xml_text(text: str) -> str:
    """Text as XML 1.0 can hold it: each character it cannot (control characters, lone surrogates as a file name
    undecodable in UTF-8 gives them, U+FFFE, U+FFFF) as its Python escape (\\x01, \\udcff): a file name or a path
    in a note must not make the file one no XML parser reads."""
    return NOT_XML.sub(lambda m: m.group().encode("unicode_escape").decode("ascii"), text)


def _same_line(p: tuple[float, float, float], q: tuple[float, float, float]) -> bool:
    """Whether two width pieces (s, a, b: a + b (s' - s)) are one line as ASAM's redundancy check decides it
    (qc_opendrive's are_same_equations, within its EPSILON): the second is then left out."""
    (s1, a1, b1), (s2, a2, b2) = p, q
    return abs(a1 - a2 - b1 * s1 + b2 * s2) < SAME and abs(b1 - b2) < SAME


def _mark(mark: tuple[str, str, str]):
    """A road mark (type, colour, laneChange: synth.road.opendrive.ROAD_MARKS) as scenariogeneration's."""
    from scenariogeneration import xodr

    kind, colour, change = mark
    return xodr.RoadMark(getattr(xodr.RoadMarkType, kind), color=getattr(xodr.RoadMarkColor, colour),
                         laneChange=getattr(xodr.LaneChange, change))


def _crosswalk(c: Crosswalk, n: int):
    """A crosswalk as an OpenDRIVE object (id n, unique in the file): type crosswalk at (s, t), its outline's
    local corners, closed."""
    from scenariogeneration import xodr

    obj = xodr.Object(c.s, c.t, Type=xodr.ObjectType.crosswalk, id=str(n), name=xml_text(c.feature_id), zOffset=0)
    outline = xodr.Outline(closed=True, outer=True, id=0)
    for n, (u, v) in enumerate(c.outline):
        outline.add_corner(xodr.CornerLocal(u, v, 0, 0, id=n))
    obj.add_outline(outline)
    return obj


def _pieces(s, w) -> list[tuple[float, float, float]]:
    """A width linear between points as polynomial pieces (s, a, b): an entry only where the slope changes (ASAM
    flags repeated ones)."""
    pieces: list[tuple[float, float, float]] = []
    for i in range(len(s) - 1):
        slope = (w[i + 1] - w[i]) / (s[i + 1] - s[i])
        if pieces and _same_line(pieces[-1], (s[i], w[i], slope)):
            continue
        pieces.append((s[i], w[i], slope))
    return pieces


def _profile(road: Road):
    """The road's lanes: a centre lane and lanes -1, -2, ... with their widths linear between points, the lane
    offsets that centre lane -1 on the reference line (half its width), each lane's road mark on its right edge
    (the centre lane's: lane -1's left edge) and its lane links."""
    from scenariogeneration import xodr

    s = road.s
    centre = xodr.Lane(a=0)
    centre.add_roadmark(_mark(road.marks[0]))  # the centre lane's mark is lane -1's left edge
    section = xodr.LaneSection(0, centre)
    pre, suc = road.predecessor, road.successor
    widths = [road.widths] + [side.widths for side in road.side]
    marks = [road.marks[1]] + [side.mark for side in road.side]
    for k, (w, mark) in enumerate(zip(widths, marks)):
        pieces = _pieces(s, w)
        _, a, b = pieces[0]
        lane = xodr.Lane(xodr.LaneType.driving, a=a, b=b)
        for s0, a, b in pieces[1:]:
            lane.add_lane_width(a=a, b=b, soffset=s0)
        lane.add_roadmark(_mark(mark))
        into = road.lane_links[k] if road.lane_links else (-1, -1)
        if pre is not None and pre.kind == "road" and into[0] is not None:
            lane.add_link("predecessor", into[0])
        if suc is not None and suc.kind == "road" and into[1] is not None:
            lane.add_link("successor", into[1])
        section.add_right_lane(lane)
    profile = xodr.Lanes()
    profile.add_lanesection(section)
    for s0, a, b in _pieces(s, road.widths):
        profile.add_laneoffset(xodr.LaneOffset(s0, a / 2.0, b / 2.0))
    return profile


def opendrive(net: Network, name: str, frame: tuple[float, float, float] | None = None):
    """The XML element of a network (module docstring); `frame`: the header offset, the world pose (x, y, hdg)
    of the file's origin (default: the network's recentring offset, hdg 0)."""
    from scenariogeneration import xodr
    from scenariogeneration.xodr.signals_objects import _SignalObjectBase

    # scenariogeneration files every object's and signal's id in registries of the whole process, renumbering an
    # id met before (and printing a warning on stdout): each file's ids are its own, so the same road is the same
    # file whatever was exported before it in this process
    _SignalObjectBase._usedIDs.clear()
    _SignalObjectBase._IDCounter.clear()
    odr = xodr.OpenDrive(xml_text(name), revMinor="7")  # 1.7: the newest every ASAM check applies to
    types = {"road": xodr.ElementType.road, "junction": xodr.ElementType.junction}
    contact = {"start": xodr.ContactPoint.start, "end": xodr.ContactPoint.end, None: None}
    walks: dict[int, list[tuple[int, Crosswalk]]] = {}
    for n, c in enumerate(net.crosswalks):
        walks.setdefault(c.road, []).append((n, c))
    for road in net.roads:
        plan = xodr.PlanView()
        for (x0, y0), (x1, y1) in straight_runs(road.points):
            plan.add_fixed_geometry(xodr.Line(math.dist((x0, y0), (x1, y1))), x0, y0, math.atan2(y1 - y0, x1 - x0))
        r = xodr.Road(road.id, plan, _profile(road), road_type=road.junction, name=xml_text(road.name))
        r.add_elevation(0, 0, 0, 0, 0)  # flat: scene JSON is 2D (the schema wants an elevation in the profile)
        if road.predecessor is not None:
            r.add_predecessor(types[road.predecessor.kind], road.predecessor.id, contact[road.predecessor.contact])
        if road.successor is not None:
            r.add_successor(types[road.successor.kind], road.successor.id, contact[road.successor.contact])
        for n, c in walks.get(road.id, ()):
            r.add_object(_crosswalk(c, n))
        odr.add_road(r)
    for j in net.junctions:
        junction = xodr.Junction(f"junction {j.id}", j.id)
        for n, (incoming, connecting, lane) in enumerate(j.connections):
            c = xodr.Connection(incoming, connecting, xodr.ContactPoint.start, id=n)
            c.add_lanelink(lane, -1)
            junction.add_connection(c)
        odr.add_junction(junction)
    element = odr.get_element()
    for obj in element.iter("object"):  # scenariogeneration writes an absent subtype as the text "None"
        if obj.get("subtype") == "None":
            del obj.attrib["subtype"]
    header = element.find("header")
    header.set("date", DATE.isoformat())
    header.set("vendor", VENDOR)
    _set_offset(header, frame if frame is not None else (net.offset[0], net.offset[1], 0.0))
    return element


def _set_offset(header, frame: tuple[float, float, float]) -> None:
    """The header's offset (OpenDRIVE 1.7 t_header_Offset): the recorded world's pose of the file's origin, a
    point (u, v) of the file being (x, y) + (u, v) turned by hdg there."""
    x, y, hdg = frame
    ET.SubElement(header, "offset", x=repr(x), y=repr(y), z="0.0", hdg=repr(hdg))


def ego_frame(world: WorldPose | None) -> tuple[float, float, float]:
    """The header offset of a scene's road in its ego frame: the ego's world pose, hdg the direction of the ego
    frame's +x (the heading less 90 degrees, in radians); (0, 0, 0) for a scene with no world."""
    if world is None:
        return (0.0, 0.0, 0.0)
    return (world.x, world.y, math.radians(world.heading - 90.0))


def header_frame(path: str) -> tuple[float, float, float] | None:
    """The header offset (x, y, hdg) of an OpenDRIVE file, None where its header has none; a UserError where
    the file is not OpenDRIVE. Reads up to the header only."""
    try:
        for n, (event, el) in enumerate(ET.iterparse(path, events=("start", "end"))):
            if n == 0 and el.tag != "OpenDRIVE":
                raise UserError(f"{path} is not an OpenDRIVE file (its root is <{xml_text(el.tag)[:40]}>)")
            if event == "end" and el.tag == "offset":
                return tuple(float(el.get(k, "0")) for k in ("x", "y", "hdg"))  # type: ignore[return-value]
            if event == "end" and el.tag == "header":
                return None
    except (ET.ParseError, ValueError, OSError) as exc:
        raise UserError(f"{path} is not an OpenDRIVE file ({xml_text(str(exc))[:100]})") from None
    raise UserError(f"{path} is not an OpenDRIVE file (no header)")


def check_road_frame(path: str, scene: Scene) -> None:
    """A UserError unless the OpenDRIVE file at `path` is in the scene's ego frame (its header offset the ego's
    world pose, as --frame ego writes it); a file without a header offset is taken as in it."""
    if not Path(path).is_file():
        raise UserError(f"--road {path} is not a file (r2s export SCENE.json --to opendrive --frame ego --out "
                        "F.xodr writes it)")
    if not path.lower().endswith(MAP_SUFFIX):
        raise UserError(f"--road {path} is not an OpenDRIVE file: its name must end in {MAP_SUFFIX}")
    frame = header_frame(path)
    want = ego_frame(scene.world)
    if frame is not None and any(abs(a - b) > FRAME_TOLERANCE for a, b in zip(frame, want)):
        raise UserError(f"--road {path} is not in the ego frame of {scene.frame_id!r} (its header offset is "
                        f"{frame[0]:g}, {frame[1]:g}, {frame[2]:g}): write it with r2s export SCENE.json --to "
                        "opendrive --frame ego --out F.xodr")


def map_path(road: str, out: str | None) -> str:
    """How a Scenic text names its map: relative to the text's file where it is written to one (localPath
    resolves it there, so the two move together), absolute on standard output."""
    target = Path(road).resolve()
    if out is None:
        return str(target)
    return os.path.relpath(target, Path(out).resolve().parent)


def write_xml(element, path: Path) -> None:
    """An XML tree to a file, indented."""
    ET.indent(element, space="    ")
    ET.ElementTree(element).write(path, encoding="utf-8", xml_declaration=True)


def linked(road: RoadMap, what: str, recentre: bool = True) -> Network:
    """The linked network of a road (synth.road.opendrive; recentred, or in the road's own frame), or one line
    (UserError) where OpenDRIVE cannot be had: no lane with a centre line, or more than MAX_GEOMETRIES line
    geometries."""
    try:
        import scenariogeneration  # noqa: F401 (pinned in requirements.lock; optional for a pip install)
    except ImportError:
        raise UserError("OpenDRIVE needs scenariogeneration (pip install scenariogeneration==0.16.7)") from None
    try:  # the bound is checked before the costly marks, grouping and XML
        net = network(road, recentre, MAX_GEOMETRIES)
        geometries = sum(len(straight_runs(r.points)) for r in net.roads)  # the file's: grouping may cut roads
        if geometries > MAX_GEOMETRIES:
            raise TooManyGeometries(geometries)
    except TooManyGeometries as exc:
        raise UserError(f"the road of {what} would be {'' if exc.exact else 'at least '}{exc.count:,} OpenDRIVE "
                        f"line geometries, more than "
                        f"{MAX_GEOMETRIES:,} (a real scene's road has about 1,000): export a smaller road "
                        "(r2s scene --radius)") from None
    except ValueError as exc:  # too many paths through junctions
        raise UserError(f"the road of {what}: {exc}") from None
    if not net.roads:
        raise UserError(f"{what} has no lane with a centre line: OpenDRIVE needs a road")
    return net


def export_road(source: str, map_id: str | None, out: str, frame: str = "world") -> str:
    """`r2s export SOURCE --to opendrive --out F.xodr [--frame world|ego]`: the road of a scene JSON (in its
    world, recentred; or in its ego frame, the frame of its Scenic text) or one map of a maps dataset, written
    atomically to `out`; returns the line to tell the user."""
    if Path(source).is_dir() or source.endswith(".parquet"):
        from frames.maps import read_maps  # pyarrow: only a maps dataset is Parquet, a scene JSON is not

        maps = [m for m in read_maps(source) if map_id is None or m.map_id == map_id]
        if not maps:
            raise UserError(f"{source} holds no map" + (f" {map_id!r}" if map_id is not None else ""))
        if len(maps) > 1:
            raise UserError(f"{source} holds {len(maps)} maps: name one with --map ID")
        if frame == "ego":
            raise UserError("--frame ego is a scene's ego frame: a maps dataset has no ego (export a scene JSON)")
        road, what = maps[0], f"map {maps[0].map_id!r}"
    else:
        if map_id is not None:
            raise UserError("--map names a map of a maps dataset; a scene JSON has its own road")
        scene = read_scene(source)
        if scene.road is None:
            raise UserError(f"the scene {scene.frame_id!r} has no road: export a frame whose source has a map")
        what = f"the scene {scene.frame_id!r}"
        road = scene.road if frame == "ego" else road_in_world(scene.world or WorldPose.identity(), scene.road)
    net = linked(road, what, recentre=frame == "world")
    header = ego_frame(scene.world) if frame == "ego" else None
    element = opendrive(net, road.map_id, header)
    with writing(out), atomic_path(out) as tmp:
        write_xml(element, tmp)
    connecting = sum(r.junction != -1 for r in net.roads)
    return (f"wrote {out}: {len(net.roads) - connecting} roads and {connecting} connecting roads in "
            f"{len(net.junctions)} junctions from {what}, "
            + (f"in its ego frame (ego at {header[0]:g}, {header[1]:g} in the world)" if header is not None
               else f"offset ({net.offset[0]:g}, {net.offset[1]:g})")
            + "".join(f"; {n}" for n in net.notes))
