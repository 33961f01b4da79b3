"""Sampling variants of a program, read back as scene JSON: r2sgen's chain or Scenic's own rejection sampler.

Shared by `r2s sample` and `r2s render --samples`. Both samplers draw from one distribution: the program's
Ranges as Scenic draws them, conditioned on the collision rule (two boxes may overlap only if they overlap in the
recording; synth.variants.collision_rule), which the emitted text states as requirements.

- `gibbs` (the default): Metropolis-within-Gibbs over the program's parameters (synth.variants.gibbs), started at the
  recorded scene. Pure Python and numpy, no Scenic import; 5 variants of every shipped keyframe (up to 141
  entities) in seconds. It reads the program, the scene and the tolerances from the text's `# r2s-source`
  record, after checking that the text is exactly what the emitter writes from that record.
- `scenic`: the official compiler (scenic 3.1.1) compiles the text and rejection-samples whole scenes. Exact and
  independent, but its acceptance falls exponentially with the number of entities: the reference for small
  scenes (tests/synth/variants/test_variants.py compares the two), and the only sampler for a hand-edited text (--trusted).

Scenic draws from Python's `random` and numpy's global generators; both are seeded for a run and restored
afterwards, so the same text and seed give the same scenes in any process, and a caller's own random state is
left as it was. The chain has its own generator, seeded by the seed.

Text given by a user is a program: compiling it runs it (Scenic is Python). So a Scenic file is compiled only
if the emitter renders it again byte for byte from its own `# r2s-source` record (synth.scenic.emit): an edited
or foreign file is refused before anything runs, unless the caller says it is trusted (`r2s sample --trusted`).
The DSL route (`sample_program`) takes a validated DSL program and scene instead. Every variant, from either
sampler, is checked against the DSL semantics before it is returned.
"""

from __future__ import annotations

import math
import random
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy
from tqdm import tqdm

from pipeline.errors import SamplingError, UserError
from pipeline.variants import DEFAULT_MAX_ITERATIONS, MAX_SEED, SAMPLERS
from synth.config import SynthConfig, config_from_mapping
from synth.dsl import DslError, Program, parse_program
from synth.geometry import normalize
from synth.scene import DEFAULT_MAX_ENTITIES, Scene, SceneError, scene_from_dict
from synth.scenic.emit import (
    COLLISIONS_PARAM,
    FRAME_PARAM,
    MIN_DISTANCE,
    MOTION_PARAM,
    NotGenerated,
    read_source,
    rebuild_from_source,
    render_scenic,
)
from synth.semantics import check
from synth.variants.gibbs import ChainSettings, NoVariant, rejection_odds, sample_variants
from synth.variants.scene_road import SceneRoad


class ScenicProgramError(UserError):
    """The Scenic text does not compile, or fails while sampling, or is not an r2sgen program. One line."""


class SamplingFailed(SamplingError):
    """No variant satisfies the program and the collision rule within the budget (not bad input: the program
    and scene are valid, the sampler could not find a variant). One line naming the pairs that block."""


@dataclass(frozen=True)
class SampleOptions:
    n: int = 1
    seed: int = 0
    max_iterations: int = DEFAULT_MAX_ITERATIONS  # per scene (scenic)
    allow_collisions: bool = False
    sampler: str | None = None  # None: gibbs for r2sgen's own text, scenic for a trusted hand-edited one
    burn_in: int | None = None  # sweeps (gibbs); None: synth.variants.gibbs's default
    thin: int | None = None

    def __post_init__(self) -> None:
        if self.n < 1 or self.max_iterations < 1:
            raise UserError("the number of scenes and the iteration budget must be at least 1")
        if not 0 <= self.seed <= MAX_SEED:
            raise UserError(f"the seed must be in [0, {MAX_SEED}], got {self.seed}")
        if self.sampler is not None and self.sampler not in SAMPLERS:
            raise UserError(f"unknown sampler {self.sampler!r} (choose from {', '.join(SAMPLERS)})")
        if (self.burn_in is not None and self.burn_in < 0) or (self.thin is not None and self.thin < 1):
            raise UserError("--burn-in must be at least 0 and --thin at least 1")

    def chain_settings(self):
        default = ChainSettings()
        return ChainSettings(burn_in=default.burn_in if self.burn_in is None else self.burn_in,
                             thin=default.thin if self.thin is None else self.thin)


