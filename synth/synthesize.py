"""ConstraintSolvingBasedSynthesizer (the paper's Alg. 1): one scene in, a minimum-cost program out.

`synthesize` is the Python API's entry point (`from synth import synthesize`, docs/api.md). The package exports it
under this module's own name, so this module is imported whenever `synth` is: it loads only the scene and config
modules, and the core (DSL, oracles, solver, search, Scenic) on the first call.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from synth.config import SynthConfig, as_config
from synth.errors import InternalError
from synth.scene import Scene, SceneError, as_scene
from synth.version import __version__

if TYPE_CHECKING:
    from synth.dsl import Program


@dataclass(frozen=True)
class SynthStats:
    """Where the time and memory of one synthesis went (the `stats` of `r2s synth --format json`)."""

    runtime_s: float
    search_s: float
    smt_s: float
    smt_queries: int
    nodes_expanded: int
    peak_rss_mb: float
    # Where runtime_s went, stage by stage (not in the JSON document or programs.parquet): the relation oracle
    # (every pair's witness relations), Alg. 4 (references and Range values), certification of the printed
    # program, Scenic rendering. smt_s is the solver's share of the first three.
    oracle_s: float = 0.0
    ranges_s: float = 0.0
    certify_s: float = 0.0
    render_s: float = 0.0

    @classmethod
    def since(cls, started: float, smt: list, nodes_expanded: int, search_s: float, oracle_s: float, ranges_s: float,
              certify_s: float, render_s: float) -> SynthStats:
        """The stats of a synthesis that started at `started` (perf_counter), its solvers' stats summed (`smt`:
        one per solver backend asked, a window's frames each have one)."""
        from synth.search.budget import peak_rss_mb

        return cls(runtime_s=time.perf_counter() - started, search_s=search_s, smt_s=sum(s.seconds for s in smt),
                   smt_queries=sum(s.queries for s in smt), nodes_expanded=nodes_expanded, peak_rss_mb=peak_rss_mb(),
                   oracle_s=oracle_s, ranges_s=ranges_s, certify_s=certify_s, render_s=render_s)


@dataclass(frozen=True)
class ResultField:
    """One field of a synthesis result as the outputs carry it (docs/formats.md): a key of the `r2s synth --format
    json` document and a column of programs Parquet, in this order."""

    name: str
    type: str  # its Parquet type: string, int32, int64, float64, bool
    # Where a result's value is: "result" (a SynthResult field; the program as its DSL text), "stats" (a SynthStats
    # field; the JSON nests these under "stats"), "config" (a SynthConfig field) or "run" (the batch stage's own:
    # Parquet only).
    source: str


# The one declaration of the result fields: SynthResult.to_json_dict, pipeline.programs' rows and schema read it.
# By source, each as name:Parquet type, in contract order (docs/formats.md says what each means).
RESULT_FIELDS: tuple[ResultField, ...] = tuple(ResultField(name, type_, source) for source, spec in (
    ("result", "frame_id:string status:string cost:int32 lower_bound:int32 n_entities:int32 program:string "
               "scenic:string certified:bool"),
    ("config", "strategy:string oracle:string solver:string"),
    ("stats", "runtime_s:float64 search_s:float64 smt_s:float64 smt_queries:int64 nodes_expanded:int64 "
              "peak_rss_mb:float64"),
    ("run", "error:string config_hash:string version:string frame_hash:string"),
) for name, type_ in (field.split(":") for field in spec.split()))


@dataclass(frozen=True)
class SynthResult:
    """The program synthesized for one scene, with its cost, status and certificate (docs/dsl.md, "What synthesis
    returns"). `str(result.program)` is the DSL text, `result.scenic` the Scenic text, `to_json_dict()` the
    `r2s synth --format json` document."""

    frame_id: str
    status: str  # optimal | feasible | timeout | memout
    cost: int
    lower_bound: int
    n_entities: int  # entities declared (ego excluded)
    program: Program
    scenic: str
    certified: bool
    stats: SynthStats
    config: SynthConfig

    def value(self, result_field: ResultField) -> Any:
        """The value of a result field that is not the batch stage's own (RESULT_FIELDS)."""
        holder = {"result": self, "stats": self.stats, "config": self.config}[result_field.source]
        value = getattr(holder, result_field.name)
        return str(value) if result_field.name == "program" else value

    def to_json_dict(self) -> dict:
        """The `r2s synth --format json` document (docs/formats.md): the result's fields, then its stats."""
        return {**{f.name: self.value(f) for f in RESULT_FIELDS if f.source == "result"},
                "stats": {f.name: self.value(f) for f in RESULT_FIELDS if f.source == "stats"}}


