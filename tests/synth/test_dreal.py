"""The optional dReal backend (the paper's solver). Its wheel needs the system library libibex."""

from __future__ import annotations

import pytest

from synth.config import SynthConfig

try:
    import dreal  # noqa: F401

    DREAL_ERROR = None
except ImportError as exc:  # e.g. "libibex.so: cannot open shared object file"
    DREAL_ERROR = str(exc)

needs_dreal = pytest.mark.skipif(DREAL_ERROR is not None, reason=f"dreal cannot be imported here: {DREAL_ERROR}")


@needs_dreal
def test_dreal_backend_finds_the_same_optimum(real_frames):
    from synth.synthesize import synthesize
    from tests.support.bruteforce import optimal_cost

    for scene in [s for s in real_frames if len(s.others) <= 8][:3]:
        result = synthesize(scene, SynthConfig(solver="dreal", oracle="smt", strategy="bfs-cpa"))
        assert result.cost == optimal_cost(scene) and result.certified


def test_missing_dreal_is_a_clear_error_not_a_crash():
    if DREAL_ERROR is None:
        pytest.skip("dreal imports here; nothing to refuse")
    from synth.smt import DrealBackend, SolverUnavailable

    with pytest.raises(SolverUnavailable, match="libibex"):
        DrealBackend(SynthConfig(solver="dreal"))
