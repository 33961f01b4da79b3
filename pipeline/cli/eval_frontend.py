"""`r2s eval-frontend PRED GT --out DIR`: detection metrics of predicted frames against ground truth (Table 4).

Both files are frames.parquet (same frame ids; the ego row of each frame is the origin, not a detection).
Writes DIR/metrics.json, DIR/table.md (the paper's Table 4 layout) and DIR/recall_by_range.png.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

from pipeline.evaluation.frontend import DEFAULT_MAX_DISTANCE


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("pred", help="predicted frames Parquet (a detector's output in the frames schema)")
    p.add_argument("gt", help="ground-truth frames Parquet (same frame ids)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory for metrics.json, table.md and the plot")
    p.add_argument("--max-distance", type=float, default=DEFAULT_MAX_DISTANCE, metavar="M",
                   help=f"reject matched pairs farther apart than this (default {DEFAULT_MAX_DISTANCE:g} m)")
    p.add_argument("--name", metavar="TEXT", help="method name in table.md (default: the PRED file name)")


def objects_by_frame(df) -> dict:
    """frame_id -> its non-ego objects as Detected, range measured from the frame's ego row."""
    from pipeline.evaluation.frontend import Detected

    out = {}
    for fid, rows in df.groupby("frame_id", sort=False):
        ego = rows[rows["is_ego"].astype(bool)].iloc[0]
        others = rows[~rows["is_ego"].astype(bool)]
        out[str(fid)] = tuple(
            Detected(str(r.type), float(r.x), float(r.y), float(r.heading),
                     math.hypot(float(r.x) - float(ego.x), float(r.y) - float(ego.y)))
            for r in others.itertuples(index=False)
        )
    return out


def run(args: argparse.Namespace) -> int:
    from extractors.atomic import write_text_atomic
    from extractors.frames import read_frames
    from pipeline.errors import UserError
    from pipeline.evaluation.frontend import evaluate, metrics, table_md

    if not (math.isfinite(args.max_distance) and args.max_distance > 0):
        raise UserError(f"--max-distance must be a positive number of metres, got {args.max_distance!r}")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"--out {out} exists and is not a directory")
    pred, gt = read_frames(args.pred), read_frames(args.gt)
    ev = evaluate(objects_by_frame(gt), objects_by_frame(pred), args.max_distance)
    if not ev.frames:
        raise UserError(f"{args.pred} and {args.gt} have no frames")
    doc = metrics(ev)
    method = args.name or Path(args.pred).stem
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "metrics.json", json.dumps({"method": method, **doc}, indent=1, allow_nan=False) + "\n")
    write_text_atomic(out / "table.md", table_md(doc, method))
    plot(ev, doc, method, out / "recall_by_range.png")
    o = doc["overall"]
    print(f"{method}: {len(ev.frames)} frames, TP {o['tp']} FP {o['fp']} FN {o['fn']}, F1 "
          f"{'-' if o['f1'] is None else format(o['f1'], '.3f')}; wrote {out}/metrics.json, table.md, recall_by_range.png")
    if ev.only_in_gt or ev.only_in_pred:
        print(f"note: {len(ev.only_in_gt)} frame(s) only in the ground truth (all FN), "
              f"{len(ev.only_in_pred)} only in the predictions (all FP)")
    return 0


def plot(ev, doc: dict, method: str, path: Path) -> None:
    """Recall by range bucket per category (left) and the matched pairs' error histograms (right)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from pipeline.variants.render import save

    buckets = doc["protocol"]["range_buckets_m"]
    series = {"all": doc["recall_by_range"]} | {t: c["recall_by_range"] for t, c in doc["per_category"].items()}
    fig = Figure(figsize=(12, 4.2), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    ax, ax_pos, ax_head = fig.subplots(1, 3, width_ratios=(2.2, 1, 1))
    width = 0.8 / max(1, len(series))
    for k, (name, rbr) in enumerate(series.items()):
        xs = [i + (k - (len(series) - 1) / 2) * width for i in range(len(buckets))]
        # "all" in black; categories from a 20-colour cycle so that up to 20 stay distinct.
        color = "#202020" if k == 0 else _tab20(k - 1)
        ax.bar(xs, [rbr[b]["recall"] or 0.0 for b in buckets], width, label=name, color=color)
    ax.set_xticks(range(len(buckets)), [f"{b} m" for b in buckets])
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("recall")
    ax.set_title(f"{method}: recall by range from ego")
    ax.legend(fontsize=7, ncols=2)
    pairs = [q for f in ev.frames for q in f.pairs]
    ax_pos.hist([q.position_error for q in pairs], bins=20, range=(0, ev.max_distance), color="#4c72b0")
    ax_pos.set_xlabel("position error (m)")
    ax_pos.set_title("matched pairs")
    ax_head.hist([q.heading_error for q in pairs], bins=36, range=(0, 180), color="#dd8452")
    ax_head.set_xlabel("heading error (deg)")
    save(fig, path)  # atomic, and without version or date metadata: the same inputs give the same bytes


def _tab20(i: int):
    from matplotlib import colormaps

    return colormaps["tab20"](i % 20)
