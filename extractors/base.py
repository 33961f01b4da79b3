"""The one small interface every source implements (Source), its options (ExtractOptions), and what sources share.

A source is one module (nuscenes, scenarionet, argoverse2, mcap, rosbag; registry.py names them), in the manner
of trajdata's dataset adapters: a Source subclass and `SOURCE`, its instance, that owns everything about its
dataset: its name, the Taxonomy of its raw categories, its options (an ExtractOptions subclass that adds its
own `r2s extract` options), how it cuts an input into pieces for `--jobs` (`units`), how it recognises its input
(`look_at_file`, `look_at_entry`: extractors.sniff asks every source), and `extract(input_path, options,
tally=None, maps=None) -> Iterator[list[row dict]]`, one list of frames rows per frame, built with
`FrameBuilder.frame(...)` so that the ego-frame transform, category selection, radius, entity cap and lane facts
are the same for all sources. A source whose recordings carry a map hands each scenario's RoadMap to `maps` (a
callable; frames.maps writes them) before that scenario's frames, which name it. What a
run leaves out (a duplicate scenario, an object of a type no map knows) is counted in the ExtractTally, whose
summary is the last line of `r2s extract`. Problems with the input raise ExtractError (a FramesError: one line,
exit 2). docs/layout.md has the recipe for a new source.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import math
import os
import sys
from abc import ABC, abstractmethod
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from extractors.categories import ALL, UNKNOWN_CLASS, CategorySelection, Taxonomy
from frames.naming import SceneNames
from frames.rows import FramesError, frame_rows, known_speed
from frames.scene import box
from storage.regular_files import check_regular
from synth.geometry import normalize
from synth.pose import SE2
from synth.road.lane_facts import RoadIndex
from synth.road.roadmap import MapError, MapRepairs, RoadMap
from synth.scene import DEFAULT_MAX_ENTITIES

# Where a source hands the map of each scenario it reads (before that scenario's frames).
MapSink = Callable[[RoadMap], None]


@dataclass(frozen=True)
class Look:
    """What an input looks like to a source (its look_at_file, look_at_entry; extractors.sniff asks them all). Here,
    beside Source, so that the sources, sniff and registry import it without a circle through sniff."""

    source: str  # the r2s extract SOURCE that reads it
    what: str  # what it looks like, for the user
    path: str  # the INPUT to give that source


class ExtractError(FramesError):
    """The input of an extractor is missing, corrupt, or not what it claims. One line, fit for a user."""


@dataclass(frozen=True)
class ExtractOptions:
    """The options every source takes. A source with options of its own subclasses this (more fields, all with
    defaults) and adds them to `r2s extract` in add_options; sources that share options share the subclass."""

    radius: float = 50.0
    categories: CategorySelection = ALL
    every: int = 1
    max_entities: int = DEFAULT_MAX_ENTITIES
    strict_maps: bool = False  # refuse a map that breaks a rule instead of repairing or dropping (docs/formats.md)

    def __post_init__(self) -> None:
        if not (self.radius > 0):
            raise ValueError("--radius must be positive")
        if self.every < 1:
            raise ValueError("--every must be at least 1")
        if self.max_entities < 1:
            raise ValueError("--max-entities must be at least 1")

    @classmethod
    def add_options(cls, group: argparse._ArgumentGroup) -> None:
        """Add the fields of this class beyond ExtractOptions' as options of `r2s extract` (in their own group)."""

    @classmethod
    def options_from(cls, args: argparse.Namespace, **common: Any) -> ExtractOptions:
        """The options of a parsed `r2s extract` command line; `common` holds ExtractOptions' own fields."""
        return cls(**common)


def comma_list(text: str) -> tuple[str, ...]:
    """The items of a comma-separated option value (--scenes, --topics)."""
    return tuple(t.strip() for t in text.split(",") if t.strip())