@dataclass(frozen=True)
class Samples:
    scenes: tuple[Scene, ...]
    sampler: str
    iterations: int = 0  # scenic: rejection-sampling iterations over all scenes (n when nothing was rejected)
    sweeps: int = 0  # gibbs: sweeps of the chain (after finding a start)
    acceptance: float = 1.0  # gibbs: accepted draws / draws

    def describe(self) -> str:
        if self.sampler == "scenic":
            return f"scenic: {self.iterations} iterations"
        return f"gibbs: {self.sweeps} sweeps, {self.acceptance:.0%} of draws accepted"


Progress = Callable[[int, int], None]


class ProgressReport:
    """Progress of a long sampling run on stderr: a bar on a terminal, else a log line every few seconds."""

    def __init__(self, what: str, every_s: float = 5.0):
        self.what, self.every_s = what, every_s
        self.started = self.last = time.monotonic()
        self.bar = None
        self.tty = sys.stderr.isatty()

    def __call__(self, done: int, total: int) -> None:
        now = time.monotonic()
        if self.tty:
            if self.bar is None and now - self.started > 1.0:
                self.bar = tqdm(total=total, desc=self.what, unit=" sweeps", file=sys.stderr, leave=False)
            if self.bar is not None:
                self.bar.total = total
                self.bar.n = done
                self.bar.refresh()
        elif now - self.last >= self.every_s:
            self.last = now
            sys.stderr.write(f"{self.what}: {done}/{total} ({now - self.started:.0f} s)\n")

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _first_line(exc: BaseException) -> str:
    text = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), "")
    text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
    return text if len(text) <= 300 else text[:297] + "..."


@contextmanager
def _seeded(seed: int) -> Iterator[None]:
    saved = random.getstate(), numpy.random.get_state()
    random.seed(seed)
    numpy.random.seed(seed)
    try:
        yield
    finally:
        random.setstate(saved[0])
        numpy.random.set_state(saved[1])


def compile_scenic(text: str, options: SampleOptions, filename: str = "<program>", generated: bool = False):
    """The Scenic scenario of a text, with the collision switch of the options (a UserError if it fails). A
    `generated` text (r2sgen's own, checked against its record) that names a map has it parsed afresh: Scenic
    would otherwise load a pickled cache found beside the .xodr, which a received folder could hold."""
    import scenic

    params = {COLLISIONS_PARAM: options.allow_collisions}
    if generated:
        params["map_options"] = {"useCache": False, "writeCache": False}
    try:
        scenario = scenic.scenarioFromString(text, params=params, filename=filename, mode2D=True)
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


def scene_from_scenic(sampled, frame_id: str, filename: str = "<program>", motion: bool = False) -> Scene:
    """A sampled Scenic scene as our scene: `name` is the id, the class the type; all of it re-validated.
    With motion (the text says `param r2s_motion = True`) each object's speed too."""
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
            "width": float(o.width), **({"speed": float(o.speed) + 0.0} if motion else {}),
        })
    try:
        return scene_from_dict({"frame_id": frame_id, "entities": entities}, max_entities=DEFAULT_MAX_ENTITIES)
    except SceneError as exc:
        raise ScenicProgramError(f"{filename}: a sampled scene is not a valid scene: {exc}") from None


