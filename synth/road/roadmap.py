"""The recorded road as data: a map is a set of map features (docs/formats.md, "Maps Parquet").

A map belongs to one scenario or log (its `map_id`), in that scenario's world frame (metres; the frame its
tracks are in). Each feature is one row: a lane, road line, crosswalk, intersection or drivable area, with its
polygon (lanes, crosswalks, intersections, drivable areas) and its line (a lane's centre line, a road line), and
for lanes the lane graph: left / right neighbour, successors, predecessors, whether it is an intersection lane,
and its direction of travel (the centre line runs from its first to its last point).

`RoadMap.of` validates a map once, so that everything downstream may trust it: finite coordinates, polygons of
at least three distinct vertices that do not cross themselves, lane-graph references that name lanes of the
map. A map that breaks a rule is a MapError: one line, exit 2; or, for a reader of recorded maps given a
`MapRepairs` (r2s extract without --strict-maps), the features that break one are dropped (links to lanes that are
not there: the links) and counted by kind.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Collection, Iterable, Sequence
from dataclasses import MISSING, dataclass, field, fields
from itertools import chain

import numpy as np

from synth.errors import InputError
from synth.pose import SE2

LANE, ROAD_LINE, CROSSWALK, INTERSECTION, DRIVABLE_AREA = "lane", "road_line", "crosswalk", "intersection", \
    "drivable_area"
KINDS = (LANE, ROAD_LINE, CROSSWALK, INTERSECTION, DRIVABLE_AREA)
# The kinds whose features are areas (a polygon is required) and the kinds that are lines.
AREA_KINDS = (LANE, CROSSWALK, INTERSECTION, DRIVABLE_AREA)
LINE_KINDS = (LANE, ROAD_LINE)

Points = tuple[tuple[float, float], ...]


class FloatPairs(tuple):
    """Points that are pairs of Python floats because the function that made them made them so (`points`, and the
    readers' conversions of float arrays): RoadMap.of need not look at the type of every coordinate again (their
    finiteness it still checks). A tuple in every other respect (equal to, and hashed as, the same plain tuple).
    Only such functions construct it, from pairs they have just made."""

    __slots__ = ()


class ArrayPoints(Sequence):
    """Points kept as the (N, 2) float64 array they were read or made as (`xy`, read-only): what a reader of float
    arrays (ScenarioNet's polylines) and the lane widening make. A map holds ~10^5 points; as Python pairs (one
    tuple and two floats a point) they were most of what a Waymo map cost beyond its widening, and extraction
    never looks at them one by one: `packed` concatenates the arrays (RoadMap.of, the widening, the lane index)
    and the maps' columns are read from them (frames.maps). As a sequence they ARE the plain tuple of (x, y)
    pairs of Python floats, made on first use and kept: equal to it (and to other points of the same values),
    hashed as it, iterated, indexed, sliced and added as it. Not a tuple subclass: a tuple's items are fixed when
    it is made, and C code (json, pyarrow) reads a subclass's items directly."""

    __slots__ = ("xy", "_pairs")

    def __init__(self, xy: np.ndarray) -> None:
        """The points of a float (N, 2) array, which they keep as a read-only float64 copy of their own (the
        caller's array may change; points may not)."""
        self._keep(np.array(xy, dtype=float))

    @classmethod
    def owning(cls, xy: np.ndarray) -> ArrayPoints:
        """The points of an (N, 2) float64 array nobody else writes to (the caller's promise): no copy."""
        out = cls.__new__(cls)
        out._keep(np.ascontiguousarray(xy, dtype=float))
        return out

    def _keep(self, xy: np.ndarray) -> None:
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise ValueError(f"points need an (N, 2) array, not one of shape {xy.shape}")
        xy.flags.writeable = False
        self.xy, self._pairs = xy, None

    @property
    def pairs(self) -> Points:
        """The plain tuple of (x, y) pairs, made once."""
        if self._pairs is None:
            self._pairs = tuple(zip(self.xy[:, 0].tolist(), self.xy[:, 1].tolist()))
        return self._pairs

    def __len__(self) -> int:
        return self.xy.shape[0]

    def __getitem__(self, i):
        if isinstance(i, slice):  # the points of the slice, still an array's (a slice of a ring is no ring)
            return ArrayPoints.owning(self.xy[i])
        if self._pairs is not None:
            return self._pairs[i]
        x, y = self.xy[i].tolist()  # IndexError as a tuple's
        return (x, y)

    def __iter__(self):
        return iter(self.pairs)

    def __reversed__(self):
        return reversed(self.pairs)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, ArrayPoints):
            other = other.pairs
        return self.pairs == other if isinstance(other, tuple) else NotImplemented

    def __hash__(self) -> int:
        return hash(self.pairs)

    def __add__(self, other: object):
        return self.pairs + tuple(other) if isinstance(other, (tuple, ArrayPoints)) else NotImplemented

    def __radd__(self, other: object):
        return tuple(other) + self.pairs if isinstance(other, (tuple, ArrayPoints)) else NotImplemented

    def __repr__(self) -> str:
        return repr(self.pairs)

    def __reduce__(self):
        return type(self).owning, (self.xy,)

    def __array__(self, dtype=None, copy=None):
        # numpy (and shapely through it) reads the array, not the pairs one by one; a copy of its own, writable,
        # as np.asarray of the tuple gives (of no points: shape (0,), as of the empty tuple)
        return np.array(self.xy if len(self.xy) else (), dtype=dtype)


