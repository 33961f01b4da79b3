"""A ScenarioNet line of fewer than two distinct points is dropped (docs/formats.md): the reader decides it on the
array its points keep (ArrayPoints) without making their pairs; it must count distinct points exactly as a set of
the pairs does (NaN distinct from itself, -0.0 equal to 0.0), whatever the line."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from extractors.scenarionet import _one_point
from synth.road.roadmap import ArrayPoints

values = st.sampled_from([0.0, -0.0, 1.0, 2.5, float("nan"), float("inf")])


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(values, values), max_size=6))
def test_one_point_counts_distinct_points_as_a_set_of_pairs(pairs):
    xy = np.array(pairs, dtype=float).reshape(-1, 2)
    pts = ArrayPoints(xy)
    plain = tuple(zip(xy[:, 0].tolist(), xy[:, 1].tolist()))  # fresh floats, as the pairs would be made
    assert _one_point(pts) == (len(set(plain)) < 2)
    assert _one_point(plain) == (len(set(plain)) < 2)
