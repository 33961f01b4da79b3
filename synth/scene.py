"""The entity model: a scene is ego plus typed, placed, oriented entities, validated on construction.

Validation is the gate every input passes (scene JSON, frames from extractors, sampled variants): ids come
from a closed pattern that can never carry code into generated Scenic or DSL text, types from a closed set,
numbers are finite.
"""

from __future__ import annotations

import builtins
import json
import keyword
import math
import re
import sys
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

from synth.errors import InputError

if TYPE_CHECKING:
    from synth.road.lane_relations import LaneGraph
    from synth.road.roadmap import RoadMap
    from synth.world import WorldPose

# Scenic classes an entity may have, with typical (length, width) in metres for when a source has no box.
ENTITY_TYPES: Mapping[str, tuple[float, float]] = {
    "Car": (4.6, 1.9),
    "Truck": (7.0, 2.5),
    "Bus": (11.0, 2.9),
    "Trailer": (10.0, 2.8),
    "ConstructionVehicle": (6.5, 2.8),
    "EmergencyVehicle": (5.5, 2.2),
    "Motorcycle": (2.1, 0.8),
    "Bicycle": (1.7, 0.6),
    "Pedestrian": (0.7, 0.7),
    "Animal": (1.0, 0.5),
    "Barrier": (0.5, 2.5),
    "TrafficCone": (0.4, 0.4),
    "PushableObject": (0.8, 0.6),
    "Debris": (0.8, 0.8),
    "BicycleRack": (2.0, 1.0),
    "Object": (1.0, 1.0),
}

# The classes `--categories vehicles` keeps, and what the pattern type `Vehicle` matches (synth.patterns.one_frame).
VEHICLE_CLASSES = frozenset(
    {"Car", "Truck", "Bus", "Motorcycle", "Bicycle", "Trailer", "ConstructionVehicle", "EmergencyVehicle"}
)

EGO_ID = "ego"
MAX_ID_LENGTH = 64
MAX_FRAME_ID_LENGTH = 256
MAX_COORDINATE = 1e6  # metres from ego, |x| and |y|
DEFAULT_MAX_ENTITIES = 1000
# Bounds on a measurement error (robust synthesis): metres of position, degrees of heading, m/s of speed.
MAX_POS_SIGMA = 1000.0
MAX_HEADING_SIGMA = 90.0
MAX_SPEED_SIGMA = 100.0
MAX_SPEED = 1000.0  # m/s: anything faster is a unit or decoding error, not a road user
# The optional per-entity bounds, each with its cap (the sigma keys of scene JSON and the frames columns).
SIGMA_CAPS: Mapping[str, float] = {"pos_sigma": MAX_POS_SIGMA, "heading_sigma": MAX_HEADING_SIGMA,
                                   "speed_sigma": MAX_SPEED_SIGMA}

_ID_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")

# Words that an id must not be: Python's and Scenic's keywords (scenic 3.1.1 grammar), Python builtins, and
# the names generated Scenic text itself binds. An id is printed verbatim into programs, so anything that
# could change what the program means is refused.
_SCENIC_WORDS = frozenset(
    ["abort", "above", "additive", "after", "ahead", "along", "altitude", "always", "angle", "apparent", "apparently", "at", "attribute", "away", "back", "behavior", "behind", "below", "beyond", "bottom", "by", "can", "case", "choose", "compose", "contained", "deg", "directly", "distance", "do", "dynamic", "ego", "eval", "eventually", "every", "facing", "final", "follow", "following", "from", "front", "heading", "implies", "initial", "interrupt", "intersects", "invariant", "kind", "left", "model", "monitor", "mutate", "new", "next", "of", "offset", "on", "override", "param", "past", "position", "precondition", "print", "record", "relative", "require", "right", "scenario", "seconds", "see", "setup", "shuffle", "simulation", "simulator", "steps", "take", "terminate", "to", "top", "toward", "until", "visible", "wait", "when", "with", "workspace", "Range", "Vector", "Point", "OrientedPoint", "Object", "Uniform", "Normal", "Discrete", "Options", "TruncatedNormal", "globalParameters", "localPath", "verbosePrint", "math", "simulation", "resample", "hypot"]
)
RESERVED_IDS = frozenset(keyword.kwlist) | frozenset(keyword.softkwlist) | _SCENIC_WORDS | frozenset(
    dir(builtins)
) | frozenset(ENTITY_TYPES)