class ShellRing(ArrayPoints):
    """The outer ring of a lane's widened centre line (synth.road.lane_geometry.lane_polygons: a buffer, which GEOS
    returns valid, or an offset ring GEOS found simple), without its closing repeat: simple by construction, so
    check_simple need not ask GEOS again. Only that function constructs it."""


class MapError(InputError, ValueError):
    """A map that is not what the map format says (NaN, a self-crossing polygon, a dangling lane id). One line."""


class MapRepairs:
    """What readers of recorded maps repaired or dropped, counted by kind (the `map repairs` of `r2s extract`'s
    summary line; docs/formats.md, "Maps Parquet", names each rule). Mutable on purpose: a tally, like the
    extraction's. `repaired` counts a rule that reads what a producer writes (a zero width, a one-point line);
    `broken` a feature that breaks a rule of every map, which `strict` (--strict-maps) refuses instead: MapError,
    one line, exit 2."""

    def __init__(self, strict: bool = False) -> None:
        self.strict = strict
        self.counts: Counter = Counter()

    def repaired(self, kind: str, n: int = 1) -> None:
        if n:
            self.counts[kind] += n

    def broken(self, kind: str, message: str) -> None:
        if self.strict:
            raise MapError(message)
        self.counts[kind] += 1


# The kinds of repair RoadMap.of makes for a reader that gives it a MapRepairs.
DROPPED_BROKEN = "features breaking a map rule dropped"
DROPPED_TWICE = "features whose id occurs twice dropped"
DROPPED_LINKS = "lane links to no lane dropped"


@dataclass(frozen=True)
class MapFeature:
    """One map feature in its map's world frame.

    polygon: the outer ring, without the closing repeat of its first vertex (empty for road lines).
    line: a lane's centre line in its direction of travel, or a road line's points (empty for the other kinds).
    source_type: the source's own type (LANE_SURFACE_STREET, ROAD_LINE_SOLID_SINGLE_WHITE, VEHICLE, ...).
    polygon_rule: "source" (given by the source) or "centre line" (built from the centre line and its width by
    synth.road.lane_geometry.lane_polygon); neighbour_rule: "source" or "geometric" (synth.road.lane_geometry.neighbours).
    """

    map_id: str
    feature_id: str
    kind: str
    polygon: Points = ()
    line: Points = ()
    source_type: str = ""
    left: str | None = None
    right: str | None = None
    successors: tuple[str, ...] = ()
    predecessors: tuple[str, ...] = ()
    is_intersection: bool = False
    polygon_rule: str = "source"
    neighbour_rule: str = "source"

    @classmethod
    def fast(cls, map_id: str, feature_id: str, kind: str, **fields) -> MapFeature:
        """MapFeature(map_id, feature_id, kind, **fields), built without the frozen __init__'s one setattr per
        field (a reader builds thousands of features a map): the same fields and defaults, nothing else skipped
        (MapFeature has no __post_init__); unknown fields are a TypeError as for the constructor."""
        if not _FIELDS.issuperset(fields):
            raise TypeError(f"MapFeature has no field {sorted(fields.keys() - _FIELDS)[0]!r}")
        g = object.__new__(cls)
        # the instance dict in one piece (frozen: __setattr__ refuses, setting __dict__ itself does not)
        object.__setattr__(g, "__dict__", {"map_id": map_id, "feature_id": feature_id, "kind": kind, **_DEFAULTS,
                                           **fields})
        return g

    def with_(self, **changes) -> MapFeature:
        """dataclasses.replace for a feature, without its per-field machinery (a map has thousands of features to
        complete, and replace costs more than the work on each): a copy of every field but `changes`. MapFeature
        has no __post_init__ nor derived field, so nothing replace would run is skipped."""
        if not _FIELDS.issuperset(changes):
            raise TypeError(f"MapFeature has no field {sorted(changes.keys() - _FIELDS)[0]!r}")
        g = object.__new__(MapFeature)
        object.__setattr__(g, "__dict__", {**self.__dict__, **changes})  # frozen: as in `fast`
        return g

    @property
    def direction(self) -> float | None:
        """A lane's direction of travel: the heading (degrees CCW from +x, in the map's frame, in [0, 360)) of
        the chord from its centre line's first point to its last; None for other kinds or a degenerate line."""
        if self.kind != LANE or len(self.line) < 2:
            return None
        (x0, y0), (x1, y1) = self.line[0], self.line[-1]
        if x0 == x1 and y0 == y1:
            return None
        return math.degrees(math.atan2(y1 - y0, x1 - x0)) % 360.0


