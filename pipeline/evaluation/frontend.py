"""Detection metrics of a perception frontend against ground truth: the paper's Table 4 protocol (appendix).

Per frame, predictions and ground-truth objects (ego rows excluded: ego is the frame, not a detection) are paired
by the optimal one-to-one assignment on centre distance (Hungarian, scipy's linear_sum_assignment), and pairs
farther than max_distance are then rejected, as the paper words it. A matched pair is a true positive, an
unmatched prediction a false positive, an unmatched ground-truth object a false negative. Matching ignores the
class (the paper scores vehicles as one class); per-category figures attribute a pair to its ground-truth type.
A frame present in only one file counts wholly as misses (ground truth only) or false alarms (predictions only).

Pure math on plain values (objects_by_frame turns frames rows into them): reading files and writing outputs
live in pipeline.cli.eval_frontend, the plot in pipeline.evaluation.plot.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from statistics import median
from typing import Any

import numpy as np

from synth.geometry import angular_difference

# Range buckets (metres from ego) of the recall-by-range breakdown; the last is open.
RANGE_BUCKETS: tuple[tuple[float, float], ...] = ((0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (30.0, math.inf))


@dataclass(frozen=True)
class Detected:
    """One object of one frame (predicted or ground truth), in the ego frame; range = distance to ego."""

    type: str
    x: float
    y: float
    heading: float
    range: float


@dataclass(frozen=True)
class Pair:
    """A true positive: indices into the frame's ground truth and predictions, and its errors."""

    gt: int
    pred: int
    position_error: float
    heading_error: float


@dataclass(frozen=True)
class FrameResult:
    frame_id: str
    gt: tuple[Detected, ...]
    pred: tuple[Detected, ...]
    pairs: tuple[Pair, ...]

    @property
    def tp(self) -> int:
        return len(self.pairs)

    @property
    def fp(self) -> int:
        return len(self.pred) - len(self.pairs)

    @property
    def fn(self) -> int:
        return len(self.gt) - len(self.pairs)


@dataclass(frozen=True)
class Evaluation:
    frames: tuple[FrameResult, ...]
    only_in_gt: tuple[str, ...]  # frames with no prediction row at all: every object a false negative
    only_in_pred: tuple[str, ...]  # frames with no ground truth: every prediction a false positive
    max_distance: float


def bucket_of(distance: float) -> str:
    lo, hi = next(b for b in RANGE_BUCKETS if b[0] <= distance < b[1])
    return f"{lo:g}-{hi:g}" if math.isfinite(hi) else f"{lo:g}+"


def assign(gt: tuple[Detected, ...], pred: tuple[Detected, ...], max_distance: float) -> tuple[Pair, ...]:
    """Optimal one-to-one assignment on centre distance, then pairs farther than max_distance rejected."""
    if not gt or not pred:
        return ()
    from scipy.optimize import linear_sum_assignment

    g = np.array([(o.x, o.y) for o in gt])
    p = np.array([(o.x, o.y) for o in pred])
    cost = np.hypot(g[:, None, 0] - p[None, :, 0], g[:, None, 1] - p[None, :, 1])
    rows, cols = linear_sum_assignment(cost)
    pairs = [
        Pair(int(i), int(j), float(cost[i, j]), angular_difference(gt[i].heading, pred[j].heading))
        for i, j in zip(rows, cols)
        if cost[i, j] <= max_distance
    ]
    return tuple(sorted(pairs, key=lambda q: q.gt))


def evaluate(
    gt: Mapping[str, tuple[Detected, ...]], pred: Mapping[str, tuple[Detected, ...]], max_distance: float
) -> Evaluation:
    """Every frame of either side, in ground-truth order then prediction-only frames."""
    ids = list(gt) + [f for f in pred if f not in gt]
    frames = tuple(
        FrameResult(f, gt.get(f, ()), pred.get(f, ()), assign(gt.get(f, ()), pred.get(f, ()), max_distance))
        for f in ids
    )
    return Evaluation(
        frames=frames,
        only_in_gt=tuple(f for f in gt if f not in pred),
        only_in_pred=tuple(f for f in pred if f not in gt),
        max_distance=max_distance,
    )


def _ratio(num: int, den: int) -> float | None:
    return num / den if den else None


def _median(values: list[float]) -> float | None:
    return float(median(values)) if values else None


def scores(tp: int, fp: int, fn: int, pairs: Iterable[Pair], n_frames: int | None = None) -> dict[str, Any]:
    """Precision, recall, F1 = 2TP / (2TP + FP + FN), median errors; per-frame averages when n_frames given.

    A ratio with nothing to count is None (null in JSON), never a made-up 0 or 1.
    """
    pairs = list(pairs)
    out: dict[str, Any] = {
        "tp": tp, "fp": fp, "fn": fn,
        "precision": _ratio(tp, tp + fp),
        "recall": _ratio(tp, tp + fn),
        "f1": _ratio(2 * tp, 2 * tp + fp + fn),
        "position_error_median_m": _median([q.position_error for q in pairs]),
        "heading_error_median_deg": _median([q.heading_error for q in pairs]),
    }
    if n_frames is not None:
        out.update({f"{k}_per_frame": _ratio(v, n_frames) for k, v in (("tp", tp), ("fp", fp), ("fn", fn))})
    return out