class SceneError(InputError, ValueError):
    """The input is not a valid scene. The message is one line, fit for a user."""


def check_identifier(name: Any, what: str = "id") -> str:
    """Return name if it may be printed into generated code as an entity id, else raise SceneError."""
    if not isinstance(name, str):
        raise SceneError(f"{what} must be a string, got {type(name).__name__}")
    if len(name) > MAX_ID_LENGTH:
        raise SceneError(f"{what} {name[:20]!r}... is longer than {MAX_ID_LENGTH} characters")
    if not _ID_PATTERN.match(name) or "__" in name:
        raise SceneError(f"{what} {name!r} is not an identifier (letters, digits, single underscores)")
    if name in RESERVED_IDS and name != EGO_ID:
        raise SceneError(f"{what} {name!r} is a reserved word in Python or Scenic")
    return name


def _coordinate(value: Any, what: str) -> float:
    """A position in metres within the supported range (docs/formats.md): beyond MAX_COORDINATE the exact
    certification of programs fails (1e154 m squared is past every float), and a subnormal (5e-324) loses the
    precision its bearings need; 0 and every normal float up to 1e6 m in magnitude are certified."""
    v = _finite(value, what)
    if abs(v) > MAX_COORDINATE or (v != 0.0 and abs(v) < sys.float_info.min):
        raise SceneError(f"{what} is {value!r}, outside the supported range: 0 or 2.2e-308 to {MAX_COORDINATE:g} m "
                         "in magnitude")
    return v


def check_frame_id(frame_id: Any) -> str:
    """Return frame_id if it is a frame id (scene JSON, frames files): printable text of 1 to MAX_FRAME_ID_LENGTH
    characters (it names output files and report rows), else raise SceneError."""
    if not isinstance(frame_id, str) or not frame_id or len(frame_id) > MAX_FRAME_ID_LENGTH or not frame_id.isprintable():
        shown = repr(frame_id[:40]) + ("..." if len(frame_id) > 40 else "") if isinstance(frame_id, str) else \
            type(frame_id).__name__
        raise SceneError(f"frame_id {shown} is not a printable string of 1 to {MAX_FRAME_ID_LENGTH} characters")
    return frame_id


def _finite(value: Any, what: str) -> float:
    # bool is an int subclass; true/false in JSON is never a coordinate.
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{what} must be a number, got {type(value).__name__}")
    try:
        f = float(value)
    except OverflowError:  # an integer of hundreds of digits (JSON has no bound): no float holds it
        raise SceneError(f"{what} must be finite, got an integer of {value.bit_length()} bits") from None
    if not math.isfinite(f):
        raise SceneError(f"{what} must be finite, got {value!r}")
    return f


@dataclass(frozen=True)
class Entity:
    """One recorded road user: ego-centric metres, heading in degrees counter-clockwise from +y (docs/spec.md)."""

    id: str
    type: str
    x: float
    y: float
    heading: float
    length: float | None = None
    width: float | None = None
    # This entity's own bound on its measurement error (position: metres, a disc; heading: degrees, each side),
    # overriding the configured uncertainty (robust synthesis). None: the configured one applies.
    pos_sigma: float | None = None
    heading_sigma: float | None = None
    # Magnitude of the ground velocity (m/s, >= 0); None where the source does not know it (motion needs it).
    speed: float | None = None
    speed_sigma: float | None = None  # m/s, each side (robust synthesis with motion)
    # Where it is on the recorded road (docs/formats.md, "Lane facts"; synth.road.lane_facts), as extraction decided
    # exactly in the map's frame; None where the scene has no map or the source did not place this entity.
    lanes: tuple[str, ...] | None = None
    lane: str | None = None
    in_intersection: bool | None = None
    on_crosswalk: bool | None = None
    off_road: bool | None = None
    # The lane graph of its scene's road (synth.road.lane_relations), set by Scene for each entity of a scene with a
    # road: how a LANE clause naming this entity as its reference reads the lanes related to its lane. Neither
    # scene JSON nor compared: a fact of the scene, not of the entity.
    lane_graph: LaneGraph | None = field(default=None, compare=False, repr=False)

    @property
    def is_ego(self) -> bool:
        return self.id == EGO_ID

    def dimensions(self) -> tuple[float, float]:
        """(length, width): the recorded box where known, else the type's typical size."""
        typical = ENTITY_TYPES[self.type]
        return (self.length or typical[0], self.width or typical[1])