_FIELDS = frozenset(f.name for f in fields(MapFeature))
_DEFAULTS = {f.name: f.default for f in fields(MapFeature) if f.default is not MISSING}


@dataclass(frozen=True)
class RoadMap:
    """A validated map: its features in a stable order (by kind, then feature id)."""

    map_id: str
    features: tuple[MapFeature, ...]
    _by_id: dict = field(default_factory=dict, repr=False, compare=False)
    _packed: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def of(cls, map_id: str, features: Iterable[MapFeature], repairs: MapRepairs | None = None) -> RoadMap:
        """Validate and order the features of one map. A lane-graph reference to a lane the map does not hold is
        a MapError (a source whose maps are crops of a larger map drops links out of the crop before: see
        `links_within`). With `repairs` (a reader of recorded maps), a feature that breaks a rule is dropped and
        a link to no lane of the map removed, each counted there (or refused, if it is strict)."""
        feats = sorted(features, key=lambda f: (KINDS.index(f.kind) if f.kind in KINDS else len(KINDS),
                                                f.feature_id))
        seen: dict[str, MapFeature] = {}
        lines, polygons = [f.line for f in feats], [f.polygon for f in feats]
        coords = _plain_finite(lines, polygons)  # packed, when plain and finite
        distinct = _three_distinct(*coords[1]).tolist() if coords is not None else [None] * len(feats)
        keep = []
        for f, three in zip(feats, distinct):
            if f.map_id != map_id:
                raise MapError(f"map {map_id!r}: feature {f.feature_id!r} belongs to map {f.map_id!r}")
            try:
                if f.feature_id in seen:
                    raise MapError(f"map {map_id!r}: feature id {f.feature_id!r} occurs twice")
                check_feature(f, coordinates=coords is None, three_distinct=three)
            except MapError as exc:
                if repairs is None:
                    raise
                repairs.broken(DROPPED_TWICE if f.feature_id in seen else DROPPED_BROKEN, str(exc))
                keep.append(False)
                continue
            seen[f.feature_id] = f
            keep.append(True)
        if coords is None:  # every point kept was checked above: two finite numbers
            feats = [f for f, k in zip(feats, keep) if k]
            coords = packed([f.line for f in feats]), packed([f.polygon for f in feats])
        elif not all(keep):
            mask = np.array(keep, dtype=bool)
            feats = [f for f, k in zip(feats, keep) if k]
            coords = packed_subset(coords[0], mask), packed_subset(coords[1], mask)
        simple = simple_polygons(feats, coords[1])
        if not simple.all():
            for i in np.flatnonzero(~simple).tolist():
                f = feats[i]
                message = f"{_where(f)} has a self-intersecting polygon"
                if repairs is None:
                    raise MapError(message)
                repairs.broken(DROPPED_BROKEN, message)
                del seen[f.feature_id]
            feats = [f for f, ok in zip(feats, simple.tolist()) if ok]
            coords = packed_subset(coords[0], simple), packed_subset(coords[1], simple)
        lanes = {fid for fid, f in seen.items() if f.kind == LANE}
        out = []
        for f in feats:
            if f.kind == LANE:
                f = _resolve_links(map_id, f, lanes, repairs)
            out.append(f)
        road = cls(map_id, tuple(out))
        road._by_id.update((f.feature_id, f) for f in out)
        road._packed.update(line=coords[0], polygon=coords[1])
        return road

    def packed(self, what: str, *kinds: str) -> tuple[np.ndarray, np.ndarray]:
        """The lines or polygons (`what`) of the features of these kinds, in of_kind's order, as `packed` gives
        them: packed once when the map was validated, so that every index built on the map reuses them."""
        if what not in self._packed:
            self._packed[what] = packed([getattr(f, what) for f in self.features])
        if "kind" not in self._packed:  # each feature's kind as its index in KINDS, for the masks below
            self._packed["kind"] = np.fromiter((KINDS.index(f.kind) for f in self.features), dtype=np.int64,
                                               count=len(self.features))
        return packed_subset(self._packed[what], np.isin(self._packed["kind"], [KINDS.index(k) for k in kinds]))

    def with_features(self, changed: Iterable[MapFeature]) -> RoadMap:
        """This map with some of its features replaced by new versions of themselves (same id, kind, line and
        polygon objects: a source's completion of its lane graph, synth.road.lane_geometry.neighbours), their links
        validated as RoadMap.of validates them; order and packed coordinates kept."""
        new = {f.feature_id: f for f in changed}
        lanes = {f.feature_id for f in self.features if f.kind == LANE}
        out = []
        for f in self.features:
            g = new.pop(f.feature_id, None)
            if g is None:
                out.append(f)
                continue
            if g.kind != f.kind or g.line is not f.line or g.polygon is not f.polygon or g.map_id != f.map_id:
                raise ValueError(f"with_features: feature {f.feature_id!r} changed more than its links")
            out.append(_resolve_links(self.map_id, g, lanes) if g.kind == LANE else g)
        if new:
            raise ValueError(f"with_features: feature {next(iter(new))!r} is not in map {self.map_id!r}")
        road = RoadMap(self.map_id, tuple(out))
        road._by_id.update((f.feature_id, f) for f in out)
        road._packed.update(self._packed)
        return road

    def __getitem__(self, feature_id: str) -> MapFeature:
        return self._by_id[feature_id]

    def __contains__(self, feature_id: object) -> bool:
        return feature_id in self._by_id

    def of_kind(self, *kinds: str) -> tuple[MapFeature, ...]:
        return tuple(f for f in self.features if f.kind in kinds)

    @property
    def lanes(self) -> tuple[MapFeature, ...]:
        return self.of_kind(LANE)


