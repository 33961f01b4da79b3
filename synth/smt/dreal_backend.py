"""dReal 4 (delta-complete, the paper's solver): the same encoding over doubles. Optional: imported only when
chosen (`--solver dreal`); its PyPI wheel needs the system library libibex.

Where libibex comes from: dReal's own installer puts it in /opt/libibex/2.7.4/lib, which the wheel's RUNPATH
names, so `import dreal` just works there. `make dreal` builds it into a cache directory instead and writes that
library's absolute path into the venv (LIBIBEX_MARKER); load_dreal loads it from there (RTLD_GLOBAL) before
importing dreal, and the dynamic linker then takes the loaded library for the wheel's `libibex.so` (its SONAME),
so nobody sets LD_LIBRARY_PATH.
"""

from __future__ import annotations

import ctypes
import importlib
import sys
import time
from dataclasses import dataclass
from fractions import Fraction
from functools import cached_property
from pathlib import Path
from typing import Any

from synth.geometry import exact_cos_squared, exact_heading_vector
from synth.scene import Entity
from synth.smt.backend import ExactBackend, Formula, Measurements, MeasureRequest, SolverBackend, SolverUnavailable
from synth.smt.z3_backend import Z3Backend

# The file in the venv (sys.prefix) naming libibex.so by absolute path; tools/dreal.sh writes it.
LIBIBEX_MARKER = "r2sgen-libibex"


def load_dreal() -> Any:
    """The dreal module, with the libibex of `make dreal` loaded first where there is one.

    Raises SolverUnavailable (one line, fit for a user) where dReal cannot be loaded."""
    if "dreal" in sys.modules:  # loaded already: its libibex too
        return sys.modules["dreal"]
    marker = Path(sys.prefix) / LIBIBEX_MARKER
    try:
        libibex = marker.read_text().strip()
    except OSError:  # no `make dreal` here: a system install (dReal's own installer) may still serve
        libibex = None
    try:
        if libibex:
            ctypes.CDLL(libibex, mode=ctypes.RTLD_GLOBAL)
        return importlib.import_module("dreal")
    except (ImportError, OSError) as exc:
        raise SolverUnavailable(
            f"dReal cannot be loaded here ({exc}); it needs the system library libibex: run `make dreal`, "
            "or use --solver z3") from None


@dataclass
class DrealBackend(SolverBackend):
    """dReal as a backend: where its wheel cannot load, making one raises SolverUnavailable."""

    def __post_init__(self) -> None:
        dreal = self.dreal = load_dreal()
        self.And, self.Or, self.Not = dreal.And, dreal.Or, dreal.Not
        self._fresh = 0

    @cached_property
    def exact(self) -> ExactBackend:
        # dReal is delta-complete: it can confirm the delta-weakening of a formula, not refute it exactly. Robust
        # questions (about every point of a disc) and certification rest on z3, the solver of record for
        # exactness: one per frame, made on first use, counting into this backend's stats.
        return Z3Backend(self.config, self.stats)

    # --------------------------------------------------------------------------------- encoding primitives
    def constant(self, v: float | str | Fraction) -> float:
        return float(v)

    def var(self, stem: str) -> Any:
        self._fresh += 1
        return self.dreal.Variable(f"{stem}{self._fresh}")

    def offset(self, ref: Entity, e: Entity) -> tuple[float, float]:
        return e.x - ref.x, e.y - ref.y

    def cone(self, vx: Any, vy: Any, axis_heading: float, delta: float) -> Formula:
        ux, uy = (float(c) for c in exact_heading_vector(axis_heading))
        dot = vx * ux + vy * uy
        cos_sq = float(exact_cos_squared(delta))
        # Constants only: dReal still decides the (ground) formula, as the paper has it do.
        z = self.var("z")
        return self.dreal.And(z == dot, z > 0, z * z >= cos_sq * (vx * vx + vy * vy))

    def distance_in(self, vx: Any, vy: Any, lo: Any, hi: Any) -> Formula:
        d = self.var("d")
        return self.dreal.And(d >= 0, d * d == vx * vx + vy * vy, lo <= d, d <= hi)

    # --------------------------------------------------------------------------------- deciding
    def _satisfying_box(self, formula: Formula) -> Any:
        """A box of values delta-satisfying the formula, or None (unsat)."""
        started = time.perf_counter()
        box = self.dreal.CheckSatisfiability(formula, self.config.dreal_delta)
        self.stats.record(1, started)
        return box

    def check(self, *constraints: Formula) -> bool:
        formula = self.dreal.And(*constraints) if len(constraints) > 1 else constraints[0]
        return self._satisfying_box(formula) is not None

    def distance_value(self, vx: float, vy: float) -> Fraction:
        """|v|, the midpoint of dReal's box (Part.solver_measure)."""
        d = self.var("d")
        box = self._satisfying_box(self.dreal.And(d >= 0, d * d == vx * vx + vy * vy))
        if box is None:
            raise RuntimeError("dReal found no distance")
        return Fraction(box[d].mid())

    # --------------------------------------------------------------------------------- Range values
    def measure(self, requests: list[MeasureRequest]) -> Measurements:
        return [tuple(w.part.solver_measure(self, w.quantity, req.target, w.ref) for w in req.wants)
                for req in requests]