@dataclass(frozen=True)
class Scene:
    """A recorded frame: ego and the entities to declare, validated on construction (build one with
    scene_from_dict / scene_from_json; to_dict / to_json write scene JSON, docs/formats.md)."""

    frame_id: str
    entities: tuple[Entity, ...]
    # The recorded road around ego, in the scene's (ego) frame: the map features within the extraction radius.
    road: RoadMap | None = None
    # Where the scene is in its source's world (the ego's recorded pose, scenario, map): what an export puts the
    # scene back into (synth.world); None where the frame's source gives no world pose.
    world: WorldPose | None = None

    def __post_init__(self) -> None:
        ids = [e.id for e in self.entities]
        if len(set(ids)) != len(ids):
            dup = next(i for i in ids if ids.count(i) > 1)
            raise SceneError(f"duplicate entity id {dup!r}")
        if ids.count(EGO_ID) != 1:
            raise SceneError("a scene needs exactly one entity with id 'ego'")
        if self.road is not None and any(e.lane_graph is None or e.lane_graph.road is not self.road
                                         for e in self.entities):
            from synth.road.lane_relations import LaneGraph  # numpy: loaded only for a scene with a road

            graph = LaneGraph(self.road)
            object.__setattr__(self, "entities", tuple(replace(e, lane_graph=graph) for e in self.entities))

    @property
    def ego(self) -> Entity:
        return next(e for e in self.entities if e.is_ego)

    @property
    def others(self) -> tuple[Entity, ...]:
        """The entities to declare, in scene order (ego is given, never declared)."""
        return tuple(e for e in self.entities if not e.is_ego)

    def by_id(self) -> dict[str, Entity]:
        return {e.id: e for e in self.entities}

    def to_dict(self) -> dict[str, Any]:
        out = []
        for e in self.entities:
            d: dict[str, Any] = {"id": e.id, "type": e.type, "x": e.x, "y": e.y, "heading": e.heading}
            if e.length is not None:
                d["length"] = e.length
            if e.width is not None:
                d["width"] = e.width
            if e.speed is not None:
                d["speed"] = e.speed
            for key in SIGMA_CAPS:
                if (v := getattr(e, key)) is not None:
                    d[key] = v
            for key in LANE_FACT_KEYS:
                if (v := getattr(e, key)) is not None:
                    d[key] = list(v) if key == "lanes" else v
            out.append(d)
        doc: dict[str, Any] = {"frame_id": self.frame_id, "entities": out}
        if self.world is not None:
            doc["world"] = self.world.to_dict()
        if self.road is not None:
            from synth.road.roadmap import road_to_dict  # numpy: loaded only for a scene with a road

            doc["road"] = road_to_dict(self.road)
        return doc

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=1) + "\n"


# Every key scene JSON may hold (docs/formats.md). Anything else is refused: a misspelt optional key would
# otherwise be silently dropped (`pos_sgima` turning robust synthesis off, `hedding` leaving a default).
SCENE_KEYS = ("frame_id", "entities", "world", "road")
REQUIRED_ENTITY_KEYS = ("id", "type", "x", "y", "heading")
LANE_FACT_KEYS = ("lanes", "lane", "in_intersection", "on_crosswalk", "off_road")
ENTITY_KEYS = (*REQUIRED_ENTITY_KEYS, "length", "width", "speed", *SIGMA_CAPS, *LANE_FACT_KEYS)


def _misspelt(key: Any, known: Iterable[str]) -> str | None:
    """The known key that `key` most likely misspells, if any."""
    import difflib

    close = difflib.get_close_matches(str(key), list(known), n=1)
    return close[0] if close else None