def _resolve_links(map_id: str, f: MapFeature, lanes: set[str], repairs: MapRepairs | None = None) -> MapFeature:
    # The common case, decided with set operations: every link names another lane of the map, none twice.
    succ, pred = f.successors, f.predecessors
    refs = [*succ, *pred]
    if f.left is not None:
        refs.append(f.left)
    if f.right is not None:
        refs.append(f.right)
    if (f.feature_id not in refs and lanes.issuperset(refs) and len(set(succ)) == len(succ)
            and len(set(pred)) == len(pred)):
        return f
    def kept(ref: str | None, what: str) -> str | None:
        if ref is None:
            return None
        if ref == f.feature_id:
            message = f"map {map_id!r}: lane {f.feature_id!r} names itself as its {what}"
            if repairs is None:
                raise MapError(message)
            repairs.broken(DROPPED_LINKS, message)
            return None
        if ref in lanes:
            return ref
        message = f"map {map_id!r}: lane {f.feature_id!r} has {what} {ref!r}, which is not a lane of the map"
        if repairs is None:
            raise MapError(message)
        repairs.broken(DROPPED_LINKS, message)
        return None

    def kept_all(refs: Sequence[str], what: str) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r for r in (kept(x, what) for x in refs) if r is not None))

    links = dict(left=kept(f.left, "left neighbour"), right=kept(f.right, "right neighbour"),
                 successors=kept_all(f.successors, "successor"), predecessors=kept_all(f.predecessors, "predecessor"))
    return f if all(getattr(f, k) == v for k, v in links.items()) else f.with_(**links)


