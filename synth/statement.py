"""SynthesizeStatement (the paper's Alg. 4) for a chosen declaration order.

For each entity, in order, and each statement part: a witness relation to the nearest reference (ego or an
entity declared earlier) that has one, else the part's fallback relative to ego (cost 1). Ranges are centred on
the exact values the oracle's solver measures (closed form: on float geometry); for a part whose questions are
robust ones they widen to cover every scene within the measurement error (Part.robust_clause).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from synth.config import SynthConfig
from synth.dsl import Program, Statement
from synth.oracle import RelationOracle
from synth.parts import MeasureRequest, Want
from synth.robust import robust_parts
from synth.tables import NONE

Choice = tuple[int, int]  # (reference index, relation code or NONE for the fallback)


Distance = Callable[[int, int], float]  # (reference, target), oracle indices: how far apart they are


def choose_references(oracle: RelationOracle, order: tuple[int, ...],
                      distance: Distance | None = None) -> list[tuple[Choice, ...]]:
    """Per entity in order (oracle indices, 0 = ego): one (reference, code) per part of the oracle.

    A relation that needs no reference (Part.refless, found in ego's row) comes first; then references are
    tried nearest first (ties: lower index, ego being 0); with none, the fallback is ego. `distance`: centre
    distance in the oracle's scene by default (a window measures it in the frame its target is first seen in).
    """
    ents = oracle.entities()
    distance = distance or (lambda r, i: math.hypot(ents[r].x - ents[i].x, ents[r].y - ents[i].y))
    if oracle.complete:
        return _choose_from_table(oracle, order, distance)
    out = []
    available = [0]
    for i in order:
        refs = sorted(available, key=lambda r: (distance(r, i), r))
        row = []
        for k, part in enumerate(oracle.parts):
            if part.refless and (c := oracle.relation(k, 0, i)) in part.refless:
                row.append((0, c))
                continue
            row.append(next(((r, c) for r in refs if (c := oracle.relation(k, r, i)) != NONE), (0, NONE)))
        out.append(tuple(row))
        available.append(i)
    return out


def _choose_from_table(oracle: RelationOracle, order: tuple[int, ...], distance: Distance) -> list[tuple[Choice, ...]]:
    """choose_references when every pair is known: the nearest available witness is the least (distance, index)
    among the witnesses already declared, so only those are measured (not every declared entity, sorted)."""
    codes = [oracle.table[p.name] for p in oracle.parts]
    witnesses = [[np.flatnonzero(c[:, i] != NONE).tolist() for i in range(len(oracle.ids))] for c in codes]
    declared = {0}
    out = []
    for i in order:
        row = []
        for k, part in enumerate(oracle.parts):
            if part.refless and (c := int(codes[k][0, i])) in part.refless:
                row.append((0, c))
                continue
            refs = [r for r in witnesses[k][i] if r in declared]
            if not refs:
                row.append((0, NONE))
                continue
            r = min(refs, key=lambda r: (distance(r, i), r))
            row.append((r, int(codes[k][r, i])))
        out.append(tuple(row))
        declared.add(i)
    return out


def build_program(oracle: RelationOracle, order: tuple[int, ...], config: SynthConfig) -> Program:
    """The program Alg. 4 writes for `order` (oracle indices of the entities to declare, ego excluded)."""
    return Program(tuple(write_statements(oracle, order, choose_references(oracle, order), config)))


def write_statements(oracle: RelationOracle, order: tuple[int, ...], choices: list[tuple[Choice, ...]],
                     config: SynthConfig) -> list[Statement]:
    """Alg. 4's statements for `order` once its references are chosen (one (reference, code) per part and entity,
    oracle indices): each clause with its Ranges measured on the oracle's scene. A window (synth.window.program) chooses
    its references on the window's table and writes each frame's statements here."""
    ents = oracle.entities()
    parts = oracle.parts
    robust = robust_parts(oracle.scene, config, parts)
    # Plain parts' Ranges are centred on measured values: one request per statement, all answered at once.
    requests = [
        MeasureRequest(ents[i], tuple(Want(p, q, ents[r]) for p, (r, c) in zip(parts, row)
                                      if p.name not in robust and (q := p.quantity(c)) is not None))
        for i, row in zip(order, choices)
    ]
    if all(not req.wants for req in requests):
        measured = [()] * len(requests)
    elif oracle.backend is not None:
        measured = oracle.backend.measure(requests)
    else:
        measured = [tuple(w.part.float_measure(w.quantity, req.target, w.ref) for w in req.wants) for req in requests]
    statements = []
    for i, row, values in zip(order, choices, measured):
        e, values = ents[i], list(values)
        clauses = {}
        for part, (r, c) in zip(parts, row):
            if part.name in robust:
                clauses[part.name] = part.robust_clause(c, e, ents[r], config)
            else:
                clauses[part.name] = part.clause_for(c, e, ents[r], values.pop(0) if part.quantity(c) else (), config)
        statements.append(Statement(e.id, e.type, **clauses))
    return statements
