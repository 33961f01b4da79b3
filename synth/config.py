"""Synthesis configuration: the paper's four constants, the motion constants, and the choice of strategy, oracle
and solver."""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields, replace
from functools import cached_property
from typing import Any

from synth.errors import InputError
from synth.scene import MAX_HEADING_SIGMA, MAX_POS_SIGMA, MAX_SPEED_SIGMA

STRATEGIES = (
    "auto",
    "bfs",
    "bfs-cpa",
    "dfs",
    "dfs-bnb",
    "dfs-cpa",
    "dfs-bnb-cpa",
    "astar",
    "astar-cpa",
    "monolithic",
)
ORACLES = ("hybrid", "smt", "closed-form")
# The variant chain's (synth.variants.gibbs) defaults, here because `r2s sample --help` shows them and gibbs loads numpy.
DEFAULT_BURN_IN = 20  # sweeps from the recorded scene to the first variant
DEFAULT_THIN = 10  # sweeps between variants
SOLVERS = ("z3", "dreal")


class ConfigError(InputError, ValueError):
    """A configuration value is out of range or unknown. One line, fit for a user."""


@dataclass(frozen=True)
class SynthConfig:
    # Angular tolerance of ahead / behind / left / right (degrees, each side of the axis).
    delta1: float = 10.0
    # Angular tolerance of facing toward / away from (degrees).
    delta2: float = 5.0
    # Width of every distance / coordinate Range (metres) and of every heading Range (degrees).
    c_dist: float = 5.0
    c_head: float = 5.0
    strategy: str = "auto"
    oracle: str = "hybrid"
    solver: str = "z3"
    # Seconds of search before the anytime answer is returned; None = no limit.
    time_limit: float | None = None
    # Resident memory (MB) at which the search stops with status memout; None = no limit.
    memory_limit: float | None = None
    # dReal's delta (only used with solver = dreal).
    dreal_delta: float = 1e-3
    # Robust synthesis (`--uncertainty POS_M,HEAD_DEG`): every entity but ego may be anywhere within this many
    # metres of where it was recorded (a disc) and face anywhere within this many degrees of its heading; a
    # relation is used only where it holds for all of them, and every Range covers all of them. An entity's
    # own pos_sigma / heading_sigma overrides these. 0, 0 is plain synthesis, byte for byte.
    pos_uncertainty: float = 0.0
    heading_uncertainty: float = 0.0
    # Motion (beyond the paper; `--motion`): every statement also says how fast its entity moves, from each
    # entity's `speed` (m/s). stationary: speed <= v_stop; moving like REF: |speed - REF's| <= dv; speed Ranges
    # are c_speed wide. speed_uncertainty (m/s, the third number of --uncertainty) is the speed's measurement error.
    motion: bool = False
    v_stop: float = 0.5
    dv: float = 1.0
    c_speed: float = 2.0
    speed_uncertainty: float = 0.0
    # Lanes (beyond the paper; `--lanes`): every statement also says where its entity is on the recorded road
    # (the LANE part, synth.parts.lane), from the scene's road and each entity's lane facts.
    lanes: bool = False

    def __post_init__(self) -> None:
        for name in ("delta1", "delta2"):
            v = getattr(self, name)
            if not (_number(v) and 0.0 < v < 45.0):
                raise ConfigError(f"{name} must be a number in (0, 45) degrees, got {v!r}")
        # Ranges print with 2 decimals; a width under 0.02 could not stay centred on the observed value.
        for name in ("c_dist", "c_head"):
            v = getattr(self, name)
            if not (_number(v) and 0.02 <= v <= 1000.0):
                raise ConfigError(f"{name} must be a number in [0.02, 1000], got {v!r}")
        if not (_number(self.dreal_delta) and 0.0 < self.dreal_delta < 1.0):
            raise ConfigError(f"dreal_delta must be a number in (0, 1), got {self.dreal_delta!r}")
        for name in ("time_limit", "memory_limit"):
            v = getattr(self, name)
            if v is not None and not (_number(v) and v > 0.0):
                raise ConfigError(f"{name} must be a positive number of {'seconds' if 'time' in name else 'MB'}")
        if not (_number(self.pos_uncertainty) and 0.0 <= self.pos_uncertainty < MAX_POS_SIGMA):
            raise ConfigError(f"pos_uncertainty must be a number of metres in [0, {MAX_POS_SIGMA:g}), "
                              f"got {self.pos_uncertainty!r}")
        if not (_number(self.heading_uncertainty) and 0.0 <= self.heading_uncertainty < MAX_HEADING_SIGMA):
            raise ConfigError(f"heading_uncertainty must be a number of degrees in [0, {MAX_HEADING_SIGMA:g}), "
                              f"got {self.heading_uncertainty!r}")
        if not isinstance(self.motion, bool):
            raise ConfigError(f"motion must be true or false, got {self.motion!r}")
        for name, lo in (("v_stop", 0.0), ("dv", 0.0)):
            v = getattr(self, name)
            if not (_number(v) and lo <= v <= 100.0):
                raise ConfigError(f"{name} must be a number of m/s in [{lo:g}, 100], got {v!r}")
        if not (_number(self.c_speed) and 0.02 <= self.c_speed <= 1000.0):
            raise ConfigError(f"c_speed must be a number in [0.02, 1000], got {self.c_speed!r}")
        if not (_number(self.speed_uncertainty) and 0.0 <= self.speed_uncertainty < MAX_SPEED_SIGMA):
            raise ConfigError(f"speed_uncertainty must be a number of m/s in [0, {MAX_SPEED_SIGMA:g}), "
                              f"got {self.speed_uncertainty!r}")
        if not isinstance(self.lanes, bool):
            raise ConfigError(f"lanes must be true or false, got {self.lanes!r}")
        if self.speed_uncertainty and not self.motion:
            raise ConfigError("a speed uncertainty needs motion (--motion, or motion = true)")
        _one_of("strategy", self.strategy, STRATEGIES)
        _one_of("oracle", self.oracle, ORACLES)
        _one_of("solver", self.solver, SOLVERS)
        if self.strategy == "monolithic" and self.solver != "z3":
            # The baseline is one z3 Optimize problem; dReal has no optimiser, and answering with z3 under the
            # name of dReal would misreport which solver a benchmark measured.
            raise ConfigError("strategy monolithic is one z3 optimisation problem: use it with --solver z3")

    def with_(self, **changes: Any) -> SynthConfig:
        """A copy with the given fields changed; None values leave a field as it is."""
        return replace(self, **{k: v for k, v in changes.items() if v is not None})

    @cached_property
    def hash(self) -> str:
        """semantic_hash(), computed once per value: what a programs row records as its config_hash."""
        return self.semantic_hash()

    def semantic_hash(self) -> str:
        """Hash of what decides the program: constants, strategy, oracle, solver, limits.

        Two runs with the same hash on the same frame produce the same row, so the pipeline may skip one.
        The uncertainty fields enter only when non-zero, and the motion fields only with motion on: plain static
        synthesis keeps the hashes it always had, so programs.parquet files written before robust synthesis,
        motion or lanes existed still resume.
        """
        # 10 in a TOML file and 10.0 on the command line are one setting: hash numbers as floats.
        values = {k: float(v) if isinstance(v, int) and not isinstance(v, bool) else v
                  for k, v in asdict(self).items()}
        for name in ("pos_uncertainty", "heading_uncertainty", "speed_uncertainty"):
            if values[name] == 0.0:
                del values[name]
        if not self.motion:
            for name in MOTION_FIELDS:
                values.pop(name, None)
        if not self.lanes:
            values.pop("lanes")
        import hashlib  # here, not at the top: `import synth` (which loads this module) stays light

        blob = json.dumps(values, sort_keys=True).encode()
        return hashlib.sha256(blob).hexdigest()[:16]


