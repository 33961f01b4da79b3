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


def _fake_dreal(monkeypatch):
    """An importable stand-in for the dreal module: enough for the backend's parts that never reach dReal (its
    exact backend), so they are tested where the wheel cannot load."""
    import sys
    import types

    fake = types.ModuleType("dreal")
    fake.And = fake.Or = fake.Not = fake.Variable = fake.CheckSatisfiability = None
    monkeypatch.setitem(sys.modules, "dreal", fake)


def test_dreal_certifies_with_one_z3_backend_per_frame_that_counts_into_its_stats(monkeypatch, real_frames):
    from dataclasses import replace

    import synth.smt.dreal_backend as dreal_backend
    from synth.dsl import Program
    from synth.parts.heading import AbsoluteHeading
    from synth.smt import make_backend
    from synth.smt.z3_backend import Z3Backend
    from synth.syntax import Range
    from synth.synthesize import synthesize

    _fake_dreal(monkeypatch)
    made = []

    class CountedZ3(Z3Backend):
        def __post_init__(self):
            made.append(self)
            super().__post_init__()

    monkeypatch.setattr(dreal_backend, "Z3Backend", CountedZ3)
    config = SynthConfig(solver="dreal", oracle="smt")  # the all-SMT certification: every statement to z3
    backend = make_backend(config)
    assert isinstance(backend, dreal_backend.DrealBackend)
    scene = next(s for s in real_frames if len(s.others) >= 4)
    program = synthesize(scene, SynthConfig(oracle="smt")).program
    first = program.statements[0]
    h = round(scene.by_id()[first.id].heading)
    wrong = Program((replace(first, heading=AbsoluteHeading(Range(h + 10.0, h + 15.0))),) + program.statements[1:])
    for _ in range(3):
        assert backend.certify(program, scene) == []
        assert backend.certify(wrong, scene) == [first.id]
    assert len(made) == 1 and backend.exact is made[0]
    assert made[0].stats is backend.stats and backend.stats.queries >= 6 * len(program.statements)