def _plain_finite(lines: Sequence[Points], polygons: Sequence[Points]):
    """`packed` lines and polygons, if every point of every sequence is a pair of finite Python floats or ints
    (what `points` and the readers make): then check_feature need not look at the coordinates one feature at a
    time. None for anything else, which check_feature then judges (and names) feature by feature."""
    # the others are float pairs, or an array's (their finiteness is checked on the packed arrays below)
    seqs = [pts for pts in chain(lines, polygons) if not isinstance(pts, (FloatPairs, ArrayPoints))]
    try:
        if not set(map(len, chain.from_iterable(seqs))) <= {2}:
            return None
    except TypeError:  # a point that is not a sequence
        return None
    if not set(map(type, chain.from_iterable(chain.from_iterable(seqs)))) <= {float, int}:
        return None
    try:
        out = packed(lines), packed(polygons)
    except OverflowError:  # an int beyond a float
        return None
    return out if np.isfinite(out[0][0]).all() and np.isfinite(out[1][0]).all() else None


def _three_distinct(xy: np.ndarray, counts: np.ndarray) -> np.ndarray:
    """For each of many packed rings, whether it has three distinct vertices (len(set(ring)) >= 3, in one pass):
    a vertex unlike the first, then one unlike both. Points compared as complex numbers (x + iy, a view of the
    same floats): equal exactly when both coordinates are, -0.0 equal to 0.0, as tuples compare."""
    if not len(counts):
        return np.zeros(0, dtype=bool)
    z = np.ascontiguousarray(xy, dtype=float).view(np.complex128).reshape(-1)
    ring = np.repeat(np.arange(len(counts)), counts)
    start = np.cumsum(counts) - counts
    has = counts > 0
    first = np.zeros(len(counts), dtype=np.complex128)
    first[has] = z[start[has]]
    unlike_first = z != first[ring]
    # each ring's first vertex unlike its first (its own first where there is none, matching nothing new)
    at = np.where(unlike_first, np.arange(len(z)), len(z))
    second_at = np.full(len(counts), len(z))
    second_at[has] = np.minimum.reduceat(at, start[has])
    second = first.copy()
    found = second_at < len(z)
    second[found] = z[second_at[found]]
    third = unlike_first & (z != second[ring])
    return np.bincount(ring, weights=third, minlength=len(counts)) > 0


def check_feature(f: MapFeature, coordinates: bool = True, three_distinct: bool | None = None) -> None:
    """The rules of one feature but simplicity (`check_simple` takes a map's polygons at once): a known kind,
    finite coordinates (unless `coordinates` is False: the caller checked them), a polygon of at least three
    distinct vertices where the kind is an area (`three_distinct`: the caller's answer, if it has one), a line of
    two points or more where the kind has one."""
    if f.kind not in KINDS:
        raise MapError(f"map {f.map_id!r}: feature {f.feature_id!r} has unknown kind {f.kind!r} "
                       f"(kinds: {', '.join(KINDS)})")
    for name, pts in (("line", f.line), ("polygon", f.polygon)):
        if not pts or not coordinates:
            continue
        try:
            a = np.asarray(pts, dtype=float)
        except (TypeError, ValueError):
            a = None
        if a is None or a.ndim != 2 or a.shape[1] != 2 or not np.isfinite(a).all():
            bad = next((p for p in pts if a is None or len(p) != 2 or not all(_finite(v) for v in p)), pts[0])
            raise MapError(f"{_where(f)} has a {name} point that is not two finite numbers ({bad!r})")
    if f.kind in AREA_KINDS and not (len(set(f.polygon)) >= 3 if three_distinct is None else three_distinct):
        raise MapError(f"{_where(f)} has no polygon of three distinct vertices")
    if f.kind in LINE_KINDS and len(f.line) < 2:
        raise MapError(f"{_where(f)} has no line of two points or more")


def _where(f: MapFeature) -> str:
    return f"map {f.map_id!r}: {f.kind.replace('_', ' ')} {f.feature_id!r}"


