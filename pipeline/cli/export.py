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
                   "named in every scenario's metadata")
    p.add_argument("--steps", type=bounded_int(1, 10_000), default=1, metavar="T",
                   help="steps of 0.1 s per scenario: each entity moves on at its speed along its heading "
                        "(default 1: the instant)")


def run(args: argparse.Namespace) -> int:
    from pipeline.cli.inputs import read_scene, read_text_file
    from pipeline.export.stage import EXPORTED, ExportOptions, export, exported, variant_files

    if args.to == ROAD_ONLY:
        return _road(args)
    if args.map is not None:
        raise UserError("--map is for --to opendrive from a maps dataset")
    if args.frame != "world":
        raise UserError("--frame is for --to opendrive: the frame of the road written alone")
    out = Path(args.out)
    check_apart(out, [("scene", args.scene), ("program", args.program)]
                + [("variant", v) for v in args.variants], directory=True)
    check_folder(out, exported, EXPORTED)  # before any input is read: an earlier export's, or empty, or new
    recorded = read_scene(args.scene)
    files = variant_files(args.variants)
    program = read_text_file(args.program, "program") if args.program else None
    options = ExportOptions(program, Path(args.program).name if args.program else None, args.steps)
    n, notes = export(recorded, files, args.to, out, options)
    what = "a ScenarioNet database" if args.to == "scenarionet" else "OpenSCENARIO 1.2 files on one OpenDRIVE road"
    print(f"wrote {n} scenarios (the frame and {n - 1} variants) to {out}, {what}" + "".join(f"; {x}" for x in notes))
    return 0


def _road(args: argparse.Namespace) -> int:
    from pipeline.export.opendrive import export_road

    if args.variants or args.program:
        raise UserError("--to opendrive writes the road alone: give no variants and no --program")
    check_apart(args.out, [("input", args.scene)])
    print(export_road(args.scene, args.map, args.out, args.frame))
    return 0