def draw_scenes(scenario, options: SampleOptions, filename: str = "<program>",
                progress: Progress | None = None) -> Samples:
    """options.n scenes of a compiled scenario, seeded: compiling draws nothing, sampling starts from the seed."""
    from scenic.core.distributions import RejectionException

    with _seeded(options.seed):
        scenes, total = [], 0
        for k in range(options.n):
            try:
                sampled, iterations = scenario.generate(maxIterations=options.max_iterations)
            except RejectionException:
                rule = "the requirements" if options.allow_collisions else "the program and the collision rule"
                raise SamplingFailed(f"{filename}: Scenic found no scene that satisfies {rule} in "
                                     f"{options.max_iterations} iterations (scene {k + 1} of {options.n})") from None
            except Exception as exc:
                raise ScenicProgramError(f"{filename}: Scenic fails while sampling: {_first_line(exc)}") from None
            total += iterations
            motion = scenario.params.get(MOTION_PARAM) is True
            scenes.append(scene_from_scenic(sampled, _frame_id(scenario, k), filename, motion))
            if progress is not None:
                progress(k + 1, options.n)
    return Samples(tuple(scenes), "scenic", iterations=total)


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
        # Files written before a change of the emitter (e.g. the collision rule) differ too: say how to renew them.
        raise ScenicProgramError(f"{filename} differs from what r2sgen writes for its own record at line {line + 1} "
                                 "(edited, or written by an older r2sgen: write it again with "
                                 f"`r2s synth SCENE --format scenic`); {hint}")


def sample_scenic(text: str, options: SampleOptions, filename: str = "<program>", trusted: bool = False,
                  progress: Progress | None = None) -> Samples:
    """options.n variants of a Scenic text; untrusted text must be r2sgen's own, unedited.

    r2sgen's own text is sampled from its record (program, scene, tolerances) by the chosen sampler, and every
    variant is checked against the program; a hand-edited text (trusted) only by Scenic, as it stands.
    """
    generated = True
    try:
        ensure_generated(text, filename)
    except ScenicProgramError:
        if not trusted:
            raise
        generated = False
    sampler = options.sampler or ("gibbs" if generated else "scenic")
    if not generated:
        if sampler != "scenic":
            raise UserError(f"{filename} is not r2sgen's own text (edited?): only --sampler scenic samples it as it "
                            "stands")
        return draw_scenes(compile_scenic(text, options, filename), options, filename, progress)
    src = read_source(text)
    return _sample(src.program, src.scene, src.config, options, sampler, text, filename, progress)


def sample_program(program: Program, scene: Scene, config: SynthConfig, options: SampleOptions,
                   progress: Progress | None = None) -> Samples:
    """The DSL route: a validated program and the scene it describes (the Scenic text is regenerated)."""
    ids = {e.id for e in scene.others}
    unknown = [s.id for s in program.statements if s.id not in ids]
    if unknown:
        raise UserError(f"the program declares {unknown[0]!r}, which is not an entity of scene {scene.frame_id}")
    return _sample(program, scene, config, options, options.sampler or "gibbs", None, "<emitted Scenic>", progress)


def _sample(program: Program, scene: Scene, config: SynthConfig, options: SampleOptions, sampler: str,
            text: str | None, filename: str, progress: Progress | None) -> Samples:
    if sampler == "gibbs":
        try:
            v = sample_variants(program, scene, config, options.n, options.seed, options.chain_settings(),
                                options.allow_collisions, progress)
        except NoVariant as exc:
            raise SamplingFailed(f"{filename}: {exc}") from None
        samples = Samples(v.scenes, "gibbs", sweeps=v.stats.sweeps, acceptance=v.stats.acceptance)
    else:
        text = text if text is not None else render_scenic(program, scene, config)
        try:
            samples = draw_scenes(compile_scenic(text, options, filename, generated=True), options, filename,
                                  progress)
        except SamplingFailed as exc:
            if options.allow_collisions:
                raise
            raise SamplingFailed(f"{exc}; {blockers(program, scene, config, options.seed)}; the default sampler "
                                 "(--sampler gibbs) does not reject whole scenes") from None
        except ScenicProgramError as exc:  # our own text failing is a bug, not bad input
            raise RuntimeError(str(exc)) from None
        if scene.road is not None:  # each variant on the recorded road, with its lane facts where it now is
            road = SceneRoad(scene.road)
            samples = replace(samples, scenes=tuple(road.placed(s) for s in samples.scenes))
    for k, s in enumerate(samples.scenes):
        result = check(program, s, config)
        if not result.ok:
            # The program is the user's: a statement no scene can satisfy as sampled (a distance Range under
            # dsl__MIN_DISTANCE, an entity placed on the reference it must face) is bad input, named as such.
            raise UserError(f"sampled scene {k} is outside the program's own semantics ({result.violations[0]}): "
                            "the program has a statement no sampled scene satisfies, e.g. a distance Range under "
                            f"{MIN_DISTANCE} m or an entity placed on the reference it faces")
    return samples


