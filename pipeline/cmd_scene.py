"""`r2s scene frames.parquet FRAME_ID`: one frame of a frames file as scene JSON (the input of `r2s synth`)."""

from __future__ import annotations

import argparse
import sys


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("frames", help="frames Parquet file (from r2s extract)")
    p.add_argument("frame_id", help="frame id, e.g. scene-0061/3")
    p.add_argument("--out", metavar="F", help="write the JSON to this file (atomically) instead of stdout")


def run(args: argparse.Namespace) -> int:
    import difflib

    from extractors.atomic import write_text_atomic
    from extractors.frames import frame_to_scene, read_frames
    from pipeline.errors import UserError

    df = read_frames(args.frames)
    rows = df[df["frame_id"] == args.frame_id]
    if rows.empty:
        ids = list(dict.fromkeys(df["frame_id"]))
        close = difflib.get_close_matches(args.frame_id, ids, n=3, cutoff=0.5)
        hint = f"; did you mean {', '.join(close)}?" if close else f" ({len(ids)} frames, e.g. {ids[0]})" if ids else ""
        raise UserError(f"{args.frames} has no frame {args.frame_id!r}{hint}")
    text = frame_to_scene(rows).to_json()
    if args.out:
        write_text_atomic(args.out, text)
    else:
        sys.stdout.write(text)
    return 0