class SpeedMissing(SceneError):
    """Motion was asked for a scene with an entity whose speed is unknown. One line naming the entity."""


def require_speeds(scene: Scene) -> None:
    """Motion describes every entity's speed, ego's too: refuse a scene where one is not known."""
    missing = [e.id for e in scene.entities if e.speed is None]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise SpeedMissing(f"entity {missing[0]!r}{more} has no speed, which motion (--motion) needs")


class CertificationError(InternalError, RuntimeError):
    """The solver could not confirm a statement of the synthesized program: an internal error, never silent."""


def synthesize(scene: Scene | Mapping[str, Any], config: SynthConfig | Mapping[str, Any] | None = None) -> SynthResult:
    """A minimum-cost program whose semantics contain `scene` (docs/dsl.md).

    `scene`: a Scene, or a decoded scene JSON document (a dict, validated as scene_from_dict validates it).
    `config`: a SynthConfig, a dict of its fields (or {"synth": {...}}, as a TOML file decodes), or None for the
    defaults. Bad input raises SceneError / ConfigError (ValueErrors with one-line messages); with motion, a scene
    entity without a speed raises SpeedMissing; with lanes, a scene without a road (or an entity without lane facts)
    raises LanesMissing. A program the solver cannot certify raises CertificationError (a
    bug, never a silent result). Deterministic: the same scene and config give the same program and Scenic text.
    """
    from synth.dsl import fmt_number
    from synth.oracle import make_oracle
    from synth.parts import MOTION
    from synth.robust import is_robust
    from synth.scenic.emit import render_scenic
    from synth.search import Budget, CostModel, search
    from synth.smt.certify import certify
    from synth.statement import build_program

    scene = as_scene(scene)
    config = as_config(config)
    if config.motion:
        require_speeds(scene)
    if config.lanes:
        from synth.parts.lane import require_lanes

        require_lanes(scene)
    started = time.perf_counter()
    budget = Budget(config.time_limit, config.memory_limit)
    oracle = make_oracle(scene, config)
    if config.strategy == "auto":
        oracle.full_table()
    cost_model = CostModel(oracle)
    t = time.perf_counter()
    oracle_s = t - started
    found = search(config.strategy, cost_model, budget)
    search_s = time.perf_counter() - t
    t = time.perf_counter()
    # Search indices are oracle indices minus one (oracle index 0 is ego).
    program = build_program(oracle, tuple(i + 1 for i in found.order), config)
    if program.cost != found.cost:
        raise AssertionError(f"program cost {program.cost} differs from the search's {found.cost}")
    ranges_s = time.perf_counter() - t
    t = time.perf_counter()
    certified = False
    if oracle.backend is not None:
        failed = certify(oracle.backend, program, scene)
        if failed:
            raise CertificationError(f"the solver refutes the statements of {', '.join(failed)}")
        certified = True
    certify_s = time.perf_counter() - t
    t = time.perf_counter()
    header = f"frame {scene.frame_id}: cost {program.cost} ({found.status}), r2sgen {__version__}"
    if is_robust(scene, config):
        speed = f", {fmt_number(config.speed_uncertainty)} m/s" if MOTION.is_robust(scene, config) else ""
        header += (f"; robust to {fmt_number(config.pos_uncertainty)} m, {fmt_number(config.heading_uncertainty)} deg"
                   f"{speed} (entities' own sigmas override)")
    scenic = render_scenic(program, scene, config, header=header)
    render_s = time.perf_counter() - t
    stats = oracle.backend.stats if oracle.backend is not None else None
    return SynthResult(
        frame_id=scene.frame_id,
        status=found.status,
        cost=found.cost,
        lower_bound=found.lower_bound,
        n_entities=len(scene.others),
        program=program,
        scenic=scenic,
        certified=certified,
        stats=SynthStats.since(started, [stats] if stats else [], found.nodes_expanded, search_s, oracle_s, ranges_s,
                               certify_s, render_s),
        config=config,
    )
