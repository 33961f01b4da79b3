"""Maps Parquet (docs/formats.md, "Maps Parquet"): one row per map feature, the maps of a frames output.

`r2s extract --out DIR` writes the maps of its scenarios / logs to DIR/_maps/ (`--out F.parquet`: F.maps/ beside
it), one part per input piece, named like the frames part it goes with (part-000000.parquet, ...); each map is
written once, however many frames name it. Rows <-> RoadMap is one conversion each way (`map_rows`,
`read_maps`), so a map read back is the map written.
"""

from __future__ import annotations

import hashlib
import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from frames.frame_hash import RowBytes
from frames.scene import EgoPlace, FrameColumns, given
from frames.schema import MAPS_DIR, FramesError
from storage.atomic import parquet_writer
from storage.folders import check_replaceable, replace_with
from synth.road.roadmap import MapError, MapFeature, RoadMap, in_ego_frame, points

_COORDS = pa.list_(pa.float64())
MAPS_SCHEMA = pa.schema([
    ("map_id", pa.string()),
    ("feature_id", pa.string()),
    ("kind", pa.string()),
    ("source_type", pa.string()),
    ("polygon_x", _COORDS), ("polygon_y", _COORDS),
    ("line_x", _COORDS), ("line_y", _COORDS),
    ("left_neighbour", pa.string()),
    ("right_neighbour", pa.string()),
    ("successors", pa.list_(pa.string())),
    ("predecessors", pa.list_(pa.string())),
    ("is_intersection", pa.bool_()),
    ("direction", pa.float64()),
    ("polygon_rule", pa.string()),
    ("neighbour_rule", pa.string()),
])


def maps_dir(out: str | os.PathLike) -> Path:
    """Where the maps of a frames output go: DIR/_maps for a dataset directory, F.maps beside a file F.parquet."""
    p = Path(out)
    return p.with_suffix(".maps") if p.suffix == ".parquet" else p / MAPS_DIR


def _columns(pts) -> tuple[list[float], list[float]]:
    """A feature's points as its x and y columns: read from the array of points that keep one (ArrayPoints: the
    same floats, without making their pairs)."""
    xy = getattr(pts, "xy", None)
    if xy is not None:
        return xy[:, 0].tolist(), xy[:, 1].tolist()
    return [p[0] for p in pts], [p[1] for p in pts]


def map_rows(road: RoadMap) -> list[dict]:
    rows = []
    for f in road.features:
        (px, py), (lx, ly) = _columns(f.polygon), _columns(f.line)
        rows.append({
            "map_id": f.map_id, "feature_id": f.feature_id, "kind": f.kind, "source_type": f.source_type,
            "polygon_x": px, "polygon_y": py, "line_x": lx, "line_y": ly,
            "left_neighbour": f.left, "right_neighbour": f.right, "successors": list(f.successors),
            "predecessors": list(f.predecessors), "is_intersection": f.is_intersection, "direction": f.direction,
            "polygon_rule": f.polygon_rule, "neighbour_rule": f.neighbour_rule,
        })
    return rows


def feature_of(row: dict) -> MapFeature:
    return MapFeature(
        map_id=row["map_id"], feature_id=row["feature_id"], kind=row["kind"], source_type=row["source_type"] or "",
        polygon=points(row["polygon_x"] or (), row["polygon_y"] or ()), line=points(row["line_x"] or (),
                                                                                   row["line_y"] or ()),
        left=row["left_neighbour"], right=row["right_neighbour"], successors=tuple(row["successors"] or ()),
        predecessors=tuple(row["predecessors"] or ()), is_intersection=bool(row["is_intersection"]),
        polygon_rule=row["polygon_rule"] or "source", neighbour_rule=row["neighbour_rule"] or "source")


class MapsWriter:
    """The maps of one output part, a map at a time (each map is one row group)."""

    def __init__(self, writer: pq.ParquetWriter) -> None:
        self._writer = writer
        self.map_ids: list[str] = []

    def add(self, road: RoadMap) -> None:
        if road.map_id in self.map_ids:
            return
        self.map_ids.append(road.map_id)
        self._writer.write_table(pa.Table.from_pylist(map_rows(road), schema=MAPS_SCHEMA))