class Source(ABC):
    """One dataset, everything about it. Subclasses set the class attributes and implement extract; the rest
    has defaults that fit a source whose input is one thing that cannot be split and that no file betrays."""

    name: ClassVar[str]  # the SOURCE of `r2s extract SOURCE INPUT`, its key in registry.SOURCES
    description: ClassVar[str]  # one line: what it reads
    input_help: ClassVar[str]  # what INPUT is, a few words for `r2s extract --help`
    taxonomy: ClassVar[Taxonomy]  # its raw categories -> Scenic classes
    options: ClassVar[type[ExtractOptions]] = ExtractOptions

    @abstractmethod
    def extract(self, input_path: str, options: ExtractOptions,
                tally: ExtractTally | None = None, maps: MapSink | None = None) -> Iterator[list[dict[str, Any]]]:
        """The frames of INPUT, one list of rows (FrameBuilder.frame) per frame, streamed; with `maps`, the map of
        each scenario / log goes to it before that scenario's frames, whose rows then carry their lane facts (a
        source whose recordings carry no map never calls it)."""

    def units(self, input_path: str) -> list[str]:
        """The independent pieces of INPUT, for `r2s extract --jobs`, in the order extract reads them. Each piece
        is a valid input on its own, so a worker extracts it with extract, exactly as the whole input would be."""
        path = require_path(input_path, f"{self.name} input")
        return [str(p) for p in self.unit_paths(path)]

    def unit_paths(self, path: Path) -> list[Path]:
        """The pieces of an existing INPUT (one file, log or bag each); by default the input is one piece."""
        return [path]

    def look_at_file(self, path: Path, head: bytes) -> Look | None:
        """What INPUT looks like when it is this file (head: its first bytes), if it is this source's."""
        return None

    def look_at_entry(self, top: str, path: Path, is_dir: bool, depth: int) -> Look | None:
        """What the INPUT folder `top` looks like, from one entry `depth` levels below it, if this source's."""
        return None


@dataclass(frozen=True)
class RecordedObject:
    """One recorded object in the ego frame (+x right, +y forward, heading degrees CCW from +y).

    `fallback` is a coarser type to classify by when the taxonomy does not know `category` (ScenarioNet tracks
    carry a dataset's own type in metadata.type and MetaDrive's VEHICLE / PEDESTRIAN / ... in type).
    `speed` is the magnitude of the ground velocity in m/s, as the source gives or its positions imply
    (extractors.speed); None where it is not known. `world` is the centre and yaw (x, y, radians CCW from +x) in
    the frame of the scenario's map, where the source knows them: the lane facts are decided there, on the
    source's own values."""

    track_id: str
    category: str
    x: float
    y: float
    heading: float
    length: float | None = None
    width: float | None = None
    fallback: str | None = None
    speed: float | None = None
    world: tuple[float, float, float] | None = None


def _stderr_line(message: str) -> None:
    sys.stderr.write(message + "\n")


# Distinct category names a tally keeps apart; more are summed under "..." (a corrupt file must not grow it).
MAX_NAMES = 20


@dataclass
class ExtractTally:
    """What an extraction read and what it left out, for the summary line at its end. Mutable on purpose: the
    source modules and FrameBuilder count into it while the frames stream; `warn` prints a line at once."""

    warn: Callable[[str], None] = field(default=_stderr_line, repr=False, compare=False)
    scenarios: int = 0  # scenarios (scenes, logs, files) that gave frames
    skipped: Counter = field(default_factory=Counter)  # why -> scenarios left out
    by_fallback: Counter = field(default_factory=Counter)  # "raw as FALLBACK" -> objects
    unknown_kept: Counter = field(default_factory=Counter)  # raw -> objects typed UNKNOWN_CLASS
    unknown_left_out: Counter = field(default_factory=Counter)  # raw -> objects left out
    categories_left_out: Counter = field(default_factory=Counter)  # Scenic class -> boxes --categories left out
    map_repairs: Counter = field(default_factory=Counter)  # repair kind (synth.road.roadmap.MapRepairs) -> how many
    maps_unusable: int = 0  # scenarios whose map could not be used: their frames have no road columns
    _scene: str | None = field(default=None, repr=False, compare=False)

    def frame_of(self, scene: str) -> None:
        # the frames of a scenario come together, so a change of scene is a new scenario
        if scene != self._scene:
            self.scenarios += 1
            self._scene = scene

    def skip(self, why: str, warning: str | None = None) -> None:
        self.skipped[why] += 1
        if warning:
            self.warn(warning)

    def map_unusable(self, warning: str) -> None:
        self.maps_unusable += 1
        self.warn(warning)

    @staticmethod
    def count(counter: Counter, name: str) -> None:
        counter[name if name in counter or len(counter) < MAX_NAMES else "..."] += 1

    @property
    def scenarios_read(self) -> int:
        return self.scenarios + sum(self.skipped.values())

    def notes(self) -> str:
        """What was skipped and why, what --categories left out (boxes by Scenic class), and how objects of unknown
        type were typed ("" when nothing was)."""
        parts = []
        if self.skipped:
            parts.append(f"skipped {sum(self.skipped.values())} scenarios ({_listing(self.skipped)})")
        if self.categories_left_out:
            # Said first among the objects: a query for a type this dropped finds nothing, so the user must see it.
            parts.append(f"--categories left out {sum(self.categories_left_out.values())} boxes within --radius "
                         f"({_listing(self.categories_left_out)})")
        unknown = [(self.by_fallback, "typed by their MetaDrive type"), (self.unknown_kept, f"typed {UNKNOWN_CLASS}"),
                   (self.unknown_left_out, "left out")]
        if any(c for c, _ in unknown):
            parts.append("objects of unknown type: " + ", ".join(
                f"{sum(c.values())} {what} ({_listing(c)})" for c, what in unknown if c))
        if self.map_repairs:
            parts.append("map repairs: " + ", ".join(f"{n:,} {kind}" for kind, n in sorted(
                self.map_repairs.items(), key=lambda kv: (-kv[1], kv[0]))))
        if self.maps_unusable:
            parts.append(f"{self.maps_unusable} maps unusable (their frames have no road columns)")
        return "; ".join(parts)