MOTION_FIELDS = ("motion", "v_stop", "dv", "c_speed", "speed_uncertainty")


def _number(v: Any) -> bool:
    """A finite number: true and false are not numbers (TOML `delta1 = true`), nor is an integer beyond floats."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(v)
    except OverflowError:  # an int of 400 digits
        return False


UNCERTAINTY_FIELDS = ("pos_uncertainty", "heading_uncertainty", "speed_uncertainty")


def parse_uncertainty(text: str) -> tuple[float, ...]:
    """`POS_M,HEAD_DEG[,SPEED_MPS]` (as `--uncertainty` takes it) -> (metres, degrees[, m/s]), as many numbers as
    given (UNCERTAINTY_FIELDS in order); ConfigError when it is not that."""
    parts = str(text).split(",")
    usage = f"uncertainty must be POS_M,HEAD_DEG or POS_M,HEAD_DEG,SPEED_MPS (two or three numbers), got {text!r}"
    if len(parts) not in (2, 3):
        raise ConfigError(usage)
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise ConfigError(usage) from None
    # The one range check, at parse time (a speed bound is checked as if motion were on: --motion may come later).
    SynthConfig(**dict(zip(UNCERTAINTY_FIELDS, values)), motion=len(values) == 3)
    return values


def _one_of(name: str, value: Any, allowed: tuple[str, ...]) -> None:
    if value not in allowed:
        raise ConfigError(f"unknown {name} {value!r} (choose from {', '.join(allowed)})")


def as_config(value: SynthConfig | Mapping[str, Any] | None) -> SynthConfig:
    """The configuration the Python API was given: a SynthConfig as it is, a dict of its fields (or a decoded TOML
    document with a [synth] table) through config_from_mapping, None as the defaults."""
    if value is None:
        return SynthConfig()
    if isinstance(value, SynthConfig):
        return value
    if isinstance(value, Mapping):
        return config_from_mapping(value)
    raise TypeError(f"a configuration is a SynthConfig or a dict of its fields, not {type(value).__name__}")


def config_from_mapping(raw: Mapping[str, Any], base: SynthConfig | None = None) -> SynthConfig:
    """A config from a decoded TOML table ([synth] section or flat); unknown keys are refused."""
    table = raw.get("synth", raw)
    if not isinstance(table, Mapping):
        raise ConfigError("the [synth] section must be a table")
    known = {f.name for f in fields(SynthConfig)}
    unknown = sorted(set(table) - known)
    if unknown:
        import difflib

        close = difflib.get_close_matches(str(unknown[0]), known, n=1)
        hint = f"; did you mean {close[0]!r}?" if close else ""
        raise ConfigError(f"unknown config key(s): {', '.join(map(str, unknown))}{hint} "
                          f"(known: {', '.join(sorted(known))})")
    return replace(base or SynthConfig(), **dict(table))
