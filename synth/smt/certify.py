"""Certification: does a program, as printed, hold on its scene (and for every perturbation, where robust)?"""

from __future__ import annotations

import time

from synth.dsl import Program, Statement
from synth.parts import Clause, Part
from synth.robust import robust_parts
from synth.scene import Entity, Scene
from synth.smt.backend import ExactBackend, Formula, SolverBackend


def certify(backend: SolverBackend, program: Program, scene: Scene) -> list[str]:
    """Ids of the statements that cannot be shown to hold on the scene (empty: certified), decided by the
    backend's exact backend (backend.exact: z3).

    Plain parts, in the paper's all-SMT mode (oracle smt): the solver checks the whole program at once, and only
    when that fails is each statement asked alone, to name it. Otherwise each clause is first decided by rigorous
    interval arithmetic (Clause.decide, synth.intervals): a clause it proves holds needs nothing more, one it
    refutes fails, and the clauses it cannot decide (within rounding of a boundary) go to the solver, statement
    by statement. Robust parts: each clause's violations over every perturbation must be unsat.
    """
    backend = backend.exact
    config = backend.config
    robust = robust_parts(scene, config)
    by_id = scene.by_id()
    failed: set[str] = set()
    plain = [st for st in program.statements if any(p.name not in robust for p, _ in st.clauses())]
    if plain and config.oracle == "smt":
        started = time.perf_counter()  # building the formulas is solver work too: it is counted
        formulas = [statement_formula(backend, st, by_id, robust) for st in plain]
        if not backend.check_together(formulas, started):
            failed |= {st.id for st, f in zip(plain, formulas) if not backend.check(f)}
    elif plain:
        failed |= {st.id for st in plain if not _decided_or_checked(backend, st, by_id, robust)}
    if robust:
        failed |= {st.id for st in program.statements if not robust_holds(backend, st, by_id, robust)}
    return [st.id for st in program.statements if st.id in failed]


def _clauses_with_refs(st: Statement, by_id: dict[str, Entity]) -> list[tuple[Part, Clause, Entity | None]]:
    return [(part, clause, by_id[clause.ref] if clause.ref is not None else None) for part, clause in st.clauses()]


def statement_formula(backend: ExactBackend, st: Statement, by_id: dict[str, Entity],
                      skip: frozenset[str] = frozenset()) -> Formula:
    """The statement's semantics on the scene, as printed (Range bounds at their printed values); the parts named
    in `skip` are left out (certified robustly instead)."""
    e = by_id[st.id]
    return backend.And(*(clause.formula(backend, e, ref) for part, clause, ref in _clauses_with_refs(st, by_id)
                         if part.name not in skip))


def _decided_or_checked(backend: ExactBackend, st: Statement, by_id: dict[str, Entity], skip: frozenset[str]) -> bool:
    """Does the statement hold? Intervals first, the solver for the clauses they leave undecided."""
    e = by_id[st.id]
    left = []
    for part, clause, ref in _clauses_with_refs(st, by_id):
        if part.name in skip:
            continue
        fact = clause.decide(e, ref, backend.config)
        if fact is False:
            return False
        if fact is None:
            left.append(clause.formula(backend, e, ref))
    return not left or backend.check(*left)


def robust_violations(backend: ExactBackend, st: Statement, by_id: dict[str, Entity],
                      parts: frozenset[str] | None = None) -> list[Formula]:
    """Ways `st` (as printed) could fail under a perturbation of the scene within its bounds: the statement fails
    for some perturbation iff one of these is satisfiable (each clause's, Clause.violations)."""
    e = by_id[st.id]
    return [f for part, clause, ref in _clauses_with_refs(st, by_id) if parts is None or part.name in parts
            for f in clause.violations(backend, e, ref)]


def robust_holds(backend: ExactBackend, st: Statement, by_id: dict[str, Entity],
                 parts: frozenset[str] | None = None) -> bool:
    """Is every violation of `st` (of the named parts; default all) unsat?"""
    return not any(backend.check_quantified(f) for f in robust_violations(backend, st, by_id, parts))
