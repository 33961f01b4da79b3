"""The PNG plots of `r2s report`. matplotlib is imported here only, and lazily, so other verbs never pay for it.

Figures are built with matplotlib.figure.Figure (no pyplot: no global figure state between plots) on the Agg
canvas, coloured with the Okabe-Ito palette (safe for the common colour-vision deficiencies) and told apart by
marker shape as well, so they also read in greyscale.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.report.stats import (
    ABSOLUTE_COST_PER_ENTITY,
    HEADING_KINDS,
    LANE_KINDS,
    MOTION_KINDS,
    POSITION_KINDS,
    GroupStats,
    ProgramsDB,
    RelationUsage,
    bucket_order,
    cost_counts,
    per_n,
    plot_points,
)
from synth.parts import CLAUSE_KINDS

# Okabe & Ito (2008), most distinct first.
PALETTE = ("#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442", "#000000")
MARKERS = ("o", "s", "^", "D", "v", "P", "X", "*")
REFERENCE = "#555555"  # the absolute-coordinate baseline and other guides
DPI = 110
KIND_COST = {k.label: k.cost for k in CLAUSE_KINDS}  # synth.parts: the clause's cost
# Every file all_plots writes, in report order; `r2s report` may replace a directory holding only these.
PLOT_FILES = ("runtime_vs_n.png", "cost_vs_n.png", "cost_distribution.png", "cost_vs_absolute.png",
              "relation_usage.png")


@dataclass(frozen=True)
class Plot:
    filename: str
    title: str
    caption: str


def _style(i: int) -> tuple[str, str]:
    return PALETTE[i % len(PALETTE)], MARKERS[i % len(MARKERS)]


def _figure(width: float = 7.5, height: float = 4.6, ncols: int = 1):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, ncols, squeeze=False)[0]
    for ax in axes:
        ax.grid(True, color="#dddddd", linewidth=0.7)
        ax.set_axisbelow(True)
        for side in ("top", "right"):
            ax.spines[side].set_visible(False)
    return fig, axes


def _legend(fig) -> None:
    """One legend for the figure, below the axes, so it never hides a point or a bar."""
    handles, labels = [], []
    for ax in fig.axes:
        for h, label in zip(*ax.get_legend_handles_labels()):
            if label not in labels:
                handles.append(h)
                labels.append(label)
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4), frameon=False, fontsize=9)


def _no_data(ax, what: str) -> None:
    """Say so on an empty plot, rather than leave bare axes that look like a rendering bug."""
    ax.text(0.5, 0.5, f"no data: {what}", transform=ax.transAxes, ha="center", va="center", color=REFERENCE,
            fontsize=11)


def _save(fig, path: Path) -> None:
    # No Software/date metadata: the same programs file gives byte-identical PNGs.
    fig.savefig(path, format="png", metadata={"Software": None})


def _points(ax, x, y, i: int, label: str) -> None:
    """Hollow markers of distinct shapes: where two configs give the same (N, value) both stay visible."""
    colour, marker = _style(i)
    ax.scatter(x, y, s=36, marker=marker, facecolors="none", edgecolors=colour, linewidths=1.3, label=label)


@dataclass(frozen=True)
class Points:
    """What the scatter plots draw: every row, or a sample per config past PLOT_POINTS (then per_n adds the
    line over every row, so the sample shows the spread and the line the trend)."""

    rows: object  # DataFrame: config, status, n_entities, runtime_s, cost
    totals: dict[str, int]  # rows per config
    per_n: object  # DataFrame: config, n_entities, runtime_median, mean_cost

    def sampled(self, config: str) -> bool:
        return int((self.rows["config"] == config).sum()) < self.totals.get(config, 0)

    def note(self, configs) -> str:
        sampled = [c for c in configs if self.sampled(c)]
        if not sampled:
            return ""
        shown = int((self.rows["config"] == sampled[0]).sum())
        return (f" Past {shown:,} frames a config is drawn from a fixed sample of {shown:,} frames (the same frames "
                "for every config); the line follows every frame.")


def runtime_vs_n(pts: Points, configs: tuple[str, ...], path: Path) -> Plot:
    fig, (ax,) = _figure()
    frame = pts.rows
    for i, config in enumerate(configs):
        colour, _ = _style(i)
        rows = frame[(frame["config"] == config) & (frame["status"] != "error") & frame["runtime_s"].notna()]
        done = rows[rows["status"] == "optimal"]
        unproven = rows[rows["status"] == "feasible"]
        stopped = rows[rows["status"].isin(("timeout", "memout"))]
        # Sub-0.1 ms runtimes would sit at -inf on a log axis; they are clamped to the axis floor instead.
        if len(done):
            _points(ax, done["n_entities"], done["runtime_s"].clip(lower=1e-4), i, config)
        if len(unproven):  # stopped at a limit with a program: the time is the limit, not a finishing time
            ax.scatter(unproven["n_entities"], unproven["runtime_s"].clip(lower=1e-4), s=55, color=colour, marker="+",
                       linewidths=1.5, label=f"{config}: feasible (stopped, not proven)")
        if len(stopped):
            ax.scatter(stopped["n_entities"], stopped["runtime_s"].clip(lower=1e-4), s=60, color=colour, marker="x",
                       linewidths=1.8, label=f"{config}: timeout / memout")
        line = pts.per_n[(pts.per_n["config"] == config) & pts.per_n["runtime_median"].notna()]
        if pts.sampled(config) and len(line):
            ax.plot(line["n_entities"], line["runtime_median"].clip(lower=1e-4), color=colour, linewidth=1.6,
                    label=f"{config}: median per N (every frame)")
    if not ax.collections:
        _no_data(ax, "no frame ran (every row is an error)")
    ax.set_yscale("log")
    ax.set_xlabel("entities in the frame, N (ego excluded)")
    ax.set_ylabel("runtime per frame (s, log scale)")
    ax.set_title("Synthesis runtime against scene size")
    _legend(fig)
    _save(fig, path)
    return Plot(path.name, "Runtime against N",
                "Wall-clock seconds per frame (log scale): open markers are proven optima, plus signs programs found "
                "before a limit without a proof, crosses frames stopped by the time or memory limit."
                + pts.note(configs))


def cost_vs_n(pts: Points, configs: tuple[str, ...], path: Path) -> Plot:
    fig, (ax,) = _figure()
    rows = pts.rows[pts.rows["cost"].notna()]
    n_max = max(int(rows["n_entities"].max()) if len(rows) else 1, 1)
    xs = np.array([0, n_max])
    ax.plot(xs, ABSOLUTE_COST_PER_ENTITY * xs, color=REFERENCE, linestyle="--", linewidth=1.2,
            label=f"absolute coordinates ({ABSOLUTE_COST_PER_ENTITY} N)")
    for i, config in enumerate(configs):
        r = rows[rows["config"] == config]
        if len(r):
            _points(ax, r["n_entities"], r["cost"], i, config)
        line = pts.per_n[(pts.per_n["config"] == config) & pts.per_n["mean_cost"].notna()]
        if pts.sampled(config) and len(line):
            ax.plot(line["n_entities"], line["mean_cost"], color=_style(i)[0], linewidth=1.6,
                    label=f"{config}: mean per N (every frame)")
    if rows.empty:
        _no_data(ax, "no frame produced a program")
    ax.set_xlabel("entities in the frame, N (ego excluded)")
    ax.set_ylabel("program cost")
    ax.set_title("Program cost against scene size")
    ax.set_xlim(0, n_max * 1.03)
    # Scaled to the programs, not to the 4N line: relational programs cost a fraction of it and would
    # otherwise lie flat on the axis. The line leaves through the top where it outgrows them.
    ax.set_ylim(0, max(float(rows["cost"].max()) * 1.3 if len(rows) else 0.0, 8.0))
    _legend(fig)
    _save(fig, path)
    return Plot(path.name, "Cost against N",
                f"Cost of each synthesized program; the dashed line is the absolute-coordinate program "
                f"({ABSOLUTE_COST_PER_ENTITY} per entity)." + pts.note(configs))


def cost_distribution(counts, configs: tuple[str, ...], path: Path) -> Plot:
    """Histograms binned from (config, cost, N, rows) counts: every frame counts, none is drawn one by one."""
    fig, (left, right) = _figure(width=9.5, ncols=2)
    from matplotlib.ticker import MaxNLocator

    top = int(counts["cost"].max()) if len(counts) else 1
    # Integer costs: one bin per value while that stays readable, else 30 bins of whole costs.
    step = max(1, int(np.ceil((top + 1) / 30)))
    cost_bins = np.arange(0, top + step + 1, step) - 0.5
    per_entity = (counts["cost"] / counts["n_entities"]).where(counts["n_entities"] > 0)
    ratio_top = max(float(per_entity.max()) if per_entity.notna().any() else 0.0, 0.5)
    ratio_bins = np.linspace(0, min(ABSOLUTE_COST_PER_ENTITY, np.ceil(ratio_top * 4) / 4), 21)
    shown = [c for c in configs if (counts["config"] == c).any()]
    for ax, values, bins in ((left, counts["cost"], cost_bins), (right, per_entity, ratio_bins)):
        width = (bins[1] - bins[0]) * 0.85 / max(len(shown), 1)
        for j, config in enumerate(shown):
            colour, _ = _style(configs.index(config))
            mine = (counts["config"] == config) & values.notna()
            hist, edges = np.histogram(values[mine].astype(float).clip(upper=bins[-1]), bins=bins,
                                       weights=counts["rows"][mine])
            # Side by side within each bin: overlaid histograms of equal programs would hide each other.
            left_edges = edges[:-1] + (bins[1] - bins[0]) * 0.075 + j * width
            ax.bar(left_edges, hist, width=width, align="edge", color=colour, label=config)
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylabel("frames")
    if not shown:
        for ax in (left, right):
            _no_data(ax, "no frame produced a program")
    left.set_xlabel("program cost")
    left.set_title("Program cost")
    right.set_xlabel(f"cost per entity (absolute coordinates: {ABSOLUTE_COST_PER_ENTITY})")
    right.set_title("Cost per entity")
    fig.suptitle("Distribution of program cost")
    _legend(fig)
    _save(fig, path)
    return Plot(path.name, "Cost distribution", "How many frames got each cost, in total and per entity.")


def _grouped_barh(ax, kinds: tuple[str, ...], usage: RelationUsage, configs: tuple[str, ...],
                  shown: list[str]) -> None:
    k = max(len(shown), 1)
    height = 0.8 / k
    y = np.arange(len(kinds))
    for i, config in enumerate(shown):
        colour, _ = _style(configs.index(config))
        values = [int(usage.counts.loc[kind, config]) for kind in kinds]
        bars = ax.barh(y + (i - (k - 1) / 2) * height, values, height=height, color=colour, label=config)
        ax.bar_label(bars, padding=2, fontsize=7)
    ax.set_yticks(y, [f"{kind} ({KIND_COST[kind]})" for kind in kinds])
    ax.invert_yaxis()
    ax.set_xlabel("uses in all programs")
    ax.margins(x=0.15)


def relation_usage(usage: RelationUsage, configs: tuple[str, ...], path: Path) -> Plot:
    shown = [c for c in configs if usage.counts[c].sum() > 0]  # configs without a program have nothing to show
    height = max(3.6, 1.4 + 0.22 * len(POSITION_KINDS) * max(len(shown), 1))
    panels = [(POSITION_KINDS, "Position relations (cost)"), (HEADING_KINDS, "Heading relations (cost)")]
    if usage.motion:
        panels.append((MOTION_KINDS, "Motion relations (cost)"))
    if usage.lanes:
        panels.append((LANE_KINDS, "Lane relations (cost)"))
    fig, axes = _figure(width=5.25 * len(panels), height=height, ncols=len(panels))
    for ax, (kinds, title) in zip(axes, panels):
        _grouped_barh(ax, kinds, usage, configs, shown)
        if not shown:
            _no_data(ax, "no program to count")
        ax.set_title(title)
    fig.suptitle("Relation usage in the synthesized programs")
    _legend(fig)
    _save(fig, path)
    return Plot(path.name, "Relation usage",
                "Relations the programs use: directional (ahead / behind / left / right of, facing toward / away "
                "from) cost 0, relative fallbacks cost 1, absolute coordinates cost 2.")


def versus_absolute(stats: list[GroupStats], configs: tuple[str, ...], path: Path) -> Plot:
    buckets = bucket_order(s.bucket for s in stats)
    fig, (ax,) = _figure(width=max(7.5, 1.4 * len(buckets) + 2))
    ratios = {c: {s.bucket: s.absolute_ratio for s in stats if s.config == c and s.absolute_ratio is not None}
              for c in configs}
    shown = [c for c in configs if ratios[c]]
    k = max(len(shown), 1)
    width = 0.8 / k
    x = np.arange(len(buckets))
    for i, config in enumerate(shown):
        colour, _ = _style(configs.index(config))
        ratio = ratios[config]
        xs = [x[j] + (i - (k - 1) / 2) * width for j, b in enumerate(buckets) if b in ratio]
        values = [100.0 * ratio[b] for b in buckets if b in ratio]
        bars = ax.bar(xs, values, width=width, color=colour, label=config)
        ax.bar_label(bars, fmt="%.0f%%", padding=2, fontsize=7)
    if not shown:
        _no_data(ax, "no frame produced a program")
    ax.axhline(100.0, color=REFERENCE, linestyle="--", linewidth=1.2, label="absolute coordinates")
    ax.set_xticks(x, [f"N {b}" for b in buckets])
    ax.set_xlabel("entities in the frame (bucket)")
    ax.set_ylabel(f"mean cost / ({ABSOLUTE_COST_PER_ENTITY} N), %")
    ax.set_ylim(0, 110)
    ax.set_title("Cost relative to the absolute-coordinate program")
    _legend(fig)
    _save(fig, path)
    return Plot(path.name, "Against absolute coordinates",
                f"Mean of each program's cost divided by the absolute-coordinate program's ({ABSOLUTE_COST_PER_ENTITY} "
                "per entity): lower is more relational; 100% would be no better than coordinates.")


def all_plots(db: ProgramsDB, buckets: list[GroupStats], usage: RelationUsage, out: Path) -> list[Plot]:
    """Write every plot of PLOT_FILES into out; returns them in that order."""
    runtime, cost, dist, absolute, relations = (out / name for name in PLOT_FILES)
    configs = db.overview.configs
    rows, totals = plot_points(db)
    pts = Points(rows, totals, per_n(db))
    return [
        runtime_vs_n(pts, configs, runtime),
        cost_vs_n(pts, configs, cost),
        cost_distribution(cost_counts(db), configs, dist),
        versus_absolute(buckets, configs, absolute),
        relation_usage(usage, configs, relations),
    ]
