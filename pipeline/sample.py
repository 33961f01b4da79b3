"""Sampling scenes from a Scenic program with the official compiler (scenic 3.1.1), read back as scene JSON.

Shared by `r2s sample` and `r2s render --samples`. Scenic is imported here, lazily (≈ 1 s), never at module
import. Scenic draws from Python's `random` and numpy's global generators; both are seeded for a run and
restored afterwards, so the same text and seed give the same scenes in any process, and a caller's own random
state is left as it was.

Text given by a user is a program: compiling it runs it (Scenic is Python). So a Scenic file is compiled only
if the emitter renders it again byte for byte from its own `# r2s-source` record (synth.emit_scenic): an edited
or foreign file is refused before anything runs, unless the caller says it is trusted (`r2s sample --trusted`).
The DSL route (`sample_program`) regenerates the text from a validated DSL program and scene instead, and
checks every sample against the DSL.
"""

from __future__ import annotations

import math
import random
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

from pipeline.errors import UserError
from synth.config import SynthConfig
from synth.dsl import Program
from synth.emit_scenic import (
    COLLISIONS_PARAM,
    FRAME_PARAM,
    MIN_DISTANCE,
    NotGenerated,
    rebuild_from_source,
    render_scenic,
)
from synth.geometry import normalize
from synth.scene import DEFAULT_MAX_ENTITIES, Scene, SceneError, scene_from_dict
from synth.semantics import check

DEFAULT_MAX_ITERATIONS = 2000  # Scenic's own default for one scene
MAX_SEED = 2**32 - 1  # numpy's seed range


class ScenicProgramError(UserError):
    """The Scenic text does not compile, or fails while sampling, or is not an r2sgen program. One line."""


class SamplingFailed(UserError):
    """Rejection sampling found no scene within its iteration budget. One line, with what to try."""


@dataclass(frozen=True)
class SampleOptions:
    n: int = 1
    seed: int = 0
    max_iterations: int = DEFAULT_MAX_ITERATIONS  # per scene
    allow_collisions: bool = False

    def __post_init__(self) -> None:
        if self.n < 1 or self.max_iterations < 1:
            raise UserError("the number of scenes and the iteration budget must be at least 1")
        if not 0 <= self.seed <= MAX_SEED:
            raise UserError(f"the seed must be in [0, {MAX_SEED}], got {self.seed}")


@dataclass(frozen=True)
class Samples:
    scenes: tuple[Scene, ...]
    iterations: int  # rejection-sampling iterations over all scenes (n when nothing was rejected)


def _first_line(exc: BaseException) -> str:
    text = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), "")
    text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= 300 else text[:297] + "..."


@contextmanager
def _seeded(seed: int) -> Iterator[None]:
    import numpy

    saved = random.getstate(), numpy.random.get_state()
    random.seed(seed)
    numpy.random.seed(seed)
    try:
        yield
    finally:
        random.setstate(saved[0])
        numpy.random.set_state(saved[1])


def compile_scenic(text: str, options: SampleOptions, filename: str = "<program>"):
    """The Scenic scenario of a text, with the collision switch of the options (a UserError if it fails)."""
    import scenic

    try:
        scenario = scenic.scenarioFromString(
            text, params={COLLISIONS_PARAM: options.allow_collisions}, filename=filename, mode2D=True
        )
    except Exception as exc:  # any failure of a program text is the text's: Scenic raises all kinds
        raise ScenicProgramError(f"{filename}: Scenic cannot compile it: {_first_line(exc)}") from None
    if options.allow_collisions and any(o.allowCollisions is False for o in scenario.objects):
        # A hand-written program need not read the parameter; then the flag would silently do nothing.
        raise ScenicProgramError(
            f"{filename}: --allow-collisions has no effect: its classes do not read globalParameters.{COLLISIONS_PARAM}"
        )
    return scenario


def _frame_id(scenario, k: int) -> str:
    base = scenario.params.get(FRAME_PARAM)
    if not isinstance(base, str) or not base or not base.isprintable():
        base = "sample"
    return f"{base[:240]}#sample{k}"  # the scene contract caps frame ids at 256 characters


def scene_from_scenic(sampled, frame_id: str, filename: str = "<program>") -> Scene:
    """A sampled Scenic scene as our scene: `name` is the id, the class the type; all of it re-validated."""
    entities = []
    for i, o in enumerate(sampled.objects):
        name = getattr(o, "name", None)
        if name is None:
            raise ScenicProgramError(
                f"{filename}: object {i} ({type(o).__name__}) has no name: not a program written by r2sgen"
            )
        entities.append({
            # + 0.0 turns -0.0 into 0.0, which Scenic produces for a zero yaw and JSON would print as -0.0.
            "id": name, "type": type(o).__name__, "x": float(o.position.x) + 0.0, "y": float(o.position.y) + 0.0,
            "heading": normalize(math.degrees(float(o.heading))) + 0.0, "length": float(o.length),
            "width": float(o.width),
        })
    try:
        return scene_from_dict({"frame_id": frame_id, "entities": entities}, max_entities=DEFAULT_MAX_ENTITIES)
    except SceneError as exc:
        raise ScenicProgramError(f"{filename}: a sampled scene is not a valid scene: {exc}") from None


