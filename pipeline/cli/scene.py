"""`r2s scene FRAMES FRAME_ID`: one frame of a frames file or dataset as scene JSON (the input of `r2s synth`).

Only the frame's own rows are read (row-group statistics skip the rest of a large dataset) and checked."""

from __future__ import annotations

import argparse
import sys

from pipeline.errors import UserError

# Beyond this many frames, "did you mean" only looks at ids of the same scene (the part before the last '/').
MAX_HINT_POOL = 200_000


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file or directory (from r2s extract)")
    p.add_argument("frame_id", help="frame id, e.g. scene-0061/3")
    p.add_argument("--out", metavar="F", help="write the JSON to this file (atomically) instead of stdout")


def run(args: argparse.Namespace) -> int:
    from extractors.frames import frame_to_scene, validate_frames
    from extractors.frames_dataset import FramesDataset
    from storage.atomic import write_text_atomic

    dataset = FramesDataset.open(args.frames)
    table = dataset.find(args.frame_id)
    if table is None:
        raise UserError(f"{args.frames} has no frame {args.frame_id!r}{_hint(dataset, args.frame_id)}")
    rows = table.to_pandas()
    validate_frames(rows)
    text = frame_to_scene(rows).to_json()
    if args.out:
        write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    return 0


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
