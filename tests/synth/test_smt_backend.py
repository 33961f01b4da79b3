"""The solver-backend protocol (synth.smt.backend): parts use nothing of a backend but what it declares."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import pytest

import synth.parts
from synth.config import SynthConfig
from synth.smt.backend import ExactBackend, SolverBackend
from synth.smt.z3_backend import Z3Backend

PARTS = Path(synth.parts.__file__).parent


def _members(cls: type) -> set[str]:
    names = set(dir(cls))
    for klass in cls.__mro__:
        names |= set(getattr(klass, "__annotations__", {}))
    return names


def _backend_uses() -> list[tuple[str, str, str]]:
    """(function, the protocol its `backend` parameter is annotated with, attribute) for every backend.X in the parts."""
    uses = []
    for path in sorted(PARTS.glob("*.py")):
        for fn in ast.walk(ast.parse(path.read_text())):
            if not isinstance(fn, ast.FunctionDef):
                continue
            arg = next((a for a in fn.args.args if a.arg == "backend"), None)
            if arg is None:
                continue
            protocol = ast.unparse(arg.annotation) if arg.annotation is not None else "missing"
            uses += [(f"{path.name}:{fn.name}", protocol, node.attr) for node in ast.walk(fn)
                     if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "backend"]
    return uses


def test_parts_ask_a_backend_only_for_what_its_protocol_declares():
    protocols = {"SolverBackend": _members(SolverBackend), "ExactBackend": _members(ExactBackend)}
    uses = _backend_uses()
    assert len(uses) > 50  # the parts' SMT methods were found
    assert {protocol for _, protocol, _ in uses} == set(protocols)
    assert [u for u in uses if u[2] not in protocols[u[1]]] == []


def test_every_abstract_primitive_is_documented_and_z3_implements_the_exact_protocol():
    backend = Z3Backend(SynthConfig())
    assert isinstance(backend, ExactBackend) and backend.exact is backend
    for name in sorted(ExactBackend.__abstractmethods__ | SolverBackend.__abstractmethods__):
        assert inspect.getdoc(getattr(ExactBackend, name)), name


@pytest.mark.parametrize("vx,vy", [(3.0, 4.0), (1.0, 1.0), (-0.1, 7.25)])
def test_z3_distance_value_is_the_exact_length(vx, vy):
    from fractions import Fraction

    from synth.geometry import sqrt_rational

    d = Z3Backend(SynthConfig()).distance_value(vx, vy)
    exact = sqrt_rational(Fraction(vx) ** 2 + Fraction(vy) ** 2)
    assert abs(d - exact) < Fraction(1, 10**11)
