"""The synthesis driver (the paper's Alg. 1): what it is asked for in, a minimum-cost program out, in timed stages.

Every synthesis runs the same stages on what it describes, a Subject: the requirements (checked when the subject
is made, before any work), then under one budget and one stage timer the relation oracle, the search, Alg. 4 with
the cost check, certification of every frame's program and the Scenic text (synth.result.STAGES). A Subject says
what differs: one scene (Frame, here), a window of frames (synth.window.program.Window); a clip's behaviour program
(issue 38) is one more Subject, whose program() adds each entity's behaviour and whose scenic() is a scenario
over time, driven by the same stages and timer into the same result type.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

from synth.config import SynthConfig
from synth.dsl import Program
from synth.errors import InternalError
from synth.oracle import RelationOracle, make_oracle
from synth.parts.lane import require_lanes
from synth.result import SynthResult, SynthStats
from synth.robust import robust_note
from synth.scene import Scene, SceneError
from synth.scenic.emit import render_scenic
from synth.search import Budget, CostModel, search
from synth.search.budget import peak_rss_mb
from synth.smt.certify import certify
from synth.statement import build_program
from synth.version import __version__


class SpeedMissing(SceneError):
    """Motion was asked for a scene with an entity whose speed is unknown. One line naming the entity."""


class CertificationError(InternalError, RuntimeError):
    """The solver could not confirm a statement of the synthesized program: an internal error, never silent."""


def require_speeds(scene: Scene) -> None:
    """Motion describes every entity's speed, ego's too: refuse a scene where one is not known."""
    missing = [e.id for e in scene.entities if e.speed is None]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise SpeedMissing(f"entity {missing[0]!r}{more} has no speed, which motion (--motion) needs")


class StageTimer:
    """The one clock of a synthesis: the seconds since it started and those of each named stage it ran
    (`with timer.stage("search"): ...`; a stage run twice sums)."""

    def __init__(self) -> None:
        self.started = time.perf_counter()
        self.seconds: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        t = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[name] = self.seconds.get(name, 0.0) + time.perf_counter() - t

    def elapsed(self) -> float:
        return time.perf_counter() - self.started


@dataclass(frozen=True)
class Oracles:
    """The oracle stage's answer: the relation table the search runs on, and each frame's oracle (in the
    subject's frame order), whose solver certifies that frame's program."""

    search: RelationOracle
    frames: tuple[RelationOracle, ...]

    def smt_stats(self) -> list:
        return [o.backend.stats for o in self.frames if o.backend is not None]


class Subject(Protocol):
    """What one synthesis describes, made (and its requirements checked) before the driver starts its clock."""

    kind: ClassVar[str]  # "frame", "window": how the driver's internal errors name it
    scenes: tuple[Scene, ...]  # its frames, in order

    def oracles(self, config: SynthConfig) -> Oracles: ...

    def program(self, oracles: Oracles, order: tuple[int, ...], config: SynthConfig) -> Program:
        """The program of the search's order (oracle indices of oracles.search, ego excluded)."""

    def frame_program(self, program: Program, scene: Scene) -> Program:
        """What `program` says of one of its frames (certified on that frame)."""

    def where(self, scene: Scene) -> str:
        """How an error names one of its frames: a prefix of the message."""

    def scenic(self, program: Program, status: str, config: SynthConfig) -> str: ...

    def result(self, **fields: Any) -> SynthResult:
        """The result of its program: `fields` are those of every result but frame_id and n_entities."""


def drive(subject: Subject, config: SynthConfig) -> SynthResult:
    """A minimum-cost program for `subject` whose every frame's program is certified (when the oracle has a
    solver), with the stats of its stages. Deterministic: the same subject and config give the same program and
    Scenic text."""
    timer = StageTimer()
    budget = Budget(config.time_limit, config.memory_limit)
    with timer.stage("oracle"):
        oracles = subject.oracles(config)
    with timer.stage("search"):
        found = search(config.strategy, CostModel(oracles.search), budget)
    with timer.stage("ranges"):
        # Search indices are oracle indices minus one (oracle index 0 is ego).
        program = subject.program(oracles, tuple(i + 1 for i in found.order), config)
        if program.cost != found.cost:
            raise AssertionError(f"{subject.kind} program cost {program.cost} differs from the search's {found.cost}")
    with timer.stage("certify"):
        certified = _certify(subject, oracles, program)
    with timer.stage("render"):
        scenic = subject.scenic(program, found.status, config)
    stats = SynthStats.of(timer.elapsed(), timer.seconds, oracles.smt_stats(), found.nodes_expanded, peak_rss_mb())
    return subject.result(status=found.status, cost=found.cost, lower_bound=found.lower_bound, program=program,
                          scenic=scenic, certified=certified, stats=stats, config=config)


def _certify(subject: Subject, oracles: Oracles, program: Program) -> bool:
    """Each frame's program confirmed by its frame's solver; False when a frame's oracle has none (closed form)."""
    if any(oracle.backend is None for oracle in oracles.frames):
        return False
    for oracle, scene in zip(oracles.frames, subject.scenes):
        failed = certify(oracle.backend, subject.frame_program(program, scene), scene)
        if failed:
            raise CertificationError(f"{subject.where(scene)}the solver refutes the statements of {', '.join(failed)}")
    return True


@dataclass(frozen=True)
class Frame:
    """One scene: the paper's input to Alg. 1."""

    kind: ClassVar[str] = "frame"
    scene: Scene

    @classmethod
    def of(cls, scene: Scene, config: SynthConfig) -> Frame:
        """The scene, refused (one line) if the config asks what it does not record: with motion, every entity's
        speed (SpeedMissing); with lanes, its road and lane facts (LanesMissing)."""
        if config.motion:
            require_speeds(scene)
        if config.lanes:
            require_lanes(scene)
        return cls(scene)

    @property
    def scenes(self) -> tuple[Scene, ...]:
        return (self.scene,)

    def oracles(self, config: SynthConfig) -> Oracles:
        oracle = make_oracle(self.scene, config)
        if config.strategy == "auto":
            oracle.full_table()
        return Oracles(oracle, (oracle,))

    def program(self, oracles: Oracles, order: tuple[int, ...], config: SynthConfig) -> Program:
        return build_program(oracles.search, order, config)

    def frame_program(self, program: Program, scene: Scene) -> Program:
        return program

    def where(self, scene: Scene) -> str:
        return ""

    def scenic(self, program: Program, status: str, config: SynthConfig) -> str:
        scene = self.scene
        header = (f"frame {scene.frame_id}: cost {program.cost} ({status}), r2sgen {__version__}"
                  + robust_note(self.scenes, config))
        return render_scenic(program, scene, config, header=header)

    def result(self, **fields: Any) -> SynthResult:
        return SynthResult(frame_id=self.scene.frame_id, n_entities=len(self.scene.others), **fields)
