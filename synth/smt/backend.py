"""The solver-backend protocol: what a statement part builds formulas from.

Two levels, one interface. Every backend (z3, dReal) offers the encoding primitives a part's plain relation
question needs (constant, var, offset, cone, distance_in, And, Or, Not, check) and measures Range values (from
the parts' Measured answers). Robust questions, certification and Range values read from a model need exact
rational arithmetic: an ExactBackend (z3) adds those primitives, and every backend names the exact backend it
hands them to (`exact`: itself for z3, one z3 made on first use for dReal, which is delta-complete only).

This module knows no part and no program: the parts build on it (synth.parts), and the questions that need
them live above it (Part.ask, synth.smt.certify).
"""

from __future__ import annotations

import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Any, ClassVar

from synth.config import SynthConfig
from synth.errors import InputError
from synth.scene import Entity

Formula = Any  # a term of the backend at hand

# What a backend measures for a program: per statement, per wanted quantity, its exact values.
Measurements = list[tuple[tuple[Fraction, ...], ...]]


class Measured(ABC):
    """What a backend asks of a statement part to measure the quantity its Ranges are centred on (synth.parts
    implement it; a Want names the part, the quantity and the reference)."""

    @abstractmethod
    def measure_terms(self, backend: ExactBackend, quantity: str, target: Entity, ref: Entity) -> tuple[list, list]:
        """(constraints, variables) whose unique model values are the exact quantity."""

    @abstractmethod
    def exact_measure(self, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...] | None:
        """The quantity measure_terms pins down, without the solver, for centring Ranges: the exact value
        (irrational ones to within 1e-15, as the solver's model gives them to 1e-12), or one that centres every
        Range as it does (intervals.centring_value); None leaves it to the solver."""

    @abstractmethod
    def solver_measure(self, backend: SolverBackend, quantity: str, target: Entity, ref: Entity) -> tuple[Fraction, ...]:
        """The quantity as a solver without models of its own measures it (dReal)."""


@dataclass(frozen=True)
class Want:
    """One quantity a statement's Ranges are centred on: which part, what, relative to which reference."""

    part: Measured
    quantity: str
    ref: Entity


@dataclass(frozen=True)
class MeasureRequest:
    """What to measure for one statement (a solver answers all statements of a program from one model)."""

    target: Entity
    wants: tuple[Want, ...]


class SolverUnavailable(InputError, RuntimeError):
    """The chosen solver cannot be loaded here. One line, fit for a user."""


@dataclass
class SolverStats:
    queries: int = 0
    seconds: float = 0.0

    def record(self, queries: int, started: float) -> None:
        """Count `queries` and the time since `started` (time.perf_counter)."""
        self.queries += queries
        self.seconds += time.perf_counter() - started


def as_fraction(v: float | str | Fraction) -> Fraction:
    return v if isinstance(v, Fraction) else Fraction(v)


@dataclass
class SolverBackend(ABC):
    """A solver as parts encode for it and as the core asks it for Range values (synth.statement)."""

    config: SynthConfig
    stats: SolverStats = field(default_factory=SolverStats)
    # The connectives of the backend's formulas (its own, so that parts stay solver-neutral): each backend sets them.
    And: ClassVar[Any]
    Or: ClassVar[Any]
    Not: ClassVar[Any]

    # ------------------------------------------------------------------------------- encoding primitives
    @abstractmethod
    def constant(self, v: float | str | Fraction) -> Any:
        """The number v as a term (the exact rational of a float for z3)."""

    @abstractmethod
    def var(self, stem: str) -> Any:
        """A fresh real variable."""

    @abstractmethod
    def offset(self, ref: Entity, e: Entity) -> tuple[Any, Any]:
        """The offset p_e - p_ref as two terms."""

    @abstractmethod
    def cone(self, vx: Any, vy: Any, axis_heading: float, delta: float) -> Formula:
        """v lies within delta degrees of the axis (v.u > 0 and (v.u)^2 >= cos^2(delta) |v|^2)."""

    @abstractmethod
    def distance_in(self, vx: Any, vy: Any, lo: Any, hi: Any) -> Formula:
        """lo <= |v| <= hi."""

    @abstractmethod
    def check(self, *constraints: Formula) -> bool:
        """Are the constraints satisfiable together (one query)?"""

    @abstractmethod
    def distance_value(self, vx: float, vy: float) -> Fraction:
        """|v| as this solver measures it (Measured.solver_measure; one query)."""

    # ------------------------------------------------------------------------------- the exact backend
    @property
    @abstractmethod
    def exact(self) -> ExactBackend:
        """The backend that decides robust questions, certifies programs and measures from models."""

    # ------------------------------------------------------------------------------- Range values
    @abstractmethod
    def measure(self, requests: list[MeasureRequest]) -> Measurements:
        """The exact quantities the Ranges of many statements are centred on."""


class ExactBackend(SolverBackend):
    """A backend deciding exactly over the rationals: robust (quantified) questions, certification, models."""

    @property
    def exact(self) -> ExactBackend:
        return self

    @abstractmethod
    def angle_in(self, heading: float, base: float, lo: Fraction, hi: Fraction) -> Formula:
        """heading = N(base + alpha) for some alpha in [lo, hi]."""

    @abstractmethod
    def perturbed_offset(self, c: tuple[Fraction, Fraction], radius: Fraction) -> tuple[Any, Any, list[Formula]]:
        """The offset c moved anywhere in the disc of the given radius: (vx, vy, the disc's constraints)."""

    @abstractmethod
    def cone_fails(self, vx: Any, vy: Any, cons: list[Formula], axis: float, cone: float | None) -> Formula:
        """Some v (under cons) outside the cone; no cone left at all (None) always fails."""

    @abstractmethod
    def robust_cone(self, c: tuple[Fraction, Fraction], radius: Fraction, axis: float, cone: float | None) -> bool:
        """Does every v in the disc D(c, radius) lie within `cone` degrees of the axis?"""

    @abstractmethod
    def check_quantified(self, *constraints: Formula) -> bool:
        """check() for a question about every perturbation (its violation), where the solver needs its complete
        procedure; one query."""

    @abstractmethod
    def check_together(self, formulas: list[Formula], started: float) -> bool:
        """Do all the formulas hold at once? Counted as one query per formula, timed from `started`."""

    @abstractmethod
    def model_values(self, constraints: list[Formula], variables: list[Any], queries: int,
                     started: float) -> list[Fraction]:
        """The values of the variables in a model of the constraints (each pinned to one value by them),
        counted as `queries` queries timed from `started`."""