def _listing(counter: Counter) -> str:
    return ", ".join(f"{name} x{n}" for name, n in sorted(counter.items(), key=lambda kv: (-kv[1], kv[0])))


def global_to_ego(
    ego_x: float, ego_y: float, ego_yaw: float, xs: Any, ys: Any, yaws: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Global positions and yaws (radians, CCW from +x, as nuScenes / ScenarioNet / AV2 city) into the ego frame.

    The ego pose's ego frame (synth.pose.SE2.ego: its forward axis becomes +y); headings are yaw - ego_yaw in
    degrees, in [0, 360).
    """
    ego = SE2.ego(ego_x, ego_y, ego_yaw)
    x, y = ego.local(np.asarray(xs, dtype=float), np.asarray(ys, dtype=float))
    return x, y, np.degrees(ego.heading_in(np.asarray(yaws, dtype=float))) % 360.0


def vehicle_to_ego(xs: Any, ys: Any, yaws: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes in a vehicle frame with x forward, y left (ROS base_link, Argoverse 2 egovehicle) into ours."""
    return (-np.asarray(ys, dtype=float), np.asarray(xs, dtype=float),
            np.degrees(np.asarray(yaws, dtype=float)) % 360.0)


def quaternion_yaw(w: Any, x: Any, y: Any, z: Any) -> np.ndarray:
    """Rotation about +z (radians) of unit quaternions, as nuscenes-devkit's quaternion_yaw for level boxes."""
    w, x, y, z = (np.asarray(v, dtype=float) for v in (w, x, y, z))
    return np.arctan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


@dataclass(frozen=True)
class FrameBuilder:
    """Turns one frame's boxes into frames rows: category selection, radius, cap, and ids stable across a scene
    (frames.naming: frames are built in order, one scene after another, so the builder keeps the scene's
    numbering)."""

    source: str
    taxonomy: Taxonomy
    options: ExtractOptions
    tally: ExtractTally | None = field(default=None, compare=False)
    names: SceneNames = field(default_factory=SceneNames, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.tally is None:
            object.__setattr__(self, "tally", ExtractTally())

    def classify(self, b: RecordedObject) -> str | None:
        """The Scenic class of a box under --categories, or None to leave it out; a category no map knows is
        classified by the box's fallback if that is known, else as UNKNOWN_CLASS, and counted either way."""
        select = self.options.categories.select
        for by_fallback, raw in enumerate((b.category, b.fallback)):
            known = None if raw is None else self.taxonomy.scenic_class(raw)
            if known is None:
                continue
            if by_fallback:
                ExtractTally.count(self.tally.by_fallback, f"{b.category} as {b.fallback}")
            cls = select(self.taxonomy, raw)
            if cls is None:
                ExtractTally.count(self.tally.categories_left_out, known)
            return cls
        cls = select(self.taxonomy, b.category)
        ExtractTally.count(self.tally.unknown_kept if cls is not None else self.tally.unknown_left_out, b.category)
        return cls

    def frame(
        self,
        scene: str,
        frame_index: int,
        timestamp_us: int | None,
        ego: RecordedObject,
        others: Iterable[RecordedObject],
        frame_id: str | None = None,
        road: RoadIndex | None = None,
    ) -> list[dict[str, Any]]:
        """The rows of one frame; with the `road` of the scenario's map, every row names the map and carries the
        lane facts of its entity (null for an entity whose world position the source does not give)."""
        opts = self.options
        fid = frame_id or f"{scene}/{frame_index}"
        kept = []
        for b in others:
            if not (math.isfinite(b.x) and math.isfinite(b.y) and math.isfinite(b.heading)):
                raise ExtractError(f"frame {fid}: object {b.track_id} has a non-finite position or heading")
            if math.hypot(b.x, b.y) > opts.radius:
                continue
            cls = self.classify(b)
            if cls is not None:
                kept.append((b, _as_entity(b, cls)))
        if len(kept) + 1 > opts.max_entities:
            raise ExtractError(
                f"frame {fid} has {len(kept) + 1} entities, more than the cap of {opts.max_entities} "
                "(raise --max-entities, or lower --radius)"
            )
        self.tally.frame_of(scene)
        ego_entity = _as_entity(ego, "Car")
        world_places([(ego, ego_entity)] + kept)
        if road is not None:
            road_facts(road, [(ego, ego_entity)] + kept)
        return frame_rows(self.source, scene, frame_index, timestamp_us, ego_entity, [e for _, e in kept], fid,
                          self.names)


def world_places(entities: list[tuple[RecordedObject, dict[str, Any]]]) -> None:
    """Keep each entity's place in its source's world frame (map_x, map_y, map_heading) where the source gives
    it, map or no map: the ego's is how a frame goes back to the world (r2s scene's `world`, r2s export)."""
    for b, e in entities:
        if b.world is not None:
            e.update(map_x=float(b.world[0]), map_y=float(b.world[1]), map_heading=normalize(math.degrees(b.world[2])))


def road_facts(road: RoadIndex, entities: list[tuple[RecordedObject, dict[str, Any]]]) -> None:
    """Name the map in every entity and add the lane facts of those the source places in the map's frame."""
    map_id = road.road.map_id
    worlds = [b.world for b, _ in entities]
    facts = road.known(worlds)  # prefetched (prefetch_facts), by the world place itself
    todo = [j for j, f in enumerate(facts) if f is None and worlds[j] is not None]
    if todo:
        for j, f in zip(todo, road.facts(*_facts_args([worlds[j] for j in todo]))):
            facts[j] = f
    for (_, e), f in zip(entities, facts):
        e["map_id"] = map_id
        if f is not None:
            e["lanes"], e["lane"] = list(f.lanes), f.lane
            e["in_intersection"], e["on_crosswalk"], e["off_road"] = f.in_intersection, f.on_crosswalk, f.off_road


def prefetch_facts(road: RoadIndex, xs: np.ndarray, ys: np.ndarray, yaws: np.ndarray) -> None:
    """Decide at once the lane facts of every world place (x, y, yaw: arrays) a scenario's frames will ask for
    (its entities' RecordedObject.world in all its frames, whose floats these are): road_facts then looks them up
    by the world place (RoadIndex.prefetch)."""
    with gc_paused():
        yaws = np.asarray(yaws, dtype=float)
        road.prefetch(xs, ys, headings_of(yaws), keys=zip(np.asarray(xs, dtype=float).tolist(),
                                                 np.asarray(ys, dtype=float).tolist(), yaws.tolist()))


def headings_of(yaws: np.ndarray) -> np.ndarray:
    """math.degrees(h) % 360.0 of each yaw (radians CCW from +x) for many at once, the heading RoadIndex takes:
    CPython's degrees multiplies by 180 / pi and its float % is fmod taking the divisor's sign, as numpy's product
    and remainder do. prefetch_facts and a frame's own lookup (_facts_args) both use it."""
    with np.errstate(all="ignore"):  # a yaw beyond a float's degrees: NaN, as math.degrees(h) % 360.0 gives
        return (np.asarray(yaws, dtype=float) * (180.0 / math.pi)) % 360.0


@contextlib.contextmanager
def gc_paused() -> Iterator[None]:
    """No cyclic garbage collection within: for building a map and its facts, which allocate ~10^5 long-lived
    objects without a cycle among them (points, features, facts). Meanwhile CPython's collector would sweep the
    whole heap again and again (the scenario just unpickled with it) and free nothing: on the nuScenes-mini
    scenarios, 3 more full collections, ~45 ms, a sixth of the map's cost (bench/results/maps.md). Only around
    code that does not yield, so the caller's code never runs with collection off; reference counting still frees
    everything as usual."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


class LongLived:
    """A scope whose long-lived objects are left out of cyclic garbage collection (gc.freeze) until it ends
    (gc.unfreeze): `keep()` freezes every object alive at that moment. For one scenario or log: what was read of
    it, its map, the map's index (~10^5 tuples, dicts and features, without a cycle among them), alive for all its
    frames. Otherwise each young one is swept by the next collection of generation 0, again of generation 1 and
    then of generation 2 while the frames are built, freeing nothing: on the 12 shared Waymo scenarios with their
    maps, about 0.2 of 1.7 CPU s. Reference counting still frees them as usual, and whatever cycle they hold is
    collected after the scope ends, as any old one. A scope entered while objects are frozen already (a caller's
    own gc.freeze) does nothing, so that it never thaws what it did not freeze."""

    def __enter__(self) -> LongLived:
        self._mine = not gc.get_freeze_count()
        return self

    def keep(self) -> None:
        """Freeze what is alive now; call it where collection is paused (gc_paused) or nothing was built since the
        last collection, lest a sweep come first."""
        if self._mine:
            gc.freeze()

    def __exit__(self, *exc: object) -> None:
        if self._mine:
            gc.unfreeze()


def utf8_writable(text: str) -> bool:
    """Whether UTF-8 (Parquet's strings, a terminal) can write a string: a pickle or a JSON file may hold lone
    surrogates."""
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


def recorded_road(where: Path, read: Callable[[MapRepairs], RoadMap | None], strict: bool,
                  tally: ExtractTally | None) -> RoadIndex | None:
    """The map a recording carries (a ScenarioNet scenario's, an Argoverse 2 log's), read by the source's `read`
    and indexed for lane facts; None when it has none. docs/formats.md's rule, for every source: a map never costs
    the tracks. `read` drops a feature that breaks a rule into its MapRepairs, counted in the tally's `map
    repairs`; a MapError out of it means the map cannot be used at all: its frames are extracted without road
    columns, with one line naming `where`, counted as unusable. With `strict` (--strict-maps) both are a MapError
    naming `where`: one line, exit 2."""
    repairs = MapRepairs(strict)
    try:
        with gc_paused():
            road = read(repairs)
            index = RoadIndex(road) if road is not None else None
    except MapError as exc:
        if strict:
            raise MapError(f"{where}: {exc}") from None
        if tally is not None:
            tally.map_unusable(f"r2s extract: {where}: its map cannot be used ({exc}); its frames are extracted "
                               "without road columns (--strict-maps refuses it instead)")
        return None
    if tally is not None:
        tally.map_repairs.update(repairs.counts)
    return index


def _facts_args(worlds: list[tuple[float, float, float]]) -> tuple[list[float], list[float], list[float]]:
    """RoadIndex.facts's points and headings (degrees CCW from +x) of world places."""
    return [w[0] for w in worlds], [w[1] for w in worlds], headings_of(np.array([w[2] for w in worlds])).tolist()


def _as_entity(b: RecordedObject, cls: str) -> dict[str, Any]:
    return {"track_id": b.track_id, "type": cls, "category": b.category, "x": b.x, "y": b.y,
            "heading": b.heading, "length": box(b.length), "width": box(b.width), "speed": known_speed(b.speed)}


def require_path(path: str | os.PathLike, what: str) -> Path:
    """An input that exists and is a directory or a regular file (symbolic links followed): never a FIFO, a
    socket or a device (storage.regular_files)."""
    p = Path(path)
    if not p.exists():
        raise ExtractError(f"{what} {path} does not exist")
    if not p.is_dir():
        try:
            check_regular(p)
        except OSError as exc:
            raise ExtractError(f"{what} {path} {exc.strerror}") from None
    return p


def files_with_suffix(path: Path, suffixes: Sequence[str], what: str) -> list[Path]:
    """A file, or the files under a directory (recursively, sorted) whose names end in one of suffixes."""
    if path.is_file():
        return [path]
    # not only regular files: a FIFO or a device named like an input is refused by its reader, not skipped
    found = sorted(p for p in path.rglob("*") if not p.is_dir() and p.name.endswith(tuple(suffixes)))
    if not found:
        raise ExtractError(f"{path} holds no {what} ({' / '.join(suffixes)} files)")
    return found
