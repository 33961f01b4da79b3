"""What one synthesis returns (docs/dsl.md, "What synthesis returns"): the result, its stats, and the result fields
both outputs carry, declared once with their Python meaning (pipeline.programs maps them to Parquet types).

Light on purpose: `import synth` loads it (the program's type is named for the type checker only).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from synth.config import SynthConfig

if TYPE_CHECKING:
    from synth.dsl import Program

# The stages of every synthesis (synth.driver), in order, each timed by the one stage timer: the relation oracle
# (every pair's witness relations), the search (Alg. 1), Alg. 4 (references and Range values), certification of the
# printed program, Scenic rendering. SynthStats holds each as `<stage>_s`.
STAGES = ("oracle", "search", "ranges", "certify", "render")


@dataclass(frozen=True)
class SynthStats:
    """Where the time and memory of one synthesis went (the `stats` of `r2s synth --format json`)."""

    runtime_s: float
    search_s: float
    smt_s: float
    smt_queries: int
    nodes_expanded: int
    peak_rss_mb: float
    # Where runtime_s went, stage by stage (not in the JSON document or programs.parquet; search_s above is one of
    # them). smt_s is the solver's share of the oracle, search and ranges stages.
    oracle_s: float = 0.0
    ranges_s: float = 0.0
    certify_s: float = 0.0
    render_s: float = 0.0

    @classmethod
    def of(cls, runtime_s: float, stages: dict[str, float], smt: list, nodes_expanded: int,
           peak_rss_mb: float) -> SynthStats:
        """The stats of a synthesis of `runtime_s` seconds whose stages (STAGES) took `stages` seconds each, its
        solvers' stats summed (`smt`: one per solver backend asked, a window's frames each have one)."""
        return cls(runtime_s=runtime_s, smt_s=sum(s.seconds for s in smt), smt_queries=sum(s.queries for s in smt),
                   nodes_expanded=nodes_expanded, peak_rss_mb=peak_rss_mb,
                   **{f"{stage}_s": stages.get(stage, 0.0) for stage in STAGES})


@dataclass(frozen=True)
class ResultField:
    """One field of a synthesis result as the outputs carry it (docs/formats.md): a key of the `r2s synth --format
    json` document and a column of programs Parquet, in this order."""

    name: str
    type: type  # the Python type of its value (str, int, float, bool); null in a row without a program
    # Where a result's value is: "result" (a SynthResult field; the program as its DSL text), "stats" (a SynthStats
    # field; the JSON nests these under "stats"), "config" (a SynthConfig field) or "run" (the batch stage's own:
    # Parquet only).
    source: str


_PYTHON_TYPES = {"str": str, "int": int, "float": float, "bool": bool}
# The one declaration of the result fields: SynthResult.to_json_dict, pipeline.programs' rows and schema read it.
# By source, each as name:Python type, in contract order (docs/formats.md says what each means).
RESULT_FIELDS: tuple[ResultField, ...] = tuple(ResultField(name, _PYTHON_TYPES[type_], source) for source, spec in (
    ("result", "frame_id:str status:str cost:int lower_bound:int n_entities:int program:str scenic:str "
               "certified:bool"),
    ("config", "strategy:str oracle:str solver:str"),
    ("stats", "runtime_s:float search_s:float smt_s:float smt_queries:int nodes_expanded:int peak_rss_mb:float"),
    ("run", "error:str config_hash:str version:str frame_hash:str"),
) for name, type_ in (field.split(":") for field in spec.split()))


@dataclass(frozen=True)
class SynthResult:
    """The program synthesized for one scene, with its cost, status and certificate (docs/dsl.md, "What synthesis
    returns"). `str(result.program)` is the DSL text, `result.scenic` the Scenic text, `to_json_dict()` the
    `r2s synth --format json` document. A window's result is this with its frames (synth.window.program.WindowResult)."""

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
        """The `r2s synth --format json` document (docs/formats.md): the result's fields, what else the result
        says of itself (json_more: a window's frames), then its stats."""
        return {**{f.name: self.value(f) for f in RESULT_FIELDS if f.source == "result"}, **self.json_more(),
                "stats": {f.name: self.value(f) for f in RESULT_FIELDS if f.source == "stats"}}

    def json_more(self) -> dict:
        """The document's keys between the result's fields and its stats: none for one scene."""
        return {}