def _finite(v: object) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def check_simple(features: Sequence[MapFeature], polygons: tuple[np.ndarray, np.ndarray] | None = None) -> None:
    """Every polygon of these features does not cross or touch itself (consecutive repeated vertices allowed),
    as GEOS decides it (robust predicates), all in one call; the first that does is a MapError. `polygons`: the
    features' polygons packed, if the caller has them."""
    simple = simple_polygons(features, polygons)
    if not simple.all():
        f = features[int(np.flatnonzero(~simple)[0])]
        raise MapError(f"{_where(f)} has a self-intersecting polygon")


def simple_polygons(features: Sequence[MapFeature], polygons: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> np.ndarray:
    """For each feature, whether its polygon (if its kind is an area) does not cross or touch itself, as
    check_simple decides it."""
    import shapely

    # the polygons to ask GEOS about: of the area kinds, but those GEOS itself made a valid polygon's shell
    area = np.fromiter((f.kind in AREA_KINDS and type(f.polygon) is not ShellRing for f in features), dtype=bool,
                       count=len(features))
    simple = np.ones(len(features), dtype=bool)
    if not area.any():
        return simple
    xy, counts = polygons if polygons is not None else packed([f.polygon for f in features])
    coords, index = _clean_rings(xy[np.repeat(area, counts)], counts[area])
    simple[area] = shapely.is_simple(shapely.linearrings(coords, indices=index))
    return simple


def _clean_rings(xy: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """`_clean_ring` of many rings at once (packed, each of at least one vertex): their vertices concatenated and
    each one's ring index."""
    rings = range(len(counts))
    ring = np.repeat(np.arange(len(rings)), counts)
    start = np.cumsum(counts) - counts
    keep = np.ones(len(xy), dtype=bool)
    keep[1:] = (xy[1:] != xy[:-1]).any(axis=1)
    keep[start] = True
    # the closing repeat: a ring's last kept vertex equal to its first (its run ends the ring), more than one kept
    last = start + counts - 1
    kept = np.bincount(ring, weights=keep, minlength=len(rings))
    closing = (xy[last] == xy[start]).all(axis=1) & (kept > 1)
    at = np.maximum.reduceat(np.where(keep, np.arange(len(xy)), -1), start)
    keep[at[closing]] = False
    return xy[keep], ring[keep]


def _clean_ring(ring: Points) -> np.ndarray:
    a = np.asarray(ring, dtype=float)
    keep = np.ones(len(a), dtype=bool)
    keep[1:] = (a[1:] != a[:-1]).any(axis=1)
    a = a[keep]
    return a[:-1] if len(a) > 1 and (a[0] == a[-1]).all() else a


def ring_is_simple(ring: Points) -> bool:
    """Whether one closed ring does not cross or touch itself (`check_simple` for one polygon)."""
    import shapely

    return bool(shapely.is_simple(shapely.LinearRing(_clean_ring(ring))))


def points(xs: Iterable[float], ys: Iterable[float]) -> Points:
    """Coordinates as the frozen points of a feature (Python floats)."""
    xs, ys = np.asarray(xs, dtype=float).reshape(-1), np.asarray(ys, dtype=float).reshape(-1)
    if len(xs) != len(ys):
        raise ValueError(f"{len(xs)} x coordinates but {len(ys)} y coordinates")
    return FloatPairs(zip(xs.tolist(), ys.tolist()))


def packed(seqs: Sequence[Points]) -> tuple[np.ndarray, np.ndarray]:
    """Many point sequences as one (N, 2) float array and their lengths: one pass over all coordinates (numpy's
    conversion of each small tuple on its own costs more than the work done on it). Every point must be a pair.
    Points that keep their array (ArrayPoints) give it as it is, never their pairs: a map mixes them with plain
    tuples (nuScenes' lanes read from lists, its connectors widened into arrays)."""
    counts = np.fromiter(map(len, seqs), dtype=np.int64, count=len(seqs))
    parts: list[np.ndarray] = []
    plain: list[Points] = []  # a run of sequences without an array, converted in one pass

    def flush() -> None:
        if plain:
            total = sum(map(len, plain))
            flat = np.fromiter(chain.from_iterable(chain.from_iterable(plain)), dtype=float, count=2 * total)
            parts.append(flat.reshape(total, 2))
            plain.clear()

    for s in seqs:
        xy = getattr(s, "xy", None)
        if xy is None:
            if len(s):
                plain.append(s)
        else:
            flush()
            parts.append(xy)
    flush()
    if not parts:
        return np.empty((0, 2)), counts
    # a fresh array of its own, as ever (concatenate copies; never a kept array itself, which is read-only)
    return (parts[0] if len(parts) == 1 and parts[0].flags.writeable else np.concatenate(parts)), counts


def packed_subset(seqs: tuple[np.ndarray, np.ndarray], mine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The sequences of `packed`'s output where the boolean mask `mine` is true, packed."""
    xy, counts = seqs
    return xy[np.repeat(mine, counts)], counts[mine]


def open_ring(pts: Points) -> Points:
    """A ring without its closing repeat of the first vertex (sources write rings both ways)."""
    if not (len(pts) > 1 and pts[0] == pts[-1]):
        return pts
    return pts[:-1] if isinstance(pts, ArrayPoints) else type(pts)(pts[:-1])


def links_within(features: Sequence[MapFeature], *, neighbours: bool) -> list[MapFeature]:
    """The features with successors and predecessors (and, if `neighbours`, left / right neighbours) that name no
    lane among them dropped: for sources whose maps are crops of a larger map, where a link may lead out of the
    crop (docs/formats.md says which)."""
    lanes = {f.feature_id for f in features if f.kind == LANE}
    out = []
    for f in features:
        if f.kind == LANE and not (lanes.issuperset(f.successors) and lanes.issuperset(f.predecessors) and (
                not neighbours or ((f.left is None or f.left in lanes) and (f.right is None or f.right in lanes)))):
            links = dict(successors=tuple(s for s in f.successors if s in lanes),
                         predecessors=tuple(s for s in f.predecessors if s in lanes))
            if neighbours:
                links.update(left=f.left if f.left in lanes else None, right=f.right if f.right in lanes else None)
            if any(getattr(f, k) != v for k, v in links.items()):
                f = f.with_(**links)
        out.append(f)
    return out


# A feature within this many metres of an entity's centre stays in its scene's road whatever the radius: the
# lane facts were decided exactly at extraction, and the float distance must not drop a polygon that holds one.
TOUCHING = 1.0


def in_ego_frame(road: RoadMap, x: float, y: float, heading: float, radius: float,
                 entities: Sequence[tuple[float, float]] = (), named: Collection[str] = ()) -> RoadMap:
    """The features of a map that come within `radius` of a pose (x, y, heading degrees CCW from +x, in the map's
    frame), in that pose's ego frame (+x right, +y forward, as frames and scenes are): the road of one scene.
    Also kept, however far: the features named in `named` (the lanes the entities' facts name) and those within
    TOUCHING of a point of `entities` (their centres, in the map's frame), so that a radius smaller than the
    extraction's never leaves a lane fact or a lane clause without its polygon. Links to lanes left out are
    dropped. Near is decided by GEOS's distance, in float: which features a scene shows is a matter of display,
    not of the lane facts (those are the extraction's, exact)."""
    import shapely

    kept = []
    origin = shapely.Point(x, y)
    centres = shapely.MultiPoint(list(entities)) if len(entities) else None
    named = set(named)
    for f in road.features:
        geom = shapely.Polygon(f.polygon) if f.polygon else shapely.LineString(f.line)
        if (geom.distance(origin) <= radius or f.feature_id in named
                or (centres is not None and geom.distance(centres) <= TOUCHING)):
            kept.append(f)
    ego = SE2.ego(x, y, math.radians(heading))  # the pose's forward axis becomes +y (as global_to_ego's)

    def move(pts: Points) -> Points:
        if not pts:
            return ()
        a = np.asarray(pts, dtype=float)
        return points(*ego.local(a[:, 0], a[:, 1]))

    moved = [f.with_(polygon=move(f.polygon), line=move(f.line)) for f in kept]
    return RoadMap.of(road.map_id, links_within(moved, neighbours=True))


# Scene JSON's "road" (docs/formats.md): the map id and one object per feature.
ROAD_KEYS = ("map_id", "features")
FEATURE_KEYS = ("id", "kind", "source_type", "polygon", "line", "left", "right", "successors", "predecessors",
                "is_intersection")
MAX_FEATURES = 100_000
MAX_FEATURE_ID_LENGTH = 256  # a feature id names an OpenDRIVE road (r2s export): printable, as a frame id is


def road_to_dict(road: RoadMap, source_types: bool = True) -> dict:
    """A road as scene JSON's `road`. `source_types`: each feature's source type where it has one (what exports
    write back as the source's own types: road line types, bike lanes); the Scenic text's record leaves them out,
    since nothing it renders reads them."""
    out = []
    for f in road.features:
        d: dict = {"id": f.feature_id, "kind": f.kind}
        if source_types and f.source_type:
            d["source_type"] = f.source_type
        if f.polygon:
            d["polygon"] = [list(p) for p in f.polygon]
        if f.line:
            d["line"] = [list(p) for p in f.line]
        if f.kind == LANE:
            d.update(left=f.left, right=f.right, successors=list(f.successors), predecessors=list(f.predecessors),
                     is_intersection=f.is_intersection)
        out.append(d)
    return {"map_id": road.map_id, "features": out}


def road_from_dict(raw: object) -> RoadMap:
    """A scene's road as scene JSON gives it, validated as every map is (MapError: one line)."""
    if not isinstance(raw, dict) or not isinstance(raw.get("map_id"), str) or not isinstance(raw.get("features"), list):
        raise MapError("road must be an object with map_id (a string) and features (a list)")
    unknown = sorted(set(raw) - set(ROAD_KEYS))
    if unknown:
        raise MapError(f"road has unknown key {unknown[0]!r} (keys: {', '.join(ROAD_KEYS)})")
    map_id, feats = raw["map_id"], raw["features"]
    if len(feats) > MAX_FEATURES:
        raise MapError(f"road has {len(feats)} features, more than {MAX_FEATURES}")
    out = []
    for i, d in enumerate(feats):
        if not isinstance(d, dict) or not isinstance(d.get("id"), str) or not isinstance(d.get("kind"), str):
            raise MapError(f"road feature {i} must be an object with an id and a kind (strings)")
        if not 0 < len(d["id"]) <= MAX_FEATURE_ID_LENGTH or not d["id"].isprintable():
            raise MapError(f"road feature {i}: id {d['id'][:40]!r} is not a printable string of 1 to "
                           f"{MAX_FEATURE_ID_LENGTH} characters")
        unknown = sorted(set(d) - set(FEATURE_KEYS))
        if unknown:
            raise MapError(f"road feature {d['id']!r} has unknown key {unknown[0]!r} (keys: {', '.join(FEATURE_KEYS)})")
        where = f"road feature {d['id']!r}"
        refs = {k: d.get(k) for k in ("left", "right")}
        lists = {k: d.get(k) or [] for k in ("successors", "predecessors")}
        if any(v is not None and not isinstance(v, str) for v in refs.values()) or any(
                not isinstance(v, list) or not all(isinstance(r, str) for r in v) for v in lists.values()):
            raise MapError(f"{where}: left / right must be ids (strings) or null, successors / predecessors lists "
                           "of ids")
        inter = d.get("is_intersection", False)
        if not isinstance(inter, bool):
            raise MapError(f"{where}: is_intersection must be true or false")
        source_type = d.get("source_type", "")
        if not isinstance(source_type, str) or len(source_type) > MAX_FEATURE_ID_LENGTH or not source_type.isprintable():
            raise MapError(f"{where}: source_type must be a printable string of at most {MAX_FEATURE_ID_LENGTH} "
                           "characters")
        out.append(MapFeature(map_id, d["id"], d["kind"], source_type=source_type, polygon=_coords(d.get("polygon"), where),
                              line=_coords(d.get("line"), where), left=refs["left"], right=refs["right"],
                              successors=tuple(lists["successors"]), predecessors=tuple(lists["predecessors"]),
                              is_intersection=inter))
    return RoadMap.of(map_id, out)


def _coords(value: object, where: str) -> Points:
    if value is None:
        return ()
    if not isinstance(value, list) or not all(
            isinstance(p, list) and len(p) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                        for v in p) for p in value):
        raise MapError(f"{where}: coordinates must be a list of [x, y] number pairs")
    try:
        return tuple((float(p[0]), float(p[1])) for p in value)
    except OverflowError:  # a JSON integer of hundreds of digits: no float holds it (JSON has no bound)
        raise MapError(f"{where}: a coordinate is an integer beyond a float (finite numbers of metres)") from None
