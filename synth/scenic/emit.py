"""Executable Scenic 3 text for a DSL program, keeping the DSL's semantics.

Scenic's own `ahead of X by d` means an edge-to-edge gap on X's axis and `facing toward X` is exact, so the
paper's text read by Scenic would sample scenes the DSL does not describe. Instead a short prelude defines one
helper per DSL relation (centre distance within the Range, a +-delta1 sector, a +-delta2 heading tolerance), and
each entity is one statement naming its relation. Compile with scenic.scenarioFromString(text, mode2D=True).

What the text relies on, each point checked against scenic 3.1.1 (tests/synth/scenic/test_scenic.py samples real programs
and runs every sampled scene through synth.semantics.check):
- Headings: Scenic's are radians counter-clockwise from +y, ours degrees counter-clockwise from +y; `deg` converts.
  An object's heading is its yaw exactly (global parent orientation), so no quaternion round trip blurs it.
- Every helper name contains '__' (as does `<id>__at`), which no entity id may contain: an entity can never
  shadow a helper, a constant or another entity's position variable.
- `self` is not available in a specifier, so an entity whose heading depends on its own position (facing toward /
  away from) binds the position to `<id>__at` first.
- Bearings are taken as `angle from (0 @ 0) to (q - p)`: scenic 3.1.1 fails to sample `angle from p to q` when
  p is the position of a random object ("cannot iterate through a random value"); from a fixed origin it works.
- Ranges are printed as in the DSL, unshrunk, with one exception. Scenic samples Range(a, b) with
  random.uniform, so a bound itself can come out (tests/synth/scenic/test_scenic.py forces every Range to its bounds); float
  rounding then moves a distance or an angle by ~1e-13, far inside the checker's 1e-9 slack. The exception is
  a distance Range that starts at 0 (the synthesizer clamps centred distances there): at distance 0 the bearing
  is undefined and the DSL's direction relations do not hold, and just above 0 the bearing the checker
  recomputes from the rounded coordinates (p - ref, each rounded to ~1e-14 m) is off by ~1e-14 / d radians.
  Such a Range is sampled from dsl__MIN_DISTANCE = 0.05 m instead: bearings stay exact to 1e-10 degrees for
  coordinates up to a kilometre, and what is left out, centres within 5 cm of each other, is a sliver no
  recorded scene occupies. Every sample stays inside the semantics; only that sliver is never drawn.
- Each object carries `name` = its entity id and its class is its type, which is how `r2s sample` writes the
  sampled scene back as scene JSON (ids re-validated there). `param r2s_frame_id` names the recorded frame.
- The last line, `# r2s-source: {json}`, records what the text was rendered from (program, frame id, the
  recorded entities with their boxes, tolerances, header). Compiling Scenic runs it as Python, so `r2s sample` only compiles text that
  `rebuild_from_source` renders again byte for byte from that record: an edited or foreign file is refused
  (unless the user says --trusted), while the record itself can only ever yield what this emitter writes from
  validated ids, closed-set types and finite numbers.
- Collisions follow the recording (synth.variants.collision_rule): two boxes may overlap only if they overlap in the
  recorded scene. Scenic's own rule (no object meets any other) is switched off in the classes
  (allowCollisions: True), and the text ends with one requirement per entity, `require dsl__apart(e, 'a b')`:
  e's box meets none of the named earlier entities' boxes (`intersects`, which for planar boxes is shapely's
  footprint test in scenic 3.1.1, as in synth.variants.overlap). Only pairs that do not overlap in the recording and can
  meet at all (Draws.reach) are named; the partners are one string rather than a tuple of names because Scenic's
  parser takes ~1 ms per name token, which for the 9,560 pairs of a 141-entity frame would be 8 s of
  compiling (one string per entity: 0.2 s). The requirements stay off when the global parameter
  r2s_allow_collisions is overridden (`r2s sample --allow-collisions`, or `scenic -p r2s_allow_collisions True`).
- The road (synth.scenic.road), only for a scene that carries one: its lanes, crosswalks, intersections and
  drivable areas as PolygonalRegions keyed by feature id, and helpers that say where an object's centre is as
  the lane facts do; the record then holds the road too.
- Motion (synth.parts.motion), only in programs with MOTION clauses: every object gets `with speed ...` (scenic
  3.1.1, core/object_types.py: `speed` defaults to 0 and `velocity` to Vector(0, speed, 0) rotated by the
  orientation, so the velocity follows the heading), ego its recorded speed; speeds are never negative (the
  helpers clamp at 0, and a relative speed Range wholly below the reference's speed is required away), and
  `param r2s_motion = True` tells `r2s sample` to write each object's speed into the variants.
- The map (on_map), only where the user names one (`r2s synth --road F.xodr`): `param map = localPath(...)` and
  `model scenic.domains.driving.model` (Scenic's driving domain: any driving simulator's model replaces it with
  `scenic --model`), the classes the domain's (Car from its Car, the other vehicles from its Vehicle, Pedestrian
  from its Pedestrian, the rest plain), each with `regionContainedIn: None` (a recorded entity may stand off the
  map's lanes: the DSL's scenes, not the domain's, are the program's) and `parentOrientation: 0` (its default
  is the road's direction; a global parent keeps the heading exactly the yaw); the record then holds the path.
"""