def draw_scenes(scenario, options: SampleOptions, filename: str = "<program>") -> Samples:
    """options.n scenes of a compiled scenario, seeded: compiling draws nothing, sampling starts from the seed."""
    from scenic.core.distributions import RejectionException

    with _seeded(options.seed):
        scenes, total = [], 0
        for k in range(options.n):
            try:
                sampled, iterations = scenario.generate(maxIterations=options.max_iterations)
            except RejectionException:
                hint = "" if options.allow_collisions else " or pass --allow-collisions"
                raise SamplingFailed(
                    f"{filename}: no scene {'satisfies the requirements' if options.allow_collisions else 'without collisions'} "
                    f"found in {options.max_iterations} iterations (scene {k + 1} of {options.n}); "
                    f"raise --max-iterations{hint}"
                ) from None
            except Exception as exc:
                raise ScenicProgramError(f"{filename}: Scenic fails while sampling: {_first_line(exc)}") from None
            total += iterations
            scenes.append(scene_from_scenic(sampled, _frame_id(scenario, k), filename))
    return Samples(tuple(scenes), total)


def ensure_generated(text: str, filename: str = "<program>") -> None:
    """Refuse, before anything runs, Scenic text that r2sgen's emitter would not write from its own record."""
    hint = "refusing to run it (compiling Scenic runs it as Python); pass --trusted for a program you have checked"
    try:
        expected = rebuild_from_source(text)
    except NotGenerated as exc:
        raise ScenicProgramError(f"{filename} is not Scenic text written by r2sgen: {exc}; {hint}") from None
    if expected != text:
        got, want = text.splitlines(), expected.splitlines()
        line = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), min(len(got), len(want)))
        raise ScenicProgramError(f"{filename} differs from what r2sgen writes for its own record at line {line + 1}; "
                                 f"{hint}")


def sample_scenic(text: str, options: SampleOptions, filename: str = "<program>", trusted: bool = False) -> Samples:
    """Compile Scenic text and draw options.n scenes from it; untrusted text must be r2sgen's own, unedited."""
    if not trusted:
        ensure_generated(text, filename)
    return draw_scenes(compile_scenic(text, options, filename), options, filename)


def recorded_overlaps(scene: Scene) -> list[tuple[str, str]]:
    """Pairs of entities whose boxes overlap in the scene: why collision-free sampling may find nothing."""
    from shapely.geometry import Polygon  # a dependency of scenic

    from pipeline.render import ego_frame

    boxes = [(b.id, Polygon(b.corners())) for b in ego_frame(scene).values()]
    return [(a, b) for i, (a, pa) in enumerate(boxes) for b, pb in boxes[i + 1:] if pa.intersection(pb).area > 0]


def sample_program(program: Program, scene: Scene, config: SynthConfig, options: SampleOptions) -> Samples:
    """The DSL route: Scenic text regenerated from a validated program and scene; every sample is checked."""
    ids = {e.id for e in scene.others}
    unknown = [s.id for s in program.statements if s.id not in ids]
    if unknown:
        raise UserError(f"the program declares {unknown[0]!r}, which is not an entity of scene {scene.frame_id}")
    text = render_scenic(program, scene, config)
    try:
        samples = sample_scenic(text, options, filename="<emitted Scenic>", trusted=True)
    except SamplingFailed as exc:
        pairs = recorded_overlaps(scene)
        if not pairs or options.allow_collisions:
            raise
        a, b = pairs[0]
        raise SamplingFailed(f"{exc}; the recorded scene itself has {len(pairs)} overlapping "
                             f"pair{'s' if len(pairs) > 1 else ''} of boxes (e.g. {a} and {b})") from None
    except ScenicProgramError as exc:  # our own text failing is a bug, not bad input
        raise RuntimeError(str(exc)) from None
    for k, s in enumerate(samples.scenes):
        result = check(program, s, config)
        if not result.ok:
            # The program is the user's: a statement no scene can satisfy as sampled (a distance Range under
            # dsl__MIN_DISTANCE, an entity placed on the reference it must face) is bad input, named as such.
            raise UserError(f"sampled scene {k} is outside the program's own semantics ({result.violations[0]}): "
                            "the program has a statement no sampled scene satisfies, e.g. a distance Range under "
                            f"{MIN_DISTANCE} m or an entity placed on the reference it faces")
    return samples
