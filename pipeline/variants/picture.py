"""`r2s render` (render, its Python API: `from pipeline import render`): a scene's bird's-eye picture
with its program's references and sampled variants, written to an image file. What is drawn is
pipeline.variants.render's; this module gathers it: the program (given, or a run's for the frame), whether it
contains the scene, and the variants."""

from __future__ import annotations

import os
from pathlib import Path

from pipeline.cli.inputs import read_scene
from pipeline.errors import UserError
from pipeline.outputs import check_apart, writing
from pipeline.variants.render import FORMATS, View, draw, save
from pipeline.variants.sample import ProgressReport, SampleOptions, sample_program
from synth.config import SynthConfig, config_from_mapping
from synth.dsl import DslError, Program, parse_program
from synth.scene import Scene, SceneError, scene_from_dict
from synth.semantics import check


def render(scene, out: str | os.PathLike, *, program=None, programs=None, samples: int = 0,
           config: SynthConfig | dict | None = None, sampling: SampleOptions | None = None,
           matches: str | os.PathLike | None = None, progress=None, where_scene: str | None = None) -> Path:
    """`r2s render` in-process (docs/api.md): draws `scene` (a Scene, a scene JSON dict, or a scene JSON file) into
    `out` (.png, .svg or .pdf, written atomically): with `program` (a Program or DSL text) or `programs` (a
    programs file or dataset: the frame's program from a run) its references, and `samples` variants sampled from
    it (`sampling`: a SampleOptions, seed 0 by default); with `matches` (a matches file of `r2s query`) the
entities its bindings of this frame bind, outlined and named by their pattern names (`where_scene` names the
scene in messages). Returns the path written. Bad input raises an InputError
    (UserError, one line); no variant within the budget raises SamplingFailed."""
    where_scene = where_scene or (str(scene) if isinstance(scene, (str, os.PathLike)) else "the scene")
    check_apart(out, [("scene", scene if isinstance(scene, (str, os.PathLike)) else None),
                      ("programs", programs), ("matches", matches)])
    out = Path(out)
    if out.suffix.lstrip(".").lower() not in FORMATS:
        raise UserError(f"--out {out}: the file name must end in {', '.join('.' + f for f in FORMATS)}")
    if out.is_dir():
        raise UserError(f"--out {out} is a directory")
    if program is not None and programs is not None:
        raise UserError("give --program or --programs, not both")
    if samples and program is None and programs is None:
        raise UserError("--samples needs --program (variants are sampled from the program)")
    scene = _scene(scene)
    config = config_from_mapping(config) if isinstance(config, dict) else config or SynthConfig()
    program, where = _program(program, programs, scene)
    bound = () if matches is None else _bound(matches, scene)
    subtitle, drawn = "", ()
    if program is not None:
        ids = {e.id for e in scene.entities}
        missing = next((s.id for s in program.statements if s.id not in ids), None)
        if missing is not None:
            raise UserError(f"{where} declares {missing!r}, which is not an entity of {where_scene}")
        result = check(program, scene, config)
        subtitle = f"program cost {program.cost}, " + (
            "contains the scene" if result.ok else f"does NOT contain the scene ({len(result.violations)} violations)")
        if samples:
            options = SampleOptions(**{**(sampling or SampleOptions()).__dict__, "n": samples})
            progress = progress or ProgressReport("r2s render")
            try:
                variants = sample_program(program, scene, config, options, progress)
            finally:
                if isinstance(progress, ProgressReport):
                    progress.close()
            drawn = variants.scenes
            subtitle += f"; {len(drawn)} variants ({variants.sampler}, seed {options.seed})"
    if matches is not None:
        names = sorted({name for name, _ in bound})
        subtitle = "; ".join(filter(None, (subtitle, f"bound by the match in {Path(matches).name}: {', '.join(names)}")))
    with writing(out):
        save(draw(View(scene, program, drawn, subtitle, bound)), out)
    return out


def _bound(matches, scene: Scene) -> tuple[tuple[str, str], ...]:
    """(pattern name, entity id) for every binding of the scene's frame in the matches file."""
    from pipeline.query.matches import bindings_of_frame  # pyarrow, pandas: only --matches reads Parquet

    bindings = bindings_of_frame(matches, scene.frame_id)
    if not bindings:
        raise UserError(f"{matches} has no match in frame {scene.frame_id!r}")
    ids = {e.id for e in scene.entities}
    pairs = tuple(dict.fromkeys(p for b in bindings for p in b))
    stray = next((eid for _, eid in pairs if eid not in ids), None)
    if stray is not None:
        raise UserError(f"{matches} binds {stray!r} in frame {scene.frame_id!r}, which the scene does not have "
                        "(matches of other frames?)")
    return pairs


def _scene(scene) -> Scene:
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, dict):
        try:
            return scene_from_dict(scene)
        except SceneError as exc:
            raise UserError(str(exc)) from None

    return read_scene(str(scene))


def _program(program, programs, scene: Scene) -> tuple[Program | None, str]:
    """The program to draw and how to name it in a message."""
    if programs is not None:
        from pipeline.programs import program_of_frame  # pyarrow, pandas: only --programs reads Parquet

        text = program_of_frame(programs, scene.frame_id)
        if text is None:
            raise UserError(f"{programs} has no program for frame {scene.frame_id!r}")
        try:
            return parse_program(text), f"the program of {scene.frame_id} in {programs}"
        except DslError as exc:
            raise UserError(f"{programs}, frame {scene.frame_id}: {exc}") from None
    if isinstance(program, str):
        try:
            return parse_program(program), "the program"
        except DslError as exc:
            raise UserError(f"the program: {exc}") from None
    return program, "the program"
