"""The static DSL's output is pinned byte for byte: programs, Scenic text and `r2s synth --format json` (without
timings) on a sample of the 242 shipped nuScenes-mini keyframes, for every oracle, robust synthesis and the
paper's strategies.

The pins (tests/data/static_golden.json) were written by the core before issue 18's speed-ups (commit 23888fc,
which kept the output of the core before statement parts became one interface, a16d2a3), each case in a
process of its own (`python tests/synth/test_static_golden.py --write --tree CHECKOUT`; tests/support/golden.py), so any
change to what a static program looks like or costs shows up here, and to how many solver queries the
paper's all-SMT mode asks or how many nodes the paper's strategies expand. Rewrite them only for an intended
change of the static output, and say so in the commit. (Issue 25 renamed the shipped frames' entities, ids stable
across a scene: the pinned programs were renamed id for id and their two hashes recomputed; a fresh write by this
core gave the same programs, costs and checked counts.)
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script (--write): the repository root
from tests.support.golden import case_ids, check, key, load_pins, output, tree_argument, write  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
FRAMES = ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet"
GOLDEN = Path(__file__).resolve().parents[1] / "data" / "static_golden.json"

# (frame, config): every oracle on small and mid-sized frames, smt on small ones (it asks every pair), robust
# synthesis with and without a solver, and the paper's strategies where they finish quickly.
SMALL = ("scene-0796/35", "scene-0796/31", "scene-0757/2", "scene-0796/27")  # 4, 9, 11, 10 entities
MID = ("scene-0757/35", "scene-0553/1", "scene-0103/5", "scene-0655/10")  # 15, 30, 38, 48
LARGE = ("scene-0061/18",)  # 141
CASES = (
    [(f, {"oracle": o}) for f in SMALL + MID + LARGE for o in ("hybrid", "closed-form")]
    + [(f, {"oracle": "smt"}) for f in SMALL]
    + [(f, {"oracle": o, "pos_uncertainty": 0.5, "heading_uncertainty": 2.0}) for f in SMALL[:3] + MID[:2]
       for o in ("hybrid", "closed-form")]
    + [(SMALL[1], {"strategy": s, "oracle": "smt"}) for s in ("bfs-cpa", "dfs-bnb-cpa", "astar-cpa")]
    + [(SMALL[0], {"strategy": s}) for s in ("monolithic", "bfs", "dfs")]
)


def shipped_scenes() -> dict:
    from frames.rows import iter_scenes, read_frames

    wanted = {f for f, _ in CASES}
    return {s.frame_id: s for s in iter_scenes(read_frames(FRAMES)) if s.frame_id in wanted}


@pytest.fixture(scope="module")
def scenes():
    return shipped_scenes()


@pytest.fixture(scope="module")
def pins():
    return load_pins(GOLDEN)


@pytest.mark.parametrize("frame,cfg", CASES, ids=case_ids(CASES))
def test_static_output_is_byte_identical_to_the_pins(scenes, pins, frame, cfg):
    check(output(scenes[frame], cfg), pins[(frame, key(cfg))], cfg)


if __name__ == "__main__" and sys.argv[1:2] == ["--write"]:
    write(GOLDEN, CASES, shipped_scenes(), tree_argument(sys.argv))