@contextmanager
def maps_writer(path: str | os.PathLike) -> Iterator[MapsWriter]:
    """Write maps to `path` atomically; no file is left when no map was added."""
    with parquet_writer(path, MAPS_SCHEMA) as pw:
        w = MapsWriter(pw)
        yield w
    if not w.map_ids:
        Path(path).unlink(missing_ok=True)


MAPS_PARTS = "maps parts"


def _maps_part(entry: os.DirEntry) -> bool:
    return entry.is_file(follow_symlinks=False) and entry.name.startswith("part-") and entry.name.endswith(".parquet")


def check_maps_target(target: Path) -> Path:
    """The place of a `target` maps folder (links followed) that may be replaced: absent, or holding maps parts
    only (storage.folders, the rule of every folder replaced whole); anything else is not ours: refused."""
    try:
        return check_replaceable(target, _maps_part, MAPS_PARTS)
    except OSError as exc:
        raise FramesError(f"{target} (the maps of the frames file) {exc.strerror}") from None


def replace_maps(staged: Path, target: Path) -> None:
    """Put a staged maps folder (absent or empty: no map) in place of the maps of a frames file, `target` (F.maps),
    removing maps an earlier extraction left there; a target that holds anything but maps parts is refused."""
    check_maps_target(target)
    try:
        replace_with(staged if staged.is_dir() and any(staged.iterdir()) else None, target, _maps_part, MAPS_PARTS)
    except OSError as exc:  # a file put there meanwhile (kept), a rename that failed (the old maps put back)
        raise FramesError(f"cannot replace {target}: {exc.strerror or exc}") from None


def read_maps(path: str | os.PathLike, map_ids: set[str] | None = None) -> Iterator[RoadMap]:
    """The maps of a maps directory or file (those named in map_ids, or all), validated again: a map file may
    come from anyone. With map_ids, row-group statistics skip the other maps' rows."""
    for f, table in _map_tables(path, map_ids):
        yield from _roads(f, table)


def _map_tables(path: str | os.PathLike, map_ids: set[str] | None = None) -> Iterator[tuple[Path, pa.Table]]:
    """(file, its rows of the maps named in map_ids, or all) of every maps file, in file order."""
    p = Path(path)
    files = sorted(f for f in p.rglob("*.parquet") if not f.name.startswith((".", "_"))) if p.is_dir() else [p]
    for f in files:
        try:
            pf = pq.ParquetFile(f)
            missing = [c for c in MAPS_SCHEMA.names if c not in pf.schema_arrow.names]
            if missing:
                raise FramesError(f"{f} is not a maps file: it lacks column(s) {', '.join(missing)}")
            table = pq.read_table(f, columns=MAPS_SCHEMA.names,
                                  filters=None if map_ids is None else [("map_id", "in", sorted(map_ids))])
        except (pa.ArrowException, OSError) as exc:
            raise FramesError(f"{f} is not a readable maps Parquet file ({str(exc)[:100]})") from None
        yield f, table


def _roads(f: Path, table: pa.Table) -> Iterator[RoadMap]:
    by_map: dict[str, list[MapFeature]] = {}
    try:
        for row in table.to_pylist():
            by_map.setdefault(row["map_id"], []).append(feature_of(row))
    except (TypeError, ValueError) as exc:
        if isinstance(exc, MapError):
            raise
        raise FramesError(f"{f}: a row is not a map feature ({str(exc)[:100]})") from None
    for map_id, features in by_map.items():
        yield RoadMap.of(map_id, features)


def map_digests(path: str | os.PathLike, map_ids: set[str] | None = None) -> dict[str, bytes]:
    """The content digest of every map of a maps directory or file (or of those named), by map id: 16 bytes of
    BLAKE2b over the map's rows as stored (frames.frame_hash.RowBytes), file after file, in their order. What
    `r2s run --lanes` keys a frame's road by (frames.frame_hash.Coverage): each map is read and hashed once per
    run, and a worker hashes the rows it builds a road from the same way (FrameRoads.digest). No directory: no
    maps."""
    return _digests(_map_tables(path, map_ids)) if Path(path).exists() else {}