def _unknown_keys(raw: Mapping, known: tuple[str, ...], what: str) -> None:
    unknown = [k for k in raw if k not in known]
    if not unknown:
        return
    close = {k: _misspelt(k, known) for k in unknown}
    unknown.sort(key=lambda k: close[k] is None)  # misspellings first: they say what to fix
    named = [f"{k!r}" + (f" (did you mean {close[k]!r}?)" if close[k] else "") for k in unknown[:3]]
    more = f" and {len(unknown) - 3} more" if len(unknown) > 3 else ""
    keys = "key" if len(unknown) == 1 else "keys"
    hint = "" if any("did you mean" in n for n in named) else f"; its keys are {', '.join(known)}"
    raise SceneError(f"{what} has unknown {keys} {', '.join(named)}{more}{hint}")


def _lacks(raw: Mapping, missing: list[str], known: tuple[str, ...], what: str) -> SceneError:
    """`what lacks KEY`, naming a key of raw that misspells it."""
    unknown = [k for k in raw if k not in known]
    for key in missing:
        for k in unknown:
            if _misspelt(k, (key,)):
                return SceneError(f"{what} lacks {', '.join(missing)} ({k!r} is not a key: did you mean {key!r}?)")
    return SceneError(f"{what} lacks {', '.join(missing)}")


def entity_from_mapping(raw: Any, index: int) -> Entity:
    if not isinstance(raw, Mapping):
        raise SceneError(f"entity {index} must be an object")
    missing = [k for k in REQUIRED_ENTITY_KEYS if k not in raw]
    if missing:
        raise _lacks(raw, missing, ENTITY_KEYS, f"entity {index}")
    eid = check_identifier(raw["id"], f"entity {index} id")
    _unknown_keys(raw, ENTITY_KEYS, f"entity {eid!r}")
    etype = raw["type"]
    if not isinstance(etype, str) or etype not in ENTITY_TYPES:
        raise SceneError(
            f"entity {eid!r} has unknown type {etype!r} (known: {', '.join(sorted(ENTITY_TYPES))})"
        )
    dims = []
    for key in ("length", "width"):
        v = raw.get(key)
        if v is None:
            dims.append(None)
            continue
        f = _finite(v, f"entity {eid!r} {key}")
        if f <= 0.0:
            raise SceneError(f"entity {eid!r} {key} must be positive, got {v!r}")
        dims.append(f)
    sigmas = []
    for key, cap in SIGMA_CAPS.items():
        v = raw.get(key)
        if v is not None:
            v = _finite(v, f"entity {eid!r} {key}")
            # Two headings' bounds together must stay under half a turn, so a heading Range stays < 360 wide.
            if not 0.0 <= v < cap:
                raise SceneError(f"entity {eid!r} {key} must be in [0, {cap:g}), got {v!r}")
        sigmas.append(v)
    speed = raw.get("speed")
    if speed is not None:
        speed = _finite(speed, f"entity {eid!r} speed")
        if not 0.0 <= speed <= MAX_SPEED:
            raise SceneError(f"entity {eid!r} speed must be in [0, {MAX_SPEED:g}] m/s, got {raw['speed']!r}")
    facts = _lane_facts(raw, eid)
    return Entity(
        id=eid,
        type=etype,
        x=_coordinate(raw["x"], f"entity {eid!r} x"),
        y=_coordinate(raw["y"], f"entity {eid!r} y"),
        heading=_finite(raw["heading"], f"entity {eid!r} heading"),
        length=dims[0],
        width=dims[1],
        pos_sigma=sigmas[0],
        heading_sigma=sigmas[1],
        speed=speed,
        speed_sigma=sigmas[2],
        **facts,
    )