def metrics(ev: Evaluation) -> dict[str, Any]:
    """The metrics.json document: overall, per category (ground-truth type; FP by predicted type), by range."""
    frames = ev.frames
    all_pairs = [q for f in frames for q in f.pairs]
    overall = scores(sum(f.tp for f in frames), sum(f.fp for f in frames), sum(f.fn for f in frames), all_pairs,
                     n_frames=len(frames))
    types = sorted({o.type for f in frames for o in f.gt + f.pred})
    matched_pred = {(f.frame_id, q.pred) for f in frames for q in f.pairs}
    per_category = {}
    for t in types:
        pairs = [(f, q) for f in frames for q in f.pairs if f.gt[q.gt].type == t]
        gt_n = sum(o.type == t for f in frames for o in f.gt)
        fp = sum(o.type == t and (f.frame_id, j) not in matched_pred for f in frames for j, o in enumerate(f.pred))
        entry = scores(len(pairs), fp, gt_n - len(pairs), [q for _, q in pairs])
        entry["recall_by_range"] = _recall_by_range(frames, t)
        per_category[t] = entry
    return {
        "protocol": {
            "matching": "optimal one-to-one assignment on centre distance (Hungarian), then pairs farther than "
                        "max_distance rejected; class-agnostic; ego rows excluded",
            "max_distance_m": ev.max_distance,
            "range_buckets_m": [bucket_of(lo) for lo, _ in RANGE_BUCKETS],
        },
        "frames": len(frames),
        "frames_only_in_gt": list(ev.only_in_gt),
        "frames_only_in_pred": list(ev.only_in_pred),
        "overall": overall,
        "recall_by_range": _recall_by_range(frames, None),
        "per_category": per_category,
    }


def _recall_by_range(frames: tuple[FrameResult, ...], only_type: str | None) -> dict[str, dict[str, Any]]:
    """Ground-truth objects per range bucket (distance to ego), how many were matched, recall."""
    gt_n = {bucket_of(lo): 0 for lo, _ in RANGE_BUCKETS}
    tp_n = dict(gt_n)
    for f in frames:
        matched = {q.gt for q in f.pairs}
        for i, o in enumerate(f.gt):
            if only_type is None or o.type == only_type:
                b = bucket_of(o.range)
                gt_n[b] += 1
                tp_n[b] += i in matched
    return {b: {"gt": gt_n[b], "tp": tp_n[b], "recall": _ratio(tp_n[b], gt_n[b])} for b in gt_n}


# ---------------------------------------------------------------------------------------------- tables


def _cell(v: float | None, digits: int) -> str:
    return "-" if v is None else f"{v:.{digits}f}"


def table_md(doc: Mapping[str, Any], method: str) -> str:
    """table.md: the paper's Table 4 row for this method, then per category and recall by range."""
    o = doc["overall"]
    lines = [
        f"# Frontend evaluation: {method}",
        "",
        f"{doc['frames']} frames; matching within {doc['protocol']['max_distance_m']:g} m "
        "(Hungarian on centre distance, class-agnostic). TP, FP and FN are per-frame averages; position and "
        "heading errors are medians over matched pairs.",
        "",
        "| Method | Precision | Recall | F1 | TP/img | FP/img | FN/img | Pos. Err. (m) | Head Err. (deg) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
        f"| {method} | {_cell(o['precision'], 3)} | {_cell(o['recall'], 3)} | {_cell(o['f1'], 3)} | "
        f"{_cell(o['tp_per_frame'], 1)} | {_cell(o['fp_per_frame'], 1)} | {_cell(o['fn_per_frame'], 1)} | "
        f"{_cell(o['position_error_median_m'], 2)} | {_cell(o['heading_error_median_deg'], 1)} |",
        "",
    ]
    if doc["frames_only_in_gt"] or doc["frames_only_in_pred"]:
        lines += [
            f"Frames only in the ground truth (all objects counted as FN): {len(doc['frames_only_in_gt'])}; "
            f"only in the predictions (all counted as FP): {len(doc['frames_only_in_pred'])}.",
            "",
        ]
    buckets = doc["protocol"]["range_buckets_m"]
    lines += [
        "## Per category (ground-truth type; FP by predicted type)",
        "",
        "| Category | GT | TP | FP | FN | Precision | Recall | F1 | Pos. Err. (m) | Head Err. (deg) | "
        + " | ".join(f"Recall {b} m" for b in buckets) + " |",
        "|---|" + "---:|" * (9 + len(buckets)),
    ]
    for t, c in doc["per_category"].items():
        rbr = c["recall_by_range"]
        lines.append(
            f"| {t} | {c['tp'] + c['fn']} | {c['tp']} | {c['fp']} | {c['fn']} | {_cell(c['precision'], 3)} | "
            f"{_cell(c['recall'], 3)} | {_cell(c['f1'], 3)} | {_cell(c['position_error_median_m'], 2)} | "
            f"{_cell(c['heading_error_median_deg'], 1)} | "
            + " | ".join(_cell(rbr[b]["recall"], 3) for b in buckets) + " |"
        )
    lines += ["", "## Recall by range (all categories)", "", "| Range (m) | GT | TP | Recall |", "|---|---:|---:|---:|"]
    for b, r in doc["recall_by_range"].items():
        lines.append(f"| {b} | {r['gt']} | {r['tp']} | {_cell(r['recall'], 3)} |")
    return "\n".join(lines) + "\n"


def objects_by_frame(df) -> dict:
    """frame_id -> its non-ego objects as Detected, range measured from the frame's ego row."""
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