def _digests(tables) -> dict[str, bytes]:
    digests: dict[str, object] = {}
    for f, table in tables:
        ids = pc.dictionary_encode(table.column("map_id").combine_chunks())
        codes = ids.indices.to_numpy(zero_copy_only=False)
        valid = np.flatnonzero(np.asarray(ids.is_valid()))
        order = valid[np.argsort(codes[valid], kind="stable")]  # each map's rows together, in file order
        cuts = codes[order]
        bounds = np.flatnonzero(np.r_[True, cuts[1:] != cuts[:-1], True]) if len(cuts) else np.zeros(0, np.int64)
        try:
            grouped = RowBytes(table.take(pa.array(order, pa.int64())))  # the file's bytes once, digested map by map
        except FramesError as exc:
            raise FramesError(f"{f}: {exc}") from None
        for a, b in zip(bounds[:-1], bounds[1:]):
            grouped.digest(digests.setdefault(ids.dictionary[int(cuts[a])].as_py(), hashlib.blake2b(digest_size=16)),
                           int(a), int(b))
    return {k: h.digest() for k, h in digests.items()}


# What a frame's road is, for every verb that builds scenes from frames (r2s scene; r2s run --lanes): the map
# features within this many metres of ego (r2s scene's default --radius, so that `r2s scene` writes the scene a
# `r2s run --lanes` program was synthesized on).
SCENE_RADIUS = 50.0


class FrameRoads:
    """The roads of frames, read from the maps beside them (one map read once, however many frames name it)."""

    def __init__(self, where: str | os.PathLike, radius: float = SCENE_RADIUS) -> None:
        self.where = Path(where)
        self.radius = radius
        self._maps: dict[str, RoadMap | None] = {}
        self._tables: dict[str, list[tuple[Path, pa.Table]]] = {}  # a map's rows, read once, until its road is built
        self._digests: dict[str, bytes | None] = {}

    def _read(self, map_id: str) -> list[tuple[Path, pa.Table]]:
        if map_id not in self._tables:
            self._tables[map_id] = list(_map_tables(self.where, {map_id})) if self.where.exists() else []
        return self._tables[map_id]

    def digest(self, map_id: str) -> bytes | None:
        """The content digest (map_digests) of the rows this reader builds the map's road from; None: no such map."""
        if map_id not in self._digests:
            self._digests[map_id] = _digests(self._read(map_id)).get(map_id)
        return self._digests[map_id]

    def map_named(self, map_id: str) -> RoadMap | None:
        if map_id not in self._maps:
            found = [road for f, table in self._read(map_id) for road in _roads(f, table)]
            self._maps[map_id] = found[0] if found else None
            self._tables.pop(map_id, None)
        return self._maps[map_id]

    def road(self, rows, place: EgoPlace | None = None) -> tuple[RoadMap | None, str | None]:
        """(the frame's road in its ego frame, None) or (None, the map it names that is missing) for the rows of
        one frame (FrameColumns, an Arrow table or a DataFrame) at `place` (their ego row's, EgoPlace.of the rows
        if not given); (None, None) when the frame names no map or has no pose."""
        rows = FrameColumns.of(rows)
        place = place if place is not None else EgoPlace.of(rows)
        if (pose := place.road_pose) is None:
            return None, None
        road = self.map_named(place.map_id)
        if road is None:
            return None, place.map_id
        # map_x and map_y are there: ego's were read above
        centres = [(float(x), float(y)) for x, y in zip(rows.get("map_x"), rows.get("map_y"))
                   if given(x) is not None and given(y) is not None]
        lanes = rows.get("lanes")
        named = {lane for ids in lanes if ids is not None for lane in ids} if lanes is not None else ()
        return in_ego_frame(road, *pose, self.radius, centres, named), None