from __future__ import annotations

import json
import textwrap
from dataclasses import dataclass
from typing import Any

from synth.config import SynthConfig
from synth.dsl import Program, Statement, parse_program
from synth.errors import InputError
from synth.parts import all_parts
from synth.parts.position import DIRECTIONS, MIN_DISTANCE
from synth.road.opendrive import MAP_SUFFIX
from synth.road.roadmap import road_to_dict
from synth.scene import ENTITY_TYPES, Entity, Scene, SceneError, scene_from_dict
from synth.scenic.road import road_scenic
from synth.syntax import fmt_number
from synth.variants.collision_rule import collision_rule

FRAME_PARAM = "r2s_frame_id"
COLLISIONS_PARAM = "r2s_allow_collisions"
MOTION_PARAM = "r2s_motion"
POSITION_SUFFIX = "__at"
OBJECTS = "dsl__objects"
SOURCE_PREFIX = "# r2s-source: "
DRIVING_MODEL = "scenic.domains.driving.model"  # Scenic's driving domain (simulator-agnostic: `scenic --model`)
# Each entity type's class in the driving domain (its base there); a type not named is a plain object.
DRIVING_CLASSES = {"Car": "Car", "Truck": "Vehicle", "Bus": "Vehicle", "Trailer": "Vehicle",
                   "ConstructionVehicle": "Vehicle", "EmergencyVehicle": "Vehicle", "Motorcycle": "Vehicle",
                   "Bicycle": "Vehicle", "Pedestrian": "Pedestrian"}
# How to run the file with Scenic's own command (headless: Scenic's viewer refuses a non-interactive matplotlib
# backend, while --gather-stats samples without drawing), and where Scenic's whole-scene rejection gives up.
RUN_NOTE = (
    "# Run: scenic FILE --2d (a window per sampled scene); headless (no display): scenic FILE --2d --gather-stats 10",
    "# samples 10 scenes and prints the tries each took. Scenic's rejection gives up on crowded frames (past ~25",
    "# entities): `r2s sample FILE` draws variants of any frame as scene JSON.",
)

