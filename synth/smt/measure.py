"""Range values: the exact quantities a program's Ranges are centred on, from exact arithmetic or a model."""

from __future__ import annotations

import time

from synth.smt.backend import ExactBackend, Measurements, MeasureRequest


def measure(backend: ExactBackend, requests: list[MeasureRequest]) -> Measurements:
    """The paper's all-SMT mode (oracle smt) reads them all from one model of the solver; otherwise each part
    computes its ground quantities in exact arithmetic (Measured.exact_measure), and only those it leaves go to the
    solver, from one model.
    """
    if backend.config.oracle == "smt":
        return model_measure(backend, requests)
    exact = [tuple(w.part.exact_measure(w.quantity, req.target, w.ref) for w in req.wants) for req in requests]
    left = [i for i, values in enumerate(exact) if any(v is None for v in values)]
    for i, values in zip(left, model_measure(backend, [requests[i] for i in left])):
        exact[i] = values
    return exact


def model_measure(backend: ExactBackend, requests: list[MeasureRequest]) -> Measurements:
    """Every wanted quantity of every request from one model (each is pinned to one value by its terms)."""
    if not requests:
        return []
    started = time.perf_counter()  # building the terms is solver work too: it is counted
    constraints, variables, shapes = [], [], []
    for req in requests:
        shape = []
        for want in req.wants:
            terms, wanted = want.part.measure_terms(backend, want.quantity, req.target, want.ref)
            constraints += terms
            variables += wanted
            shape.append(len(wanted))
        shapes.append(shape)
    values = iter(backend.model_values(constraints, variables, len(requests), started))
    return [tuple(tuple(next(values) for _ in range(size)) for size in shape) for shape in shapes]
