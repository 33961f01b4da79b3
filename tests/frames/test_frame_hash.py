"""The content hash of a frame (frames.frame_hash) against a brute force written from its documentation, one
Python int at a time; and the properties the resume relies on: it sees every value synthesis reads, the row
order, nothing else, and not how Parquet stores the rows."""

from __future__ import annotations

import hashlib
import math
import struct

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from hypothesis import given, settings
from hypothesis import strategies as st

from frames.dataset import FramesDataset
from frames.frame_hash import (
    HASHED_COLUMNS,
    ROAD_HASHED_COLUMNS,
    Coverage,
    FrameHasher,
    RowBytes,
    frame_hashes_of,
    from_hex,
    to_hex,
)
from frames.maps import FrameRoads, map_digests
from frames.rows import EXTRACTED_SCHEMA, OPTIONAL_COLUMNS, frame_rows
from frames.schema import ROAD_COLUMNS
from storage.frame_index import FrameIndex, frame_hashes

MASK = 2**64 - 1
NULL = 0x7FF8000000000000
SEEDS = (0x72327367656E2E66, 0x6672616D652E6831)


def _mix(x: int) -> int:
    x ^= x >> 30
    x = (x * 0xBF58476D1CE4E5B9) & MASK
    x ^= x >> 27
    x = (x * 0x94D049BB133111EB) & MASK
    return x ^ (x >> 31)


def _blake(data: bytes) -> int:
    return int.from_bytes(hashlib.blake2b(data, digest_size=8).digest(), "little")


