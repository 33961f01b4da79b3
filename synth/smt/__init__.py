"""SMT backends: relation queries, exact Range values, and certification of whole programs.

Encoding (no atan2, no trigonometry in the formula): with v the offset between the two entities and u the
unit vector of the axis the relation names, "v within delta of u" is
    v.u > 0  and  (v.u)^2 >= cos^2(delta) |v|^2
over the exact rationals of the scene's floats. u and cos(delta) are the rationals of their correctly
rounded floats, the same constants the closed form uses (synth.geometry), so the two oracles answer the
same question. A distance Range [a, b] is encoded with d >= 0, d^2 = |v|^2, a <= d <= b: nonlinear real
arithmetic, exact in z3 (nlsat). dReal (optional) gets the same formula over doubles, delta-complete.

The modules:
  backend          the solver-backend protocol (SolverBackend, ExactBackend): the encoding primitives, and
                   what a backend asks of a part to measure Range values (Measured, MeasureRequest)
  z3_backend       z3, the default and the exact backend
  dreal_backend    dReal, optional, imported only when chosen
  measure          Range values, from exact arithmetic or one model
  certify          certification, plain and robust

Each statement part (synth.parts) builds its formulas from the backend's primitives, so a backend knows no
relation by name; the parts ask their own relation questions (Part.ask).
"""

from __future__ import annotations

from synth.config import SynthConfig
from synth.smt.backend import ExactBackend, Measurements, SolverBackend, SolverStats, SolverUnavailable
from synth.smt.dreal_backend import DrealBackend  # imports dreal itself only when one is made
from synth.smt.z3_backend import Z3Backend

__all__ = ["DrealBackend", "ExactBackend", "Measurements", "SolverBackend", "SolverStats", "SolverUnavailable",
           "Z3Backend", "make_backend"]


def make_backend(config: SynthConfig) -> SolverBackend:
    return DrealBackend(config) if config.solver == "dreal" else Z3Backend(config)
