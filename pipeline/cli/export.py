"""`r2s export SCENE.json [VARIANT.json ... | DIR] --to scenarionet|openscenario --out DIR`: the recorded frame and
its variants back in the source's world, as scenarios simulators replay (docs/cli.md, docs/formats.md "Exported
scenarios"); `r2s export SCENE.json|F.maps --to opendrive --out F.xodr`: the road alone, linked OpenDRIVE.

SCENE.json is what `r2s scene` writes (its `world` and `road`); the variants what `r2s sample` writes (a
directory of them may be given). `--to scenarionet` writes a ScenarioNet database (MetaDrive replays it);
`--to openscenario` an OpenSCENARIO 1.2 file per scenario and one OpenDRIVE road built from the scene's lanes
(esmini replays them). A scene without a road exports to ScenarioNet with an empty map (said on stdout) and is
refused by OpenSCENARIO (one line, exit 2)."""

from __future__ import annotations

import argparse
from pathlib import Path

from pipeline.cli.options import bounded_int
from pipeline.errors import UserError
from pipeline.export import FRAMES, ROAD_ONLY, TARGETS
from pipeline.outputs import check_apart, check_folder


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", metavar="SCENE.json", help="the recorded frame (r2s scene: with its world and road); "
                   "for --to opendrive also a maps dataset (r2s extract's F.maps)")
    p.add_argument("variants", nargs="*", metavar="VARIANT", help="variants (r2s sample's scene JSON), or "
                   "directories of them (their *.json files)")
    p.add_argument("--to", required=True, choices=TARGETS + (ROAD_ONLY,), help="scenarionet: a ScenarioNet "
                   "database; openscenario: .xosc files and one .xodr road; opendrive: the road alone, one .xodr file")
    p.add_argument("--out", required=True, metavar="DIR", help="the output directory, replaced whole: absent, empty "
                   "or an earlier export (--to opendrive: the .xodr file, written atomically)")
    p.add_argument("--map", metavar="ID", help="--to opendrive from a maps dataset of several maps: the map to write")
    p.add_argument("--frame", choices=FRAMES, default="world", help="--to opendrive from a scene JSON: world (the "
                   "source's world frame, recentred; default) or ego (the scene's ego frame, which its Scenic text "
                   "is in: r2s synth --road)")
    p.add_argument("--program", metavar="P", help="the program the variants were sampled from (.dsl or .scenic): "
                   "named in every scenario's metadata; a clip program (.json of r2s synth A.json B.json ... "
                   "--behaviours --format json) whose clip starts at SCENE: --steps moves the entities by its "
                   "behaviours")
    p.add_argument("--steps", type=bounded_int(1, 10_000), default=1, metavar="T",
                   help="steps of 0.1 s per scenario: each entity moves on at its speed along its heading, or with a "
                        "clip program by its behaviour (default 1: the instant)")
    p.add_argument("--clip", action="store_true", help="SCENE and the files after it are a clip's frames (scene JSON "
                   "of one scene, in time order, as r2s synth takes a clip): one scenario of their whole trajectories")
    p.add_argument("--scene", dest="scene_name", metavar="S", help="SCENE is a frames file or dataset (r2s simulate's output too): "
                   "export its scene S, every frame in time order, as one scenario of its whole trajectories")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import read_scene, read_text_file
    from pipeline.export.behaviour_motion import read_behaviours
    from pipeline.export.clip import read_clip_files, read_clip_frames
    from pipeline.export.stage import EXPORTED, ExportOptions, export, export_clip, exported, variant_files

    if args.to == ROAD_ONLY:
        return _road(args)
    if args.map is not None:
        raise UserError("--map is for --to opendrive from a maps dataset")
    if args.frame != "world":
        raise UserError("--frame is for --to opendrive: the frame of the road written alone")
    if args.clip and args.scene_name is not None:
        raise UserError("give --clip (scene JSON files) or --scene S (a frames file or dataset), not both")
    clip = args.clip or args.scene_name is not None
    if clip and args.steps != 1:
        raise UserError("--steps is for one frame: a clip is exported at its own frames' times")
    if args.scene_name is not None and args.variants:
        raise UserError("--scene S exports one scene of a frames file or dataset: give no other inputs")
    out = Path(args.out)
    check_apart(out, [("scene", args.scene), ("program", args.program)]
                + [("variant", v) for v in args.variants], directory=True)
    check_folder(out, exported, EXPORTED)  # before any input is read: an earlier export's, or empty, or new
    program = read_text_file(args.program, "program") if args.program else None
    program_file = Path(args.program).name if args.program else None
    behaviours = read_behaviours(program, args.program) if program is not None and not clip else None
    options = ExportOptions(program if behaviours is None else behaviours.program_text, program_file, args.steps,
                            behaviours)
    what = "a ScenarioNet database" if args.to == "scenarionet" else "OpenSCENARIO 1.2 files on one OpenDRIVE road"
    if clip:
        recorded = (read_clip_frames(args.scene, args.scene_name) if args.scene_name is not None
                    else read_clip_files([args.scene, *args.variants]))
        n, notes = export_clip(recorded, args.to, out, options)
        print(f"wrote the clip {recorded.scene!r} ({len(recorded.scenes)} frames, {recorded.times[-1]:g} s, "
              f"{len(recorded.motion.trajectories)} tracks) to {out}, {what}" + "".join(f"; {x}" for x in notes))
        return 0
    recorded = read_scene(args.scene)
    files = variant_files(args.variants)
    n, notes = export(recorded, files, args.to, out, options)
    print(f"wrote {n} scenarios (the frame and {n - 1} variants) to {out}, {what}" + "".join(f"; {x}" for x in notes))
    return 0


def _road(args: argparse.Namespace) -> int:
    from pipeline.export.opendrive import export_road

    if args.variants or args.program or args.clip or args.scene_name is not None:
        raise UserError("--to opendrive writes the road alone: give no variants, no --program, no --clip or --scene")
    check_apart(args.out, [("input", args.scene)])
    print(export_road(args.scene, args.map, args.out, args.frame))
    return 0
