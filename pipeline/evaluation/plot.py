"""The picture `r2s eval-frontend` writes: recall by range bucket per category and the matched pairs' errors."""

from __future__ import annotations

from pathlib import Path

from pipeline.variants.render import save


def plot(ev, doc: dict, method: str, path: Path) -> None:
    """Recall by range bucket per category (left) and the matched pairs' error histograms (right)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

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