PRELUDE = '''\
# The DSL's relations with its tolerances (Scenic's own `ahead of X by d` is an edge gap on X's axis and its
# `facing toward X` is exact, so they would describe other scenes).
dsl__DELTA1 = {delta1} deg  # half-width of the ahead / left / behind / right sectors
dsl__DELTA2 = {delta2} deg  # tolerance of facing toward / away from
dsl__MIN_DISTANCE = {min_distance}  # m: a distance Range from 0 is sampled from here (no bearing at distance 0)

def dsl__sector(ref, phi, distance):
    """Centre distance to ref in `distance`, bearing within DELTA1 of ref.heading + phi."""
    return ref.position + (0 @ distance).rotatedBy(ref.heading + phi + Range(-dsl__DELTA1, dsl__DELTA1))

def dsl__sector_ahead(ref, distance):
    return dsl__sector(ref, 0 deg, distance)

def dsl__sector_left(ref, distance):
    return dsl__sector(ref, 90 deg, distance)

def dsl__sector_behind(ref, distance):
    return dsl__sector(ref, 180 deg, distance)

def dsl__sector_right(ref, distance):
    return dsl__sector(ref, 270 deg, distance)

def dsl__relative_xy(ref, lateral, forward):
    """`on lateral @ forward relative to ref`: offsets in ref's frame (+lateral = ref's right)."""
    return ref.position + (lateral @ forward).rotatedBy(ref.heading)

def dsl__bearing(p, q):
    """Heading of the ray from p to q (0 = +y, counter-clockwise), taken from a fixed origin (see r2sgen)."""
    return angle from (0 @ 0) to (q - p)

def dsl__facing_toward(ref, p):
    return dsl__bearing(p, ref.position) + Range(-dsl__DELTA2, dsl__DELTA2)

def dsl__facing_away_from(ref, p):
    return dsl__bearing(ref.position, p) + Range(-dsl__DELTA2, dsl__DELTA2)

def dsl__apart(obj, others):
    """obj's box meets none of the boxes of the entities named in `others` (ids separated by spaces)."""
    by_name = {{o.name: o for o in dsl__objects}}
    return not any(obj intersects by_name[name] for name in others.split())
'''


def _props(e: Entity) -> str:
    """`with name` (the id: how samples are read back) and the recorded box where known (class default else)."""
    out = f", with name '{e.id}'"
    if e.length is not None or e.width is not None:
        length, width = e.dimensions()
        out += f", with length {fmt_number(length)}, with width {fmt_number(width)}"
    return out


def _classes(types: list[str], driving: bool = False) -> list[str]:
    """One class per type; in the driving domain (a map named) derived from the domain's (DRIVING_CLASSES)."""
    lines = []
    for t in types:
        length, width = ENTITY_TYPES[t]
        base = DRIVING_CLASSES.get(t) if driving else None
        lines += [f"class {t}({base}):" if base else f"class {t}:", f"    length: {fmt_number(length)}",
                  f"    width: {fmt_number(width)}", "    requireVisible: False",
                  "    allowCollisions: True  # the recording's rule instead: see the end"]
        if base:
            lines += ["    regionContainedIn: None  # where the recording has it, on the map's lanes or not",
                      "    parentOrientation: 0  # the domain's is the road's direction: the heading stays the yaw"]
        lines.append("")
    return lines


def _map_lines(road_map: str) -> list[str]:
    """The map a text names and the driving domain's model, which loads it."""
    return [f"param map = localPath({road_map!r})  # the recorded road as OpenDRIVE, in this scene's frame",
            f"model {DRIVING_MODEL}"]


def render_scenic(program: Program, scene: Scene, config: SynthConfig, header: str = "",
                  road_map: str | None = None) -> str:
    """The Scenic text of a program on its scene (module docstring); `road_map`: an OpenDRIVE file of the
    scene's road in its frame that the text names (Scenic's driving domain then loads it), relative to the text's
    file or absolute."""
    by_id = scene.by_id()
    assert set(DIRECTIONS) == {"ahead", "left", "behind", "right"}  # the four dsl__sector_* helpers
    types = sorted({scene.ego.type} | {s.type for s in program.statements})
    lines = [f"# {line}" for line in header.splitlines()] if header else []
    motion = has_motion(program)
    lines += [
        "# Generated by r2sgen. Compile in 2D mode: scenic.scenarioFromString(text, mode2D=True).",
        *RUN_NOTE,
        "# Each object's name is its entity id and its class its type (read back by `r2s sample`).",
        f"param {FRAME_PARAM} = {scene.frame_id!r}",
        f"param {COLLISIONS_PARAM} = False",
        *([f"param {MOTION_PARAM} = True"] if motion else []),
        *(_map_lines(road_map) if road_map is not None else []),
        "",
        *_classes(types, driving=road_map is not None),
        PRELUDE.format(delta1=fmt_number(config.delta1), delta2=fmt_number(config.delta2),
                       min_distance=fmt_number(MIN_DISTANCE)),
    ]
    ego = scene.ego
    speed = ""
    # Each part's own helpers, once, where some clause of the program uses them.
    carried = {name for st in program.statements for name, _ in st.parts}
    lines += [text for p in all_parts() if p.name in carried and (text := p.scenic_prelude(config))]
    if scene.road is not None:
        lines += road_scenic(scene.road)
    if motion:
        if ego.speed is None:
            raise SceneError("ego has no speed, which the program's motion clauses need")
        speed = f", with speed {ego.speed!r}"
    # ego is the recorded one, at full precision: every relation hangs off it.
    lines.append(f"ego = new {ego.type} at ({ego.x!r} @ {ego.y!r}), facing {ego.heading!r} deg{speed}{_props(ego)}")
    for st in program.statements:
        lines += _statement(st, by_id[st.id])
    lines += _collision_rule(program, scene, config)
    record = _source_record(program, scene, config, header)
    if road_map is not None:
        record["map"] = road_map
    lines.append(SOURCE_PREFIX + json.dumps(record, separators=(",", ":")))
    return "\n".join(lines) + "\n"


