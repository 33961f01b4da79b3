"""SynthesizeStatement (the paper's Alg. 4) for a chosen declaration order.

For each entity, in order: its type from the scene; a direction relation to the nearest reference (ego or an
entity declared earlier) that has one, else `on Range @ Range relative to ego` (cost 1); a facing relation to
the nearest reference that has one, else `facing Range deg relative to ego` (cost 1). Ranges are centred on the
exact values the oracle's solver measures (closed form: on float geometry); in robust synthesis they widen to
cover every scene within the measurement error (synth.robust).
"""

from __future__ import annotations

import math
from fractions import Fraction

from synth.config import SynthConfig
from synth.dsl import DirectionPos, FacingRelation, LocalXYPos, Program, RelativeHeading, Statement
from synth.geometry import signed, to_local
from synth.oracle import RelationOracle
from synth.ranges import centred
from synth.relations import DIRECTION_NAMES, FACING_NAMES, NONE
from synth.robust import angle_range, bounds_of, distance_range, is_robust, local_ranges, radius_of
from synth.smt import Measurement, MeasureRequest


def choose_references(oracle: RelationOracle, order: tuple[int, ...]) -> list[tuple[int, int, int, int]]:
    """Per entity in order (oracle indices, 0 = ego): (pos ref, direction code or NONE, head ref, facing code or NONE).

    References are tried nearest first (ties: lower index, ego being 0); with none, the fallback is ego.
    """
    ents = oracle.entities()
    out = []
    available = [0]
    for i in order:
        e = ents[i]
        refs = sorted(available, key=lambda r: (math.hypot(ents[r].x - e.x, ents[r].y - e.y), r))
        pos = next(((r, c) for r in refs if (c := oracle.position(r, i)) != NONE), (0, NONE))
        head = next(((r, c) for r in refs if (c := oracle.heading(r, i)) != NONE), (0, NONE))
        out.append((pos[0], pos[1], head[0], head[1]))
        available.append(i)
    return out


def _float_measure(req: MeasureRequest) -> Measurement:
    """Closed-form measurement: float geometry only."""
    vals: dict[str, Fraction] = {}
    if req.position_kind == "direction":
        vals["distance"] = Fraction(math.hypot(req.target.x - req.position_ref.x, req.target.y - req.position_ref.y))
    elif req.position_kind == "local":
        lx, ly = to_local(req.target.x - req.position_ref.x, req.target.y - req.position_ref.y, req.position_ref.heading)
        vals["lateral"], vals["forward"] = Fraction(lx), Fraction(ly)
    if req.heading_kind == "relative":
        vals["angle"] = Fraction(signed(req.target.heading - req.heading_ref.heading))
    return Measurement(**vals)


def build_program(oracle: RelationOracle, order: tuple[int, ...], config: SynthConfig) -> Program:
    """The program Alg. 4 writes for `order` (oracle indices of the entities to declare, ego excluded)."""
    ents = oracle.entities()
    choices = choose_references(oracle, order)
    requests = [
        MeasureRequest(
            target=ents[i],
            position_ref=ents[pr],
            position_kind="direction" if pc != NONE else "local",
            heading_ref=ents[hr],
            heading_kind="facing" if hc != NONE else "relative",
        )
        for i, (pr, pc, hr, hc) in zip(order, choices)
    ]
    robust = is_robust(oracle.scene, config)
    if robust:
        # Robust Ranges come from exact rationals, widened over every perturbation (synth.robust).
        measured = [None] * len(requests)
    elif oracle.backend is not None:
        measured = oracle.backend.measure(requests)
    else:
        measured = [_float_measure(r) for r in requests]
    statements = []
    for i, (pr, pc, hr, hc), m in zip(order, choices, measured):
        e, p, h = ents[i], ents[pr], ents[hr]
        if pc != NONE:
            distance = (distance_range(e, p, radius_of(e, p, config), config.c_dist) if robust
                        else centred(m.distance, config.c_dist, True))
            position = DirectionPos(DIRECTION_NAMES[pc], p.id, distance)
        elif robust:
            lateral, forward = local_ranges(e, p, radius_of(e, p, config), bounds_of(p, config).heading, config.c_dist)
            position = LocalXYPos(lateral, forward, p.id)
        else:
            position = LocalXYPos(centred(m.lateral, config.c_dist), centred(m.forward, config.c_dist), p.id)
        if hc != NONE:
            heading = FacingRelation(FACING_NAMES[hc], h.id)
        elif robust:
            angle = angle_range(e, h, bounds_of(e, config).heading, bounds_of(h, config).heading, config.c_head)
            heading = RelativeHeading(angle, h.id)
        else:
            heading = RelativeHeading(centred(m.angle, config.c_head), h.id)
        statements.append(Statement(e.id, e.type, position, heading))
    return Program(tuple(statements))
