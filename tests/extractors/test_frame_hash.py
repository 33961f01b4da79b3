"""The content hash of a frame (extractors.frame_hash) against a brute force written from its documentation, one
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

from extractors.frame_hash import HASHED_COLUMNS, FrameHasher, frame_hashes_of, from_hex, to_hex
from extractors.frames import EXTRACTED_SCHEMA, OPTIONAL_COLUMNS, frame_rows
from extractors.frames_dataset import FramesDataset
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


def _word(name: str, value) -> int:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return NULL
    if name in ("entity_id", "type"):
        return int.from_bytes(hashlib.blake2b(value.encode(), digest_size=8).digest(), "little")
    return struct.unpack("<Q", struct.pack("<d", float(value)))[0]


def brute_hash(rows: list[dict]) -> str:
    """The documented hash of one frame's rows, in their order."""
    sums = [0, 0]
    for pos, row in enumerate(rows):
        chain = SEEDS[0]
        for name in HASHED_COLUMNS:
            chain = _mix(chain ^ _word(name, row.get(name)))
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