def _statement(st: Statement, e: Entity) -> list[str]:
    """One object per statement: each part's clause is one specifier (Part.keyword, Clause.scenic)."""
    (position, located), *others = st.clauses()
    where = located.scenic("")
    lines = []
    if any(c.needs_own_position() for _, c in others):
        # A clause depends on this entity's own position, which a specifier cannot name (no `self`).
        at = f"{st.id}{POSITION_SUFFIX}"
        lines.append(f"{at} = {where}")
        where = at
    specifiers = [f"{position.keyword} {where}"]
    specifiers += [f"{p.keyword} {c.scenic(where)}" for p, c in others]
    lines.append(f"{st.id} = new {st.type} {', '.join(specifiers)}{_props(e)}")
    lines += [line for _, c in others for line in c.scenic_requirements(st.id)]
    return lines


def has_motion(program: Program) -> bool:
    """Does any statement say how fast its entity moves? (Then every object of the text carries a speed.)"""
    return any(st.motion is not None for st in program.statements)


def _collision_rule(program: Program, scene: Scene, config: SynthConfig) -> list[str]:
    """The recording's collision rule (see the module docstring and synth.variants.collision_rule)."""
    rule = collision_rule(program, scene, config)
    partners: dict[int, list[str]] = {}
    for i, j in rule.apart:
        partners.setdefault(j, []).append(rule.ids[i])
    recorded = [f"{a}-{b}" for a, b in rule.named(rule.recorded)]
    lines = ["", "# Collisions as in the recording: two boxes may overlap only if they overlap there. Each entity",
             "# stays clear of every earlier one it does not overlap in the recording and can reach at all."]
    lines += textwrap.wrap(", ".join(recorded) or "none", width=116, break_on_hyphens=False, break_long_words=False,
                           initial_indent="# Overlapping in the recording (free to overlap): ", subsequent_indent="#   ")
    lines += textwrap.wrap(", ".join(rule.ids) + "]", width=116, initial_indent=f"{OBJECTS} = [", subsequent_indent="    ")
    if partners:
        lines.append(f"if not globalParameters.{COLLISIONS_PARAM}:")
    for j, names in sorted(partners.items()):
        # Adjacent string literals, one per line, join into one string (a space ends every piece but the last).
        pieces = _fill(names, 90)
        first = f"    require dsl__apart({rule.ids[j]}, "
        lines += [(first if k == 0 else " " * len(first)) + repr(piece + (" " if k < len(pieces) - 1 else ""))
                  + (")" if k == len(pieces) - 1 else "") for k, piece in enumerate(pieces)]
    return lines


def _fill(words: list[str], width: int) -> list[str]:
    """textwrap.wrap(" ".join(words), width, break_on_hyphens=False, break_long_words=False) for words without
    spaces (entity ids): the same greedy fill, without textwrap's per-call machinery (one call per entity)."""
    lines, line = [], ""
    for w in words:
        if line and len(line) + 1 + len(w) <= width:
            line += " " + w
        else:
            if line:
                lines.append(line)
            line = w
    if line:
        lines.append(line)
    return lines


