"""Every strategy's output on crowd frames (tests/support/crowds.py) is pinned byte for byte: programs, Scenic text and the
`r2s synth --format json` document without its stats.

The pins (tests/data/crowd_golden.json) were written by the core as it stood before issue 18's speed-ups
(commit 23888fc, each case in a process of its own: `python tests/synth/test_crowd_golden.py --write --tree CHECKOUT`,
tests/support/golden.py), so the interval certification, exact Range values and the pruned A* must reproduce it
exactly: the same programs, certified the same way. Solver query counts are checked where issue 18 must not
change them (`--oracle smt`, the paper's all-SMT mode) and node counts where the search is unchanged (every
strategy but auto).
Also checked: the optimum against the independent brute force (tests/support/bruteforce.py) on the small frames.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # run as a script (--write): the repository root
from tests.support.crowds import crowd_scene  # noqa: E402
from tests.support.golden import case_ids, check, key, load_pins, output, tree_argument, write  # noqa: E402

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "crowd_golden.json"

STRATEGIES = ("auto", "bfs", "bfs-cpa", "dfs", "dfs-bnb", "dfs-cpa", "dfs-bnb-cpa", "astar", "astar-cpa", "monolithic")
# (name, seed, head-counts): tiny crowds every strategy finishes, small ones for the CPA strategies and the
# all-SMT oracle, full crowds (N 61-72) for auto, among them the heaviest searches of the benchmark's first 32.
TINY = [(f"tiny{s}", s, {"pedestrians": 6, "barriers": 1, "cones": 1, "cars": 0}) for s in (1, 2)]
SMALL = [(f"small{s}", s, {"pedestrians": 10, "barriers": 2, "cones": 1, "cars": 1}) for s in (3, 4)]
FULL = [("crowd4", 4, None), ("crowd6", 6, None), ("crowd19", 19, None), ("crowd0", 0, None)]
CASES = (
    [(name, {"strategy": st}) for name, _, _ in TINY for st in STRATEGIES]
    + [(name, {"strategy": st, "oracle": "smt"}) for name, _, _ in TINY[:1] for st in ("auto", "bfs-cpa", "astar-cpa")]
    + [(name, {"strategy": st}) for name, _, _ in SMALL for st in ("auto", "bfs-cpa", "dfs-bnb-cpa", "astar-cpa")]
    + [(name, {"oracle": o}) for name, _, _ in SMALL for o in ("smt", "closed-form")]
    + [(name, {"oracle": o}) for name, _, _ in FULL for o in ("hybrid", "closed-form")]
)


def scenes() -> dict:
    from tests.support.crowds import crowd_scenes

    out = {name: crowd_scene(seed, **counts) for name, seed, counts in TINY + SMALL}
    full = crowd_scenes(max(seed for _, seed, _ in FULL) + 1)
    out.update({name: full[seed] for name, seed, _ in FULL})
    return out


@pytest.fixture(scope="module")
def crowd_frames():
    return scenes()


@pytest.fixture(scope="module")
def pins():
    return load_pins(GOLDEN)


@pytest.mark.parametrize("frame,cfg", CASES, ids=case_ids(CASES))
def test_output_is_byte_identical_to_the_pins(crowd_frames, pins, frame, cfg):
    check(output(crowd_frames[frame], cfg), pins[(frame, key(cfg))], cfg)


@pytest.mark.parametrize("name", [n for n, _, _ in TINY + SMALL])
def test_the_optimum_is_the_brute_force_optimum(crowd_frames, name):
    from synth.config import SynthConfig
    from synth.synthesize import synthesize
    from tests.support.bruteforce import optimal_cost

    scene = crowd_frames[name]
    assert synthesize(scene, SynthConfig()).cost == optimal_cost(scene)


if __name__ == "__main__" and sys.argv[1:2] == ["--write"]:
    write(GOLDEN, CASES, scenes(), tree_argument(sys.argv))
