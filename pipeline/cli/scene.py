"""`r2s scene FRAMES FRAME_ID`: one frame of a frames file or dataset as scene JSON (the input of `r2s synth`).

Only the frame's own rows are read (row-group statistics skip the rest of a large dataset) and checked. A frame
that names a map gets its road: the map features within --radius of ego, from the maps beside the frames
(extractors.maps), brought into the frame's ego frame by the ego's place in the map (its map_x, map_y,
map_heading), and each entity its lane facts."""

from __future__ import annotations

import argparse
import sys

from pipeline.errors import UserError
from pipeline.outputs import check_apart

# Beyond this many frames, "did you mean" only looks at ids of the same scene (the part before the last '/').
MAX_HINT_POOL = 200_000


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file or directory (from r2s extract)")
    p.add_argument("frame_id", help="frame id, e.g. scene-0061/3")
    p.add_argument("--out", metavar="F", help="write the JSON to this file (atomically) instead of stdout")
    # the default is extractors.maps.SCENE_RADIUS (the roads r2s run --lanes synthesizes on), written out here so
    # that `r2s scene --help` does not load pyarrow
    p.add_argument("--radius", type=float, default=50.0, metavar="M",
                   help="the road: map features within M metres of ego (default 50, r2s extract's radius)")


def run(args: argparse.Namespace) -> int:
    from extractors.frames import frame_to_scene, validate_frames
    from extractors.frames_dataset import FramesDataset
    from storage.atomic import write_text_atomic

    check_apart(args.out, [("input frames", args.frames)])
    dataset = FramesDataset.open(args.frames)
    table = dataset.find(args.frame_id)
    if table is None:
        raise UserError(f"{args.frames} has no frame {args.frame_id!r}{_hint(dataset, args.frame_id)}")
    if not args.radius > 0:
        raise UserError(f"--radius must be positive, got {args.radius}")
    rows = table.to_pandas()
    validate_frames(rows)
    text = frame_to_scene(rows, _road(args.frames, rows, args.radius)).to_json()
    if args.out:
        write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    return 0


def _road(frames: str, rows, radius: float):
    """The frame's road in its ego frame, or None when the frame names no map (its maps missing: a warning)."""
    from extractors.maps import FrameRoads, maps_dir

    road, missing = FrameRoads(maps_dir(frames), radius).road(rows)
    if missing is not None:
        sys.stderr.write(f"r2s scene: warning: the frame names map {missing!r}, which is not in {maps_dir(frames)}; "
                         "the scene has no road\n")
    return road


def _hint(dataset, frame_id: str) -> str:
    import difflib

    scene = frame_id.rsplit("/", 1)[0]
    pool, count, example = [], 0, None
    for runs in dataset.runs():
        for fid in runs.ids:
            example = example or fid
            count += 1
            if count <= MAX_HINT_POOL or fid.rsplit("/", 1)[0] == scene:
                pool.append(fid)
    close = difflib.get_close_matches(frame_id, pool, n=3, cutoff=0.5)
    return f"; did you mean {', '.join(close)}?" if close else f" ({count} frames, e.g. {example})" if example else ""