def _lane_facts(raw: Mapping, eid: str) -> dict[str, Any]:
    """An entity's lane facts as scene JSON gives them (each optional): lanes a list of feature ids (strings),
    lane one of them, the three flags true / false."""
    out: dict[str, Any] = {}
    lanes = raw.get("lanes")
    if lanes is not None:
        if not isinstance(lanes, list) or not all(isinstance(x, str) and x for x in lanes):
            raise SceneError(f"entity {eid!r} lanes must be a list of lane ids (strings)")
        out["lanes"] = tuple(sorted(set(lanes)))
    lane = raw.get("lane")
    if lane is not None:
        if not isinstance(lane, str) or lane not in out.get("lanes", ()):
            raise SceneError(f"entity {eid!r} lane must be one of its lanes, got {lane!r}")
        out["lane"] = lane
    for key in LANE_FACT_KEYS[2:]:
        v = raw.get(key)
        if v is not None:
            if not isinstance(v, bool):
                raise SceneError(f"entity {eid!r} {key} must be true or false, got {v!r}")
            out[key] = v
    return out


def as_scene(value: Scene | Mapping[str, Any]) -> Scene:
    """The scene the Python API was given: a Scene as it is, a decoded scene JSON document through
    scene_from_dict. (JSON text or a path is a mistake of type: use scene_from_json.)"""
    if isinstance(value, Scene):
        return value
    if isinstance(value, Mapping):
        return scene_from_dict(value)
    hint = " (JSON text: scene_from_json(text))" if isinstance(value, (str, bytes)) else ""
    raise TypeError(f"a scene is a Scene or a dict (decoded scene JSON), not {type(value).__name__}{hint}")


def scene_from_dict(raw: Any, max_entities: int = DEFAULT_MAX_ENTITIES) -> Scene:
    """Validate a decoded scene JSON document. Headings are normalised into [0, 360)."""
    if not isinstance(raw, Mapping):
        raise SceneError("a scene must be a JSON object with 'frame_id' and 'entities'")
    if "entities" not in raw:
        raise _lacks(raw, ["entities"], SCENE_KEYS, "scene")
    _unknown_keys(raw, SCENE_KEYS, "scene")
    frame_id = check_frame_id(raw.get("frame_id", "scene"))
    ents = raw.get("entities")
    if not isinstance(ents, list):
        raise SceneError("'entities' must be a list")
    if len(ents) > max_entities:
        raise SceneError(f"scene has {len(ents)} entities, more than the cap of {max_entities}")
    road = _part(raw.get("road"), _read_road)
    world = _part(raw.get("world"), _read_world)
    return make_scene(frame_id, (entity_from_mapping(e, i) for i, e in enumerate(ents)), road, world)


def _read_road(value: Any) -> RoadMap:
    from synth.road.roadmap import road_from_dict  # numpy: loaded only for a scene with a road

    return road_from_dict(value)


def _read_world(value: Any) -> WorldPose:
    from synth.world import world_from_dict

    return world_from_dict(value)


def _part(value: Any, read: Callable[[Any], Any]) -> Any:
    """An optional part of scene JSON (road, world) read by its own module; its one-line error (an InputError:
    MapError, WorldError) becomes the scene's."""
    if value is None:
        return None
    try:
        return read(value)
    except InputError as exc:
        raise SceneError(str(exc)) from None


def make_scene(frame_id: str, entities: Iterable[Entity], road: RoadMap | None = None,
               world: WorldPose | None = None) -> Scene:
    """A scene from entities, with headings normalised so equal directions print equal."""
    from synth.geometry import normalize

    return Scene(
        frame_id=frame_id,
        entities=tuple(replace(e, heading=normalize(e.heading)) for e in entities),
        road=road,
        world=world,
    )


def scene_from_json(text: str | bytes, max_entities: int = DEFAULT_MAX_ENTITIES) -> Scene:
    """Parse and validate scene JSON text; every failure is a one-line SceneError."""
    if isinstance(text, bytes):
        try:
            text = text.decode("utf-8")
        except UnicodeDecodeError as exc:
            raise SceneError(f"scene is not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    if not text.strip():
        raise SceneError("scene is empty")
    try:
        # NaN and Infinity are not JSON; refuse them at the parser rather than as numbers later.
        raw = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as exc:
        raise SceneError(f"scene is not valid JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise SceneError("scene JSON is nested too deeply") from None
    return scene_from_dict(raw, max_entities=max_entities)


def _refuse_constant(name: str) -> float:
    raise SceneError(f"scene contains {name}, which is not a finite number")
