"""`from pipeline.query import query` (docs/api.md): the example of docs/api.md runs as written, and the API gives
the rows `r2s query` writes, from a path or from a table of frames rows."""

from __future__ import annotations

import re
import subprocess
import sys

import pyarrow.parquet as pq
import pytest

from frames.rows import read_frames
from pipeline.errors import InputError
from tests.support import ROOT, run_r2s

API = ROOT / "docs" / "api.md"
FRAMES = ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet"


def test_the_api_page_example_runs_as_written(tmp_path):
    section = API.read_text().split("## Matches and events: `pipeline.query.query`", 1)[1]
    block = re.findall(r"^```python\n(.*?)^```", section, flags=re.S | re.M)[0]
    (tmp_path / "data").symlink_to(ROOT / "data")
    proc = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert "scene-0061" in proc.stdout and "15 frames with a pedestrian ahead" in proc.stdout


@pytest.mark.parametrize("args,kw", [([], {}), (["--all"], {"all_bindings": True}),
                                     (["--events", "--min-duration", "1"], {"events": True, "min_duration_s": 1.0})])
def test_the_api_gives_what_the_verb_writes(tmp_path, args, kw):
    from pipeline.query import query

    pattern = ROOT / "data" / "patterns" / "vehicle-following-ego.dsl"
    out = tmp_path / "out.parquet"
    assert run_r2s("query", str(FRAMES), str(pattern), "--out", str(out), *args).returncode == 0
    expected = pq.read_table(out).to_pylist()
    assert expected
    assert query(FRAMES, pattern.read_text(), **kw).to_dict("records") == expected
    assert query(read_frames(FRAMES), pattern.read_text(), **kw).to_dict("records") == expected  # rows in


def test_bad_input_is_an_input_error():
    from pipeline.query import query

    with pytest.raises(InputError, match="line 1"):
        query(FRAMES, "car = new Vehicle nowhere\n")
    with pytest.raises(InputError, match="does not exist"):
        query(ROOT / "missing.parquet", "car = new Vehicle ahead of ego by Range(0, 5), facing toward ego\n")
