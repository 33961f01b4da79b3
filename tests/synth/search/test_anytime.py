"""Every strategy is anytime: under a time or memory limit it returns a valid program and a proven bound."""

from __future__ import annotations

import pytest

from synth.config import STRATEGIES, SynthConfig
from synth.semantics import check
from synth.synthesize import synthesize
from tests.support.bruteforce import optimal_cost


@pytest.fixture(scope="module")
def hard_scene(real_frames):
    # 12 vehicles: factorial strategies cannot finish in a millisecond.
    return next(s for s in real_frames if len(s.others) == 12)


@pytest.mark.parametrize("strategy", [s for s in STRATEGIES if s not in ("auto", "monolithic")])
def test_time_limit_returns_best_program_and_a_true_lower_bound(strategy, hard_scene):
    optimum = optimal_cost(hard_scene)
    result = synthesize(hard_scene, SynthConfig(strategy=strategy, oracle="closed-form", time_limit=0.002))
    assert result.status in ("optimal", "feasible", "timeout")
    assert result.lower_bound <= optimum <= result.cost
    assert (result.status == "optimal") == (result.lower_bound == result.cost)
    if result.status == "timeout":
        assert result.cost == 2 * len(hard_scene.others)
    assert check(result.program, hard_scene).ok


def test_unpruned_bfs_times_out_where_cpa_finishes(hard_scene):
    slow = synthesize(hard_scene, SynthConfig(strategy="bfs", oracle="closed-form", time_limit=0.05))
    fast = synthesize(hard_scene, SynthConfig(strategy="bfs-cpa", oracle="closed-form", time_limit=30))
    assert slow.status != "optimal"
    assert fast.status == "optimal" and fast.cost <= slow.cost


def test_memory_limit_stops_the_search_with_memout(hard_scene):
    # 1 MB is below any Python process: the first memory poll (every 4096 nodes) stops the search.
    result = synthesize(hard_scene, SynthConfig(strategy="bfs", oracle="closed-form", memory_limit=1))
    assert result.status == "memout"
    assert result.lower_bound <= result.cost
    assert check(result.program, hard_scene).ok


def test_peak_memory_is_the_process_own_not_its_parents():
    """A child of a large parent reports its own peak (Linux keeps ru_maxrss across exec; VmHWM is per process)."""
    import subprocess
    import sys

    big = "x = bytearray(300 * 2**20); x[::4096] = b'1' * len(x[::4096]); "
    child = "from synth.search.budget import peak_rss_mb; print(peak_rss_mb())"
    code = big + f"import subprocess, sys; print(subprocess.run([sys.executable, '-c', {child!r}], " \
                 "capture_output=True, text=True, check=True).stdout)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert float(out.split()[0]) < 200.0, out
