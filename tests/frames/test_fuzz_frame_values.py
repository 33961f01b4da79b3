"""Fuzzing the values of frames files (issue 22, done-when; the bytes are fuzzed by test_fuzz_frames.py): random
values in a real frames file's columns (text of any kind, NaN, infinities, huge and subnormal numbers, nulls),
read the way every verb reads them (FramesDataset.open, the streaming check, the rows to scenes). Each is
accepted or refused as bad input (an InputError: one line, exit 2); nothing else escapes. Bounded: a fixed
number of examples on a 60-row file."""

from __future__ import annotations

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from frames.dataset import FramesDataset
from frames.rows import frame_to_scene
from synth.errors import InputError
from tests.support import ROOT

KEYFRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
ROWS = 60
FUZZ = settings(max_examples=60, deadline=None, derandomize=True, database=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@pytest.fixture(scope="module")
def small() -> pa.Table:
    return pq.read_table(KEYFRAMES).slice(0, ROWS)


def _read_like_a_verb(path) -> None:
    """What `r2s run` / `query` / `scene` do with a frames path before any synthesis."""
    try:
        dataset = FramesDataset.open(path)
        dataset.check()
        table = dataset.read_all()
        for fid in sorted(set(table.column("frame_id").to_pylist())):
            frame = table.filter(pa.compute.equal(table.column("frame_id"), fid))
            frame_to_scene(frame.to_pandas())
    except InputError:
        pass  # refused as bad input: one line, exit 2


TEXT = st.text(max_size=300) | st.sampled_from(["", "ego", "Car", "a" * 257, "x\ny", "\u2028", "<script>"])
NUMBER = st.floats(allow_nan=True, allow_infinity=True) | st.sampled_from([1e154, 5e-324, -0.0, 1e6, 1e300])


@FUZZ
@given(data=st.data())
def test_random_values_are_accepted_or_bad_input(small, tmp_path, data):
    columns = {name: small.column(name).to_pylist() for name in small.column_names}
    for _ in range(data.draw(st.integers(1, 6))):
        name = data.draw(st.sampled_from(sorted(columns)))
        row = data.draw(st.integers(0, ROWS - 1))
        kind = small.schema.field(name).type
        if data.draw(st.integers(0, 5)) == 0:
            value = None
        elif pa.types.is_string(kind):
            value = data.draw(TEXT)
        elif pa.types.is_floating(kind):
            value = data.draw(NUMBER)
        elif pa.types.is_boolean(kind):
            value = data.draw(st.booleans())
        else:
            value = data.draw(st.integers(-(2**31), 2**31 - 1))
        columns[name][row] = value
    table = pa.table({n: pa.array(v, small.schema.field(n).type) for n, v in columns.items()})
    path = tmp_path / "frames.parquet"
    pq.write_table(table, path)
    _read_like_a_verb(path)
