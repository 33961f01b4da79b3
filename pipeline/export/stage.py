"""The export stage: the recorded scene and each variant, read one at a time, put back in the scene's world and
written by the chosen target into a directory staged beside --out (pipeline.outputs.staged_directory: a reader
never sees half a database, a failure leaves nothing, and only an absent or empty folder or an earlier export is
replaced: a folder of the user's files given as --out is refused, not emptied).

The world of every scenario is the recorded scene's (`world`: the ego's recorded pose; a scene without one is
exported with its ego frame as the world), and so is its road (a variant may carry its own of each; OpenSCENARIO
files all stand on the one OpenDRIVE road of the recorded scene). Variants are scene JSON in the same ego frame
(r2s sample keeps the program's ego where the recording has it)."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from pipeline.cli.inputs import read_scene
from pipeline.errors import UserError
from pipeline.export import TARGETS, slug
from pipeline.export.behaviour_motion import Behaviours, by_behaviours, check_program_of
from pipeline.export.clip import Clip
from pipeline.export.motion import Motion, straight
from pipeline.outputs import staged_directory
from synth.road.roadmap import RoadMap
from synth.scene import Scene
from synth.world import WorldPose

MAX_VARIANTS = 10**7


@dataclass(frozen=True)
class Item:
    """One scenario to write: its scene (a clip's first frame), its name (unique in the output), where it came
    from, and what its entities do over its steps (pipeline/export/motion.py)."""

    scene: Scene
    name: str
    variant: str | None  # the variant's file name; None for the recorded frame
    motion: Motion
    clip: Clip | None = None  # a recorded clip's frames (r2s export --clip, FRAMES --scene S)


class Writer(Protocol):
    """What a target writes into the staged output directory."""

    def add(self, item: Item, world: WorldPose, road: RoadMap | None) -> None: ...

    def close(self) -> None: ...


class Target(Protocol):
    name: str
    needs_road: bool  # a target that cannot be written without a road (OpenDRIVE) refuses a scene without one

    def open(self, folder: Path, recorded: Scene, options: ExportOptions) -> Writer: ...

    def owns(self, entry: os.DirEntry) -> bool:
        """Whether a regular file of an output folder is one this target writes (so an earlier export may be
        replaced, and nothing else: storage.folders)."""
        ...


@dataclass(frozen=True)
class ExportOptions:
    program_text: str | None = None  # --program's text and file name, which every scenario names
    program_file: str | None = None
    steps: int = 1  # steps of STEP_S per scenario
    behaviours: Behaviours | None = None  # --program P.json, a clip program: --steps moves entities by it

    def motion(self, scene: Scene, world: WorldPose) -> Motion:
        """What a frame's entities do over --steps: their behaviours with a clip program, else on at their speed."""
        if self.behaviours is None:
            return straight(scene, world, self.steps)
        return by_behaviours(scene, world, self.behaviours, self.steps)


def variant_files(paths: list[str]) -> list[Path]:
    """The variant files: each PATH a scene JSON file, or a directory whose *.json files (sorted) are variants."""
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            out += sorted(f for f in p.iterdir() if f.suffix == ".json" and not f.name.startswith("."))
        elif p.exists():
            out.append(p)
        else:
            raise UserError(f"variant {p} does not exist")
        if len(out) > MAX_VARIANTS:
            raise UserError(f"more than {MAX_VARIANTS:,} variants")
    written: dict[str, Path] = {}
    for f in out:
        # the names their scenarios are written under, as a filesystem that ignores case would compare them
        name = slug(f.stem).casefold()
        if name in written:
            raise UserError(f"the variants {written[name]} and {f} would both be written as {slug(f.stem)!r} "
                            "(file names are kept to letters, digits, '.' and '-'): rename one")
        written[name] = f
    return out


def items(recorded: Scene, files: list[Path], options: ExportOptions, max_entities: int | None = None
          ) -> Iterator[Item]:
    """The recorded scene, then each variant as it is read (one in memory at a time), each with its motion."""
    base = slug(recorded.frame_id)
    yield Item(recorded, base, None, options.motion(recorded, _world(recorded, recorded)))
    for f in files:
        scene = read_scene(str(f), max_entities)
        yield Item(scene, f"{base}-{slug(f.stem)}", f.name, options.motion(scene, _world(scene, recorded)))


def _world(scene: Scene, recorded: Scene) -> WorldPose:
    return scene.world or recorded.world or WorldPose.identity()


EXPORTED = "scenarios of r2s export"


def exported(entry: os.DirEntry) -> bool:
    """What an output folder of r2s export may hold to be replaced: an earlier export's files, of either target."""
    return entry.is_file(follow_symlinks=False) and any(target(t).owns(entry) for t in TARGETS)


def target(name: str) -> Target:
    # a target's writer loads when it is chosen: --to scenarionet does not load OpenSCENARIO's (xml, the road network)
    if name == "scenarionet":
        from pipeline.export.scenarionet import TARGET
    else:
        from pipeline.export.openscenario import TARGET
    return TARGET


def export(recorded: Scene, files: list[Path], to: str, out: Path, options: ExportOptions) -> tuple[int, list[str]]:
    """Write the recorded scene and the variants into `out` (replaced whole); returns the number of scenarios
    and the notes to tell the user (no world pose, no road)."""
    if options.behaviours is not None:
        check_program_of(options.behaviours, recorded, options.program_file or "--program")
    return _write(recorded, items(recorded, files, options), to, out, options)


def export_clip(clip: Clip, to: str, out: Path, options: ExportOptions) -> tuple[int, list[str]]:
    """Write a recorded clip (pipeline/export/clip.py) into `out` as one scenario of its whole trajectories."""
    return _write(clip.first, iter([Item(clip.first, clip.name, None, clip.motion, clip)]), to, out, options)


def _write(recorded: Scene, scenarios: Iterator[Item], to: str, out: Path, options: ExportOptions
           ) -> tuple[int, list[str]]:
    chosen = target(to)
    notes = []
    if recorded.road is None:
        if chosen.needs_road:
            raise UserError(f"{to} needs a road (OpenDRIVE is a road network) and the scene {recorded.frame_id!r} has "
                            "none: export a frame whose source has a map (r2s scene writes its road)")
        notes.append("the scene has no road: the scenarios have an empty map")
    if recorded.world is None:
        notes.append("the scene has no world pose: coordinates are its ego frame's")
    n = 0
    with staged_directory(out, exported, EXPORTED) as stage:
        writer = chosen.open(stage, recorded, options)
        for item in scenarios:
            scene = item.scene
            writer.add(item, _world(scene, recorded), scene.road or recorded.road)
            n += 1
        writer.close()
    return n, notes