def _entity_record(e: Entity, motion: bool) -> dict[str, Any]:
    rec = {"id": e.id, "type": e.type, "x": e.x, "y": e.y, "heading": e.heading, "length": e.length,
           "width": e.width}
    return {**rec, "speed": e.speed} if motion else rec


def _source_record(program: Program, scene: Scene, config: SynthConfig, header: str) -> dict[str, Any]:
    """Exactly what render_scenic reads: ego and the declared entities as recorded (where the boxes overlap is
    the collision rule), the two tolerances (and the motion constants, with motion), the header and the program."""
    by_id = scene.by_id()
    motion = has_motion(program)
    others = [_entity_record(by_id[st.id], motion) for st in program.statements]
    consts = {"v_stop": config.v_stop, "dv": config.dv} if motion else {}
    road = {}
    if scene.road is not None:
        road = {"road": road_to_dict(scene.road, source_types=False)}
    return {"frame_id": scene.frame_id, "header": header, "delta1": config.delta1, "delta2": config.delta2,
            **consts, "entities": [_entity_record(scene.ego, motion), *others], "program": str(program), **road}


class NotGenerated(InputError, ValueError):
    """Scenic text that this emitter did not write (or that was edited since). One line."""


@dataclass(frozen=True)
class Source:
    """What a text was rendered from, read back from its record (validated as any scene and program)."""

    program: Program
    scene: Scene
    config: SynthConfig
    header: str
    road_map: str | None = None  # the OpenDRIVE file the text names (param map), if any


def read_source(text: str) -> Source:
    """The record on the last line of `text`; NotGenerated if there is none or it is not valid.

    Only the record is read, nothing else of the text: compare rebuild_from_source(text) with the text before
    trusting that the text says what the record does.
    """
    lines = text.splitlines()
    if not lines or not lines[-1].startswith(SOURCE_PREFIX):
        raise NotGenerated("it has no r2s-source record on its last line")
    try:
        rec = json.loads(lines[-1][len(SOURCE_PREFIX):])
        if not isinstance(rec, dict):
            raise ValueError("the record is not an object")
        entities = [{k: v for k, v in e.items() if v is not None} for e in rec["entities"]]
        scene = scene_from_dict({"frame_id": rec["frame_id"], "entities": entities, "road": rec.get("road")})
        program = parse_program(rec["program"])
        config = SynthConfig(delta1=rec["delta1"], delta2=rec["delta2"],
                             **{k: rec[k] for k in ("v_stop", "dv") if k in rec})
        header = rec["header"]
        if not isinstance(header, str):
            raise ValueError("the header is not a string")
        road_map = rec.get("map")
        if road_map is not None and not (isinstance(road_map, str) and road_map.lower().endswith(MAP_SUFFIX)):
            raise ValueError(f"the map is not the path of a {MAP_SUFFIX} file")
        return Source(program, scene, config, header, road_map)
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:  # Scene/Dsl/ConfigError, JSON
        raise NotGenerated(f"its r2s-source record is not valid ({type(exc).__name__}: {str(exc)[:100]})") from None


def rebuild_from_source(text: str) -> str:
    """The text render_scenic writes from the record on the last line of `text`; NotGenerated if there is none.

    The caller compares it with `text`: equal means every line is this emitter's, whatever the record says,
    because the record passes the same validation as any scene and program (ids, types, finite numbers).
    """
    src = read_source(text)
    try:
        return render_scenic(src.program, src.scene, src.config, src.header, src.road_map)
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as exc:
        raise NotGenerated(f"its r2s-source record is not valid ({type(exc).__name__}: {str(exc)[:100]})") from None


def on_map(text: str, road_map: str) -> str:
    """The Scenic text this emitter wrote (its record), rendered again naming an OpenDRIVE map: `road_map`, the
    path of the scene's road in its frame, relative to where the text will be (localPath) or absolute."""
    src = read_source(text)
    return render_scenic(src.program, src.scene, src.config, src.header, road_map)