def _word(name: str, value, maps: dict | None = None) -> int:
    """A value's word as the docstring of frames/frame_hash.py says (maps: with a road, digests by map id)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return NULL
    if name == "map_id" and maps is not None:
        return _blake(value.encode() + b"\0" + (maps.get(value) or b""))
    if isinstance(value, str):
        return _blake(value.encode())
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, list):
        total = sum(_mix(_word("", v) ^ _mix(k + 1)) for k, v in enumerate(value)) & MASK
        return _mix(total ^ _mix(len(value) ^ SEEDS[1]))
    return struct.unpack("<Q", struct.pack("<d", float(value)))[0]


def brute_hash(rows: list[dict], maps: dict | None = None) -> str:
    """The documented hash of one frame's rows, in their order (with maps: with a road, maps' digests by id)."""
    sums = [0, 0]
    for pos, row in enumerate(rows):
        chain = SEEDS[0]
        for name in HASHED_COLUMNS + (ROAD_HASHED_COLUMNS if maps is not None else ()):
            chain = _mix(chain ^ _word(name, row.get(name), maps))
        salted = chain ^ _mix(pos + 1)
        for k in (0, 1):
            sums[k] = (sums[k] + _mix(salted ^ SEEDS[k])) & MASK
    lanes = [_mix(sums[k] ^ _mix(len(rows) ^ SEEDS[k])) for k in (0, 1)]
    return f"{lanes[0]:016x}{lanes[1]:016x}"


finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
maybe = st.one_of(st.none(), finite, st.just(float("nan")))


@st.composite
def frames(draw):
    """Frames of random rows (the hash does not care whether they are scenes); ids unique within a frame."""
    out = []
    for f in range(draw(st.integers(1, 5))):
        n = draw(st.integers(1, 6))
        ids = draw(st.lists(st.sampled_from(["ego", "car1", "car2", "ped1", "truck3", "x9"]), min_size=n,
                            max_size=n, unique=True))
        for eid in ids:
            out.append({"frame_id": f"s/{f}", "entity_id": eid, "type": draw(st.sampled_from(["Car", "Pedestrian"])),
                        "x": draw(finite), "y": draw(finite), "heading": draw(finite),
                        "length": draw(st.one_of(st.none(), st.floats(0.5, 20, width=32))),
                        "width": draw(st.one_of(st.none(), st.floats(0.5, 5, width=32))),
                        "speed": draw(maybe), "pos_sigma": draw(maybe)})
    return out


def _table(rows: list[dict]) -> pa.Table:
    schema = pa.schema([("frame_id", pa.string()), ("entity_id", pa.string()), ("type", pa.string()),
                        ("x", pa.float64()), ("y", pa.float64()), ("heading", pa.float64()),
                        ("length", pa.float32()), ("width", pa.float32()), ("speed", pa.float64()),
                        ("pos_sigma", pa.float64())])
    return pa.Table.from_pylist(rows, schema=schema)


def _by_frame(rows: list[dict]) -> dict[str, list[dict]]:
    out: dict[str, list[dict]] = {}
    for r in rows:
        out.setdefault(r["frame_id"], []).append(r)
    return out


def _starts(table: pa.Table) -> np.ndarray:
    ids = table.column("frame_id").to_pylist()
    return np.array([i for i in range(len(ids)) if i == 0 or ids[i] != ids[i - 1]], dtype=np.int64)


@settings(max_examples=60, deadline=None)
@given(frames())
def test_the_hash_is_the_documented_one(rows):
    table = _table(rows)
    got = to_hex(*frame_hashes_of(table, _starts(table)))
    assert got == [brute_hash(r) for r in _by_frame(rows).values()]


@settings(max_examples=40, deadline=None)
@given(frames(), st.integers(1, 7))
def test_streaming_over_any_row_groups_gives_the_same_keys(rows, group):
    """A frame cut by a row-group boundary hashes as a whole frame (the sum carries over)."""
    table = _table(rows)
    hasher = FrameHasher()
    for start in range(0, table.num_rows, group):
        piece = table.slice(start, group)
        hasher.feed(piece, _starts(piece), np.array([piece.column("frame_id")[int(i)].as_py()
                                                     for i in _starts(piece)], dtype=object))
    frames_ = _by_frame(rows)
    lanes = from_hex(pa.array([brute_hash(r) for r in frames_.values()]))
    hi, lo = frame_hashes(list(frames_))
    want = FrameIndex(hi ^ lanes[0], lo ^ lanes[1])
    keys = hasher.keys()
    assert len(keys) == len(frames_)
    assert (keys.hi == want.hi).all() and (keys.lo == want.lo).all()


def _one_frame() -> list[dict]:
    ego = {"track_id": "e", "type": "Car", "category": "vehicle.car", "x": 0.0, "y": 0.0, "heading": 0.0,
           "length": 4.5, "width": 1.9, "speed": 3.0}
    others = [{"track_id": f"t{i}", "type": t, "category": "c", "x": 3.0 * i, "y": 10.0 - i, "heading": 5.0 * i,
               "length": 4.0, "width": 1.8, "speed": 1.0 + i} for i, t in enumerate(["Car", "Pedestrian", "Truck"])]
    return frame_rows("test", "scene-1", 0, 1000, ego, others)


def _hash(rows: list[dict], schema: pa.Schema = EXTRACTED_SCHEMA) -> str:
    table = pa.Table.from_pylist(rows, schema=schema)
    return to_hex(*frame_hashes_of(table, np.zeros(1, np.int64)))[0]


def test_every_value_synthesis_reads_changes_the_hash_and_nothing_else_does():
    rows = _one_frame()
    base = _hash(rows)
    for name in ("x", "y", "heading", "length", "width", "speed"):
        changed = [dict(r) for r in rows]
        changed[2][name] = changed[2][name] + 0.25
        assert _hash(changed) != base, name
    for name, value in (("entity_id", "car9"), ("type", "Bus")):
        changed = [dict(r) for r in rows]
        changed[1][name] = value
        assert _hash(changed) != base, name
    assert _hash(rows[::-1]) != base  # the order is the order synthesis declares entities in
    assert _hash(rows[:-1]) != base  # a row less
    for name, value in (("source", "other"), ("scene", "s2"), ("frame_index", 7), ("timestamp_us", 5),
                        ("track_id", "zz"), ("category", "animal"), ("frame_id", "renamed")):
        same = [dict(r, **{name: value}) for r in rows]
        assert _hash(same) == base, name


def test_how_parquet_stores_the_rows_does_not_count(tmp_path):
    rows = [dict(r, frame_id=f"f{k}") for k in range(30) for r in _one_frame()]
    table = pa.Table.from_pylist(rows, schema=EXTRACTED_SCHEMA)
    hashes = []
    for name, kwargs in (("a", {"row_group_size": 7, "use_dictionary": False}),
                         ("b", {"row_group_size": 1000, "compression": "zstd"})):
        pq.write_table(table, tmp_path / f"{name}.parquet", **kwargs)
        hasher = FrameHasher()
        FramesDataset.open(tmp_path / f"{name}.parquet").check(hasher)
        keys = hasher.keys()
        hashes.append((keys.hi.tolist(), keys.lo.tolist()))
    assert hashes[0] == hashes[1] and len(hashes[0][0]) == 30
    # An optional column of nulls and no such column hash alike (synthesis reads both as "not given").
    plain = [{k: v for k, v in r.items() if k != "speed"} for r in _one_frame()]
    nulls = [dict(r, speed=None) for r in plain]
    without = pa.schema([f for f in EXTRACTED_SCHEMA if f.name != "speed"])
    assert _hash(plain, without) == _hash(nulls)
    assert set(OPTIONAL_COLUMNS) <= set(HASHED_COLUMNS)


def test_stored_hashes_read_back_and_bad_ones_are_not_valid():
    lane0 = np.array([0, 2**64 - 1, 0x0123456789ABCDEF], dtype=np.uint64)
    lane1 = np.array([5, 7, 0xFEDCBA9876543210], dtype=np.uint64)
    text = to_hex(lane0, lane1)
    got0, got1, valid = from_hex(pa.array(text + [None, "xyz", "g" * 32, text[2].upper()]))
    assert valid.tolist() == [True, True, True, False, False, False, True]
    assert got0[:3].tolist() == lane0.tolist() and got1[:3].tolist() == lane1.tolist()
    assert (got0[6], got1[6]) == (lane0[2], lane1[2])


ROAD_MAPS = {"m1": bytes(range(16)), "m2": bytes(range(16, 32))}  # "m3": named by frames, absent from the maps
maybe_text = st.one_of(st.none(), st.sampled_from(["", "lane-1", "lane-2", "é", "a\0b"]))
maybe_bool = st.one_of(st.none(), st.booleans())


@st.composite
def road_frames(draw):
    """frames() with the road columns, of every kind of value they hold (lists empty, null, with null elements)."""
    rows = draw(frames())
    for r in rows:
        r.update(source=draw(maybe_text), scene=draw(maybe_text),
                 frame_index=draw(st.one_of(st.none(), st.integers(-2**31, 2**31 - 1))),
                 map_id=draw(st.one_of(st.none(), st.sampled_from(["m1", "m2", "m3"]))),
                 map_x=draw(maybe), map_y=draw(maybe), map_heading=draw(maybe),
                 lanes=draw(st.one_of(st.none(), st.lists(maybe_text, max_size=4))), lane=draw(maybe_text),
                 in_intersection=draw(maybe_bool), on_crosswalk=draw(maybe_bool), off_road=draw(maybe_bool))
    return rows


def _road_table(rows: list[dict]) -> pa.Table:
    schema = _table([]).schema
    schema = pa.schema(list(schema) + [("source", pa.string()), ("scene", pa.string()),
                                       ("frame_index", pa.int32())] + list(ROAD_COLUMNS.items()))
    return pa.Table.from_pylist(rows, schema=schema)


@settings(max_examples=60, deadline=None)
@given(road_frames(), st.integers(1, 7))
def test_with_a_road_the_hash_is_the_documented_one_streamed_or_not(rows, group):
    table = _road_table(rows)
    coverage = Coverage.with_road(ROAD_MAPS)
    want = [brute_hash(r, ROAD_MAPS) for r in _by_frame(rows).values()]
    assert to_hex(*frame_hashes_of(table, _starts(table), coverage)) == want
    hasher = FrameHasher(keep_lanes=True, coverage=coverage)
    for start in range(0, table.num_rows, group):
        piece = table.slice(start, group)
        hasher.feed(piece, _starts(piece), np.array([piece.column("frame_id")[int(i)].as_py()
                                                     for i in _starts(piece)], dtype=object))
    assert to_hex(*hasher.lanes(list(_by_frame(rows)))) == want


def test_with_a_road_every_road_value_and_the_named_map_change_the_hash():
    rows = [dict(r, map_id="m1", map_x=1.0 + i, map_y=2.0, map_heading=30.0, lanes=["l1"], lane="l1",
                 in_intersection=False, on_crosswalk=False, off_road=False) for i, r in enumerate(_one_frame())]
    table = pa.Table.from_pylist(rows, schema=EXTRACTED_SCHEMA)

    def road_hash(t: pa.Table, maps=ROAD_MAPS) -> str:
        return to_hex(*frame_hashes_of(t, np.zeros(1, np.int64), Coverage.with_road(maps)))[0]

    base = road_hash(table)
    for name, value in (("map_x", 1.5), ("map_y", 0.0), ("map_heading", 31.0), ("lanes", ["l1", "l2"]),
                        ("lanes", []), ("lane", "l2"), ("in_intersection", True), ("on_crosswalk", True),
                        ("off_road", True), ("map_id", "m2"), ("scene", "s2"), ("frame_index", 9), ("source", "x")):
        changed = [dict(r) for r in rows]
        changed[1][name] = value
        assert road_hash(pa.Table.from_pylist(changed, schema=EXTRACTED_SCHEMA)) != base, name
    assert road_hash(table, {**ROAD_MAPS, "m1": bytes(16)}) != base  # the map it names, changed
    assert road_hash(table, {"m1": ROAD_MAPS["m1"]}) == base  # a map it does not name does not count
    assert road_hash(table, {}) != base  # the map it names is gone


def _maps_table(dx: float = 0.0) -> pa.Table:
    from frames.maps import MAPS_SCHEMA

    rows = []
    for m in ("a", "b"):
        for k in range(3):
            rows.append({"map_id": m, "feature_id": f"{m}{k}", "kind": "lane", "source_type": "t",
                         "polygon_x": [0.0 + dx, 1.0, 1.0, 0.0] if m == "a" else [0.0, 2.0, 2.0],
                         "polygon_y": [0.0, 0.0, 1.0, 1.0] if m == "a" else [0.0, 0.0, 2.0],
                         "line_x": [0.5, 0.5 + k], "line_y": [0.0, 1.0],
                         "left_neighbour": None, "right_neighbour": None, "successors": [f"{m}{k + 1}"] if k < 2 else [],
                         "predecessors": [f"{m}{k - 1}"] if k else [], "is_intersection": k == 2,
                         "direction": None if k else 90.0,
                         "polygon_rule": "source", "neighbour_rule": None})
    return pa.Table.from_pylist(rows, schema=MAPS_SCHEMA)


def test_map_digests_are_the_maps_content_not_their_storage(tmp_path):
    """A map read whole (the run's check) and alone (a worker) digests alike, however the file stores it; a
    coordinate moved changes its map's digest and no other's."""
    table = _maps_table()
    (tmp_path / "one").mkdir()
    (tmp_path / "two").mkdir()
    pq.write_table(table, tmp_path / "one" / "part-0.parquet")
    interleaved = table.take([0, 3, 1, 4, 2, 5])  # the maps' rows interleaved, each map's in its order
    pq.write_table(interleaved, tmp_path / "two" / "part-0.parquet", row_group_size=2, use_dictionary=False,
                   compression="zstd")
    one, two = map_digests(tmp_path / "one"), map_digests(tmp_path / "two")
    assert one == two and sorted(one) == ["a", "b"] and one["a"] != one["b"]
    roads = FrameRoads(tmp_path / "two")
    assert {m: roads.digest(m) for m in one} == one and roads.digest("c") is None
    assert roads.map_named("a").map_id == "a"  # the rows it digested are the rows it builds the road from
    (tmp_path / "moved").mkdir()
    pq.write_table(_maps_table(dx=0.5), tmp_path / "moved" / "part-0.parquet")
    moved = map_digests(tmp_path / "moved")
    assert moved["a"] != one["a"] and moved["b"] == one["b"]
    assert map_digests(tmp_path / "absent") == {}


ROW_SCHEMA = pa.schema([("s", pa.string()), ("xs", pa.list_(pa.float64())), ("names", pa.list_(pa.string())),
                        ("flag", pa.bool_()), ("v", pa.float64()), ("n", pa.int32())])
row_values = st.fixed_dictionaries({
    "s": maybe_text, "xs": st.one_of(st.none(), st.lists(maybe, max_size=3)),
    "names": st.one_of(st.none(), st.lists(maybe_text, max_size=3)), "flag": maybe_bool, "v": maybe,
    "n": st.one_of(st.none(), st.integers(-5, 5))})


@settings(max_examples=60, deadline=None)
@given(st.lists(row_values, min_size=1, max_size=12), st.data())
def test_digesting_a_run_of_rows_is_digesting_those_rows_alone(rows, data):
    """RowBytes of a table digests rows a..b as a table of those rows alone digests them, built afresh (as a worker
    reads one map) or as a zero-copy slice: the per-map digests of a file are each map's own."""
    import hashlib as hl

    table = pa.Table.from_pylist(rows, schema=ROW_SCHEMA)
    a = data.draw(st.integers(0, len(rows) - 1))
    b = data.draw(st.integers(a + 1, len(rows)))

    def digest(t: pa.Table, lo: int, hi: int) -> bytes:
        h = hl.blake2b(digest_size=16)
        RowBytes(t).digest(h, lo, hi)
        return h.digest()

    alone = pa.Table.from_pylist(rows[a:b], schema=ROW_SCHEMA)
    assert digest(table, a, b) == digest(alone, 0, b - a) == digest(table.slice(a, b - a), 0, b - a)
