"""`r2s eval-frontend PRED GT --out DIR`: detection metrics of predicted frames against ground truth (Table 4).

Both files are frames.parquet (same frame ids; the ego row of each frame is the origin, not a detection).
Writes DIR/metrics.json, DIR/table.md (the paper's Table 4 layout) and DIR/recall_by_range.png.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from pipeline.errors import UserError
from pipeline.evaluation import DEFAULT_MAX_DISTANCE


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("pred", help="predicted frames Parquet (a detector's output in the frames schema)")
    p.add_argument("gt", help="ground-truth frames Parquet (same frame ids)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for metrics.json, table.md and the plot")
    p.add_argument("--max-distance", type=float, default=DEFAULT_MAX_DISTANCE, metavar="M",
                   help=f"reject matched pairs farther apart than this (default {DEFAULT_MAX_DISTANCE:g} m)")
    p.add_argument("--name", metavar="TEXT", help="method name in table.md (default: the PRED file name)")


def run(args: argparse.Namespace) -> int:
    from frames.rows import read_frames
    from pipeline.evaluation.frontend import evaluate, metrics, objects_by_frame, table_md
    from pipeline.evaluation.plot import plot
    from pipeline.outputs import check_apart, output_place, writing
    from storage.atomic import write_text_atomic

    if not (math.isfinite(args.max_distance) and args.max_distance > 0):
        raise UserError(f"--max-distance must be a positive number of metres, got {args.max_distance!r}")
    out = Path(args.out)
    check_apart(out, [("predictions", args.pred), ("ground truth", args.gt)], directory=True)
    folder = output_place(out)  # a link to a folder is written through
    if folder.exists() and not folder.is_dir():
        raise UserError(f"--out {out} exists and is not a directory")
    pred, gt = read_frames(args.pred), read_frames(args.gt)
    ev = evaluate(objects_by_frame(gt), objects_by_frame(pred), args.max_distance)
    if not ev.frames:
        raise UserError(f"{args.pred} and {args.gt} have no frames")
    doc = metrics(ev)
    method = args.name or Path(args.pred).stem
    with writing(out):
        folder.mkdir(parents=True, exist_ok=True)
        write_text_atomic(folder / "metrics.json", json.dumps({"method": method, **doc}, indent=1, allow_nan=False)
                          + "\n")
        write_text_atomic(folder / "table.md", table_md(doc, method))
        plot(ev, doc, method, folder / "recall_by_range.png")
    o = doc["overall"]
    print(f"{method}: {len(ev.frames)} frames, TP {o['tp']} FP {o['fp']} FN {o['fn']}, F1 "
          f"{'-' if o['f1'] is None else format(o['f1'], '.3f')}; wrote {out}/metrics.json, table.md, recall_by_range.png")
    if ev.only_in_gt or ev.only_in_pred:
        print(f"note: {len(ev.only_in_gt)} frame(s) only in the ground truth (all FN), "
              f"{len(ev.only_in_pred)} only in the predictions (all FP)")
    return 0