def blockers(program: Program, scene: Scene, config: SynthConfig, seed: int, draws: int = 200) -> str:
    """Why whole-scene rejection fails: how often independent draws satisfy the rule, and the pairs that collide."""
    odds = rejection_odds(program, scene, config, seed, draws)
    top = ", ".join(f"{a} and {b} ({share:.0%})" for (a, b), share in odds.pairs[:3])
    return (f"{odds.clear}/{draws} independent draws from the program satisfy the collision rule"
            + (f"; most often colliding: {top}" if top else ""))


def sample(program=None, scene=None, *, programs=None, frame_id: str | None = None,
           config: SynthConfig | dict | None = None, n: int = 1, seed: int = 0, sampler: str | None = None,
           burn_in: int | None = None, thin: int | None = None, max_iterations: int = DEFAULT_MAX_ITERATIONS,
           allow_collisions: bool = False, trusted: bool = False, progress: Progress | None = None) -> Samples:
    """`r2s sample` in-process (docs/api.md): n variants of a recorded scene, from one of
    - `program`, Scenic text r2sgen wrote (`r2s synth --format scenic`, a run's scenic column; `trusted` samples an
      edited text with Scenic, as `--trusted` does),
    - `program` a DSL `Program` or text and `scene` the scene it describes (a `Scene` or a scene JSON dict), with
      `config` for the tolerances (a SynthConfig or a dict of its fields),
    - `programs` (a programs file or dataset, r2s run's output) and `frame_id`: that frame's Scenic text.
    The keywords after `config` are SampleOptions' fields (`r2s sample`'s options). Returns `Samples`: `.scenes`
    (Scenes), `.sampler`, `.describe()`. Bad input raises an InputError (UserError, one line); no variant within
    the budget raises SamplingFailed (exit 4 in `r2s sample`)."""
    from pipeline.programs import scenic_of_frame  # pyarrow, pandas: only `programs=` reads Parquet

    options = SampleOptions(n=n, seed=seed, max_iterations=max_iterations, allow_collisions=allow_collisions,
                            sampler=sampler, burn_in=burn_in, thin=thin)
    if programs is not None:
        if program is not None or scene is not None or frame_id is None:
            raise UserError("give programs and frame_id, or a program (and the scene, for a DSL program)")
        text = scenic_of_frame(programs, frame_id)
        if text is None:
            raise UserError(f"{programs} has no program for frame {frame_id!r}")
        return sample_scenic(text, options, filename=f"the program of {frame_id} in {programs}", progress=progress)
    if program is None:
        raise UserError("give a program: Scenic text, a DSL program with its scene, or programs and frame_id")
    if scene is None:
        if config is not None:
            raise UserError("config belongs to the DSL route (a program with its scene), not to a Scenic text")
        if not isinstance(program, str):
            raise UserError("a DSL program needs the scene it was synthesized for")
        return sample_scenic(program, options, trusted=trusted, progress=progress)

    try:
        program = parse_program(program) if isinstance(program, str) else program
        scene = scene_from_dict(scene) if isinstance(scene, dict) else scene
        config = config_from_mapping(config) if isinstance(config, dict) else config or SynthConfig()
    except (DslError, SceneError) as exc:
        raise UserError(str(exc)) from None
    return sample_program(program, scene, config, options, progress)
