"""ArrayPairs: points that keep their float64 array, which `packed` concatenates instead of converting every
coordinate again. Packing must give exactly what packing the plain tuples gives, whatever mix it is handed."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from synth.road.roadmap import ArrayPairs, FloatPairs, open_ring, packed

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
        return ArrayPairs.of(a[:, :2])
    pts = tuple(zip(a[:, 0].tolist(), a[:, 1].tolist()))
    return FloatPairs(pts) if how == "floatpairs" else pts


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(coords, made_as), max_size=6))
def test_packed_equals_packing_the_tuples(items):
    seqs = [make(a, how) for a, how in items]
    xy, counts = packed(seqs)
    want_xy, want_counts = brute(seqs)
    assert counts.tolist() == want_counts.tolist()
    # bit for bit (NaN where NaN, -0.0 where -0.0)
    assert xy.shape == want_xy.shape and xy.dtype == np.float64
    assert xy.tobytes() == want_xy.tobytes()


@settings(max_examples=60, deadline=None)
@given(coords)
def test_array_pairs_are_their_tuple_and_keep_a_frozen_copy(a):
    pts = ArrayPairs.of(a[:, :2])
    assert isinstance(pts, tuple) and len(pts) == len(a) and all(type(c) is float for p in pts for c in p)
    # NaN is not equal to itself: compared as bits
    assert np.array(pts, dtype=float).reshape(-1, 2).tobytes() == np.asarray(a[:, :2], dtype=float).tobytes()
    assert pts.xy.tobytes() == np.asarray(a[:, :2], dtype=float).tobytes()
    assert not np.shares_memory(pts.xy, a)  # the caller's array may change; the points may not
    with pytest.raises(ValueError):
        pts.xy[:] = 0.0


def test_open_ring_keeps_the_array_of_what_it_keeps():
    ring = ArrayPairs.of(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 0.0]]))
    opened = open_ring(ring)
    assert opened == ring[:-1] and type(opened) is ArrayPairs
    assert opened.xy.tolist() == [list(p) for p in opened]
    assert packed([opened])[0].tolist() == [list(p) for p in opened]
