"""ArrayPoints: points that keep their float64 array, which `packed` concatenates instead of converting every
coordinate again, and that make their Python pairs only when asked. Packing must give exactly what packing the
plain tuples gives, whatever mix it is handed; as a sequence they must be the plain tuple of pairs in every way a
consumer uses points (equality, hash, indexing, slicing, adding, pickling, JSON through iteration)."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from synth.road.roadmap import ArrayPoints, FloatPairs, ShellRing, open_ring, packed

coords = arrays(st.sampled_from([np.float32, np.float64]), st.tuples(st.integers(0, 6), st.integers(2, 3)),
                elements=st.floats(allow_nan=True, allow_infinity=True, width=32))
# what each sequence is handed as: kept array, plain tuple of pairs, or float pairs without array
made_as = st.sampled_from(["array", "tuple", "floatpairs"])


def brute(seqs) -> tuple[np.ndarray, np.ndarray]:
    """Packing by hand, one Python float at a time."""
    flat = [float(c) for s in seqs for p in s for c in p]
    return np.array(flat, dtype=float).reshape(-1, 2), np.array([len(s) for s in seqs], dtype=np.int64)


def make(a: np.ndarray, how: str):
    if how == "array":
        return ArrayPoints(a[:, :2])
    pts = tuple(zip(a[:, 0].tolist(), a[:, 1].tolist()))
    return FloatPairs(pts) if how == "floatpairs" else pts


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(coords, made_as), max_size=6))
def test_packed_equals_packing_the_tuples(items):
    seqs = [make(a, how) for a, how in items]
    xy, counts = packed(seqs)
    assert all(s._pairs is None for s in seqs if isinstance(s, ArrayPoints))  # packed from arrays, no pair made
    assert xy.flags.writeable and not any(np.shares_memory(xy, s.xy) for s in seqs if isinstance(s, ArrayPoints))
    want_xy, want_counts = brute(seqs)
    assert counts.tolist() == want_counts.tolist()
    # bit for bit (NaN where NaN, -0.0 where -0.0)
    assert xy.shape == want_xy.shape and xy.dtype == np.float64
    assert xy.tobytes() == want_xy.tobytes()


@settings(max_examples=80, deadline=None)
@given(coords, st.integers(-8, 8), st.integers(-8, 8), st.sampled_from([None, 1, 2, -1]))
def test_array_points_are_their_tuple_and_keep_a_frozen_copy(a, i, j, step):
    pts = ArrayPoints(a[:, :2])
    plain = tuple(zip(np.asarray(a[:, 0], dtype=float).tolist(), np.asarray(a[:, 1], dtype=float).tolist()))
    assert len(pts) == len(plain) and bool(pts) == bool(plain)
    assert all(type(c) is float for p in pts for c in p)
    # NaN is not equal to itself: the values compared as bits, equality where the tuple is equal to itself
    assert np.array(list(pts), dtype=float).reshape(-1, 2).tobytes() == np.asarray(a[:, :2], dtype=float).tobytes()
    assert pts.xy.tobytes() == np.asarray(a[:, :2], dtype=float).tobytes()
    assert not np.shares_memory(pts.xy, a)  # the caller's array may change; the points may not
    with pytest.raises(ValueError):
        pts.xy[:] = 0.0
    fresh = ArrayPoints(a[:, :2])  # pairs not made yet: indexing and slicing from the array
    if -len(plain) <= i < len(plain):
        assert _bits(fresh[i]) == _bits(plain[i])
    else:
        with pytest.raises(IndexError):
            fresh[i]
    sliced = fresh[i:j:step]
    assert isinstance(sliced, ArrayPoints) and _bits(tuple(sliced)) == _bits(plain[i:j:step])
    if not np.isnan(a).any():  # equal, hashed and added as the plain tuple
        assert pts == plain and plain == pts and pts == ArrayPoints(a[:, :2]) and not (pts != plain)
        assert hash(pts) == hash(plain) and {pts: 1}[plain] == 1
        assert pts + plain[:1] == plain + plain[:1] and plain[:1] + pts == plain[:1] + plain
        assert repr(pts) == repr(plain)
        assert json.dumps(list(pts)) == json.dumps(list(plain))
        as_array = np.asarray(pts, dtype=float)  # numpy reads the array: the tuple's values, writable, a copy
        assert as_array.shape == np.asarray(plain, dtype=float).shape
        assert as_array.tobytes() == np.asarray(plain, dtype=float).tobytes()
        assert as_array.flags.writeable and not np.shares_memory(as_array, pts.xy)
        back = pickle.loads(pickle.dumps(pts))
        assert type(back) is ArrayPoints and back == plain and not back.xy.flags.writeable
    assert pts != plain + ((1.5, 2.5),)


def _bits(pairs) -> bytes:
    return np.array(pairs, dtype=float).tobytes()


def test_open_ring_keeps_the_array_of_what_it_keeps():
    ring = ArrayPoints(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]]))
    opened = open_ring(ring)
    assert opened == ring[:-1] and type(opened) is ArrayPoints
    assert opened.xy.tolist() == [list(p) for p in opened]
    assert packed([opened])[0].tolist() == [list(p) for p in opened]


def test_a_slice_of_a_shell_ring_is_no_ring_and_points_refuse_other_shapes():
    ring = ShellRing.owning(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]))
    assert type(ring[:2]) is ArrayPoints and type(pickle.loads(pickle.dumps(ring))) is ShellRing
    with pytest.raises(ValueError):
        ArrayPoints(np.zeros((3, 3)))
