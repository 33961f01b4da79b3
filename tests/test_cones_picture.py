"""docs/cones.png is what tools/draw_cones.py draws today from the default configuration: the picture of the
direction words in docs/dsl.md stays true to the constants (a change of delta1 redraws it)."""

from __future__ import annotations

import importlib.util

from tests.support import ROOT


def test_the_committed_cones_picture_is_what_the_script_draws(tmp_path):
    spec = importlib.util.spec_from_file_location("draw_cones", ROOT / "tools" / "draw_cones.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main([str(tmp_path / "cones.png")]) == 0
    assert (tmp_path / "cones.png").read_bytes() == (ROOT / "docs" / "cones.png").read_bytes(), (
        "docs/cones.png is stale: run `python tools/draw_cones.py` from the repository's root")
    assert "](cones.png)" in (ROOT / "docs" / "dsl.md").read_text()
