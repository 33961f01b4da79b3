"""`r2s scene FRAMES FRAME_ID`: one frame of a frames file or dataset as scene JSON (the input of `r2s synth`).

What it does is pipeline.scenes.scene (`from pipeline import scene`): only the frame's own rows are read, and a
frame that names a map gets its road."""

from __future__ import annotations

import argparse
import sys

from pipeline.outputs import check_apart, writing
from storage.atomic import write_text_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file or directory (from r2s extract)")
    p.add_argument("frame_id", help="frame id, e.g. scene-0061/3")
    p.add_argument("--out", metavar="F", help="write the JSON to this file (atomically) instead of stdout")
    # the default is frames.maps.SCENE_RADIUS (the roads r2s run --lanes synthesizes on), written out here so
    # that `r2s scene --help` does not load pyarrow
    p.add_argument("--radius", type=float, default=50.0, metavar="M",
                   help="the road: map features within M metres of ego (default 50, r2s extract's radius)")


def run(args: argparse.Namespace) -> int:
    from pipeline.scenes import scene

    check_apart(args.out, [("input frames", args.frames)])
    text = scene(args.frames, args.frame_id, radius=args.radius).to_json()
    if args.out:
        with writing(args.out):
            write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    return 0
