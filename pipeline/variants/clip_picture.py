"""`r2s render A.json B.json ... [--simulated DIR] --out F` (its Python API `render_clip`): a clip's bird's-eye
picture. Over the clip's road (every frame's, in the first frame's ego frame, as the clip's programs read it),
every recorded trajectory as a solid line in its entity's colour (ego red), from a dot at its first place to its
box where it is last; with simulated clips (`--simulated DIR`: every scene of r2s simulate's output, or of any
frames dataset), each one's trajectories of the same entities dashed and translucent in the same colours. A
legend names the styles and the entities that move (the colours), so a simulated path is read against its
recorded one.

Geometry first (pure: `Paths` of a clip in a frame), drawing after (matplotlib's Agg canvas, no pyplot)."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from frames.dataset import FramesDataset
from pipeline.errors import UserError
from pipeline.export.clip import SCENE_COLUMNS, Clip, read_clip_files, read_clip_frames
from pipeline.export.motion import Trajectory
from pipeline.outputs import check_apart, writing
from pipeline.variants.render import (
    EGO_EDGE,
    EGO_FILL,
    ENTITY_PALETTE,
    FORMATS,
    ROAD_STYLES,
    Footprint,
    draw_road,
    save,
)
from synth.world import WorldPose

RECORDED_GID, SIMULATED_GID = "r2s-recorded", "r2s-simulated"  # each drawn path's gid: `{kind}-{clip}-{entity}`
MAX_SIMULATED = 100  # simulated clips drawn at most (their paths overlaid; a folder of more: one line, exit 2)
MAX_NAMED = 24  # moving entities the legend names by colour (the rest are labelled at their path's end)
STILL_M = 0.5  # an entity whose path spans less than this is drawn as its box only


@dataclass(frozen=True)
class Trace:
    """One entity's path in the picture's frame: its points at the frames it is there, its last heading (degrees
    CCW from +y) and box."""

    id: str
    type: str
    points: tuple[tuple[float, float], ...]
    heading: float
    length: float
    width: float

    @property
    def span(self) -> float:
        xs, ys = [p[0] for p in self.points], [p[1] for p in self.points]
        return math.hypot(max(xs) - min(xs), max(ys) - min(ys))

    def box(self) -> Footprint:
        x, y = self.points[-1]
        return Footprint(self.id, self.type, x, y, self.heading, self.length, self.width)


def paths(clip: Clip, frame: WorldPose) -> tuple[Trace, ...]:
    """Every entity's recorded path of the clip in `frame`'s ego frame (the first frame's of the recorded clip)."""
    out = []
    for t in clip.motion.trajectories:
        out.append(_path(t, frame))
    return tuple(out)


def _path(t: Trajectory, frame: WorldPose) -> Trace:
    pts = tuple(frame.local(float(x), float(y)) for x, y, v in zip(t.x, t.y, t.valid) if v)
    last = int(len(t.valid) - 1 - t.valid[::-1].argmax())
    heading = math.degrees(float(t.yaw[last])) - frame.heading  # world yaw (from +x) less the frame's, from +y
    return Trace(t.id, t.type, pts, heading, t.length, t.width)


def simulated_clips(folder: str) -> list[Clip]:
    """Every scene of a frames file or dataset (r2s simulate's output) as a clip, in the order of first rows."""
    dataset = FramesDataset.open(folder)
    names: dict[str, None] = {}
    for part in dataset.parts:
        for table in dataset.row_groups(part, SCENE_COLUMNS[1:2], ()):
            names.update(dict.fromkeys(table.column("scene").to_pylist()))
            if len(names) > MAX_SIMULATED:
                raise UserError(f"{folder} holds more than {MAX_SIMULATED} scenes: a picture overlays at most that "
                                "many simulated clips")
    return [read_clip_frames(folder, name) for name in names]


def render_clip(scenes: Sequence[str | os.PathLike], out: str | os.PathLike, *,
                simulated: str | os.PathLike | None = None) -> Path:
    """`r2s render A.json B.json ... [--simulated DIR]` in-process: the clip of the scene JSON files `scenes` (in time
    order) drawn into `out` (.png, .svg or .pdf, written atomically), with the simulated clips of the frames
    dataset `simulated` overlaid. Returns the path written; bad input raises an InputError (one line)."""
    check_apart(out, [("scene", str(s)) for s in scenes] + [("simulated", simulated)])
    out = Path(out)
    if out.suffix.lstrip(".").lower() not in FORMATS:
        raise UserError(f"--out {out}: the file name must end in {', '.join('.' + f for f in FORMATS)}")
    if out.is_dir():
        raise UserError(f"--out {out} is a directory")
    clip = read_clip_files([str(s) for s in scenes])
    others = simulated_clips(str(simulated)) if simulated is not None else []
    ids = {t.id for t in clip.motion.trajectories}
    for c in others:
        stray = next((t.id for t in c.motion.trajectories if t.id not in ids), None)
        if stray is not None:
            raise UserError(f"{simulated}: scene {c.scene!r} has entity {stray!r}, which the clip "
                            f"{clip.scene!r} has not: give the simulated variants of this clip")
    with writing(out):
        save(draw_clip(clip, others, str(simulated) if simulated is not None else None), out)
    return out


def colours(recorded: Sequence[Trace]) -> dict[str, str]:
    """Ego red; every other entity a palette colour in clip order, those that move first (two moving entities share
    one only beyond the palette's 20)."""
    order = sorted((p for p in recorded if p.id != "ego"), key=lambda p: p.span < STILL_M)
    palette = [c for c in ENTITY_PALETTE if c != "#d62728"]  # the palette's red reads as ego's
    out = {"ego": EGO_FILL}
    for k, p in enumerate(order):
        out[p.id] = palette[k % len(palette)]
    return out


def draw_clip(clip: Clip, simulated: Sequence[Clip] = (), where: str | None = None):
    """A matplotlib Figure (Agg canvas) of the clip and its simulated clips, in the clip's first ego frame."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch, Polygon

    frame = clip.first.world
    recorded = paths(clip, frame)
    others = [(c.scene, paths(c, frame)) for c in simulated]
    colour = colours(recorded)
    pts = [q for p in recorded for q in p.points] + [q for _, ps in others for p in ps for q in p.points]
    xs, ys = [q[0] for q in pts], [q[1] for q in pts]
    x0, x1, y0, y1 = min(xs) - 8, max(xs) + 8, min(ys) - 8, max(ys) + 8
    span = max(x1 - x0, y1 - y0)
    fig = Figure(figsize=(max(5.0, 10 * (x1 - x0) / span) + 3.2, max(4.0, 10 * (y1 - y0) / span) + 0.9), dpi=150,
                 layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    road = draw_road(ax, clip.first)
    alpha = max(0.25, min(0.7, 3.0 / max(1, len(others))))
    for name, ps in others:
        for p in ps:
            if len(p.points) >= 2:
                ax.plot(*zip(*p.points), color=colour.get(p.id, "#303030"), linewidth=1.0, linestyle=(0, (3, 2)),
                        alpha=alpha, zorder=2, gid=f"{SIMULATED_GID}-{name}-{p.id}")
    for p in recorded:
        c = colour[p.id]
        ax.add_patch(Polygon(p.box().corners(), closed=True, facecolor=EGO_FILL if p.id == "ego" else "#f0f0f0",
                             edgecolor=EGO_EDGE if p.id == "ego" else c, linewidth=0.8, zorder=3))
        if len(p.points) >= 2:
            ax.plot(*zip(*p.points), color=c, linewidth=1.6, zorder=4, gid=f"{RECORDED_GID}-{clip.scene}-{p.id}")
            ax.plot(*p.points[0], marker="o", markersize=2.5, color=c, zorder=4.5)
        if p.span >= STILL_M or p.id == "ego":
            ax.annotate(p.id, p.points[-1], xytext=(3, 3), textcoords="offset points", fontsize=5.5, color=c,
                        zorder=6)

    handles = [Line2D([], [], color="#303030", linewidth=1.6, marker="o", markersize=2.5,
                      label=f"recorded ({len(clip.scenes)} frames, {clip.times[-1]:g} s):\nfrom the dot to the box")]
    if others:
        handles.append(Line2D([], [], color="#303030", linewidth=1.0, linestyle=(0, (3, 2)), alpha=alpha,
                              label=f"simulated: {len(others)} variant{'s' * (len(others) != 1)}\n"
                                    f"({Path(where).name if where else 'overlaid'}), same colours"))
    moving = [p for p in recorded if p.span >= STILL_M]
    handles += [Line2D([], [], color=colour[p.id], linewidth=2.0, label=p.id) for p in moving[:MAX_NAMED]]
    if len(moving) > MAX_NAMED:
        handles.append(Patch(facecolor="none", edgecolor="none",
                             label=f"and {len(moving) - MAX_NAMED} more (labelled at their boxes)"))
    drawn = {r.style for r in road}
    handles += [Patch(facecolor=st.face, edgecolor=st.edge, label=st.label) if st.face != "none" else
                Line2D([], [], color=st.edge, label=st.label) for name, st in ROAD_STYLES.items() if name in drawn]
    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.grid(True, color="#e5e5e5", linewidth=0.6, zorder=0)
    ax.set_axisbelow(True)
    ax.set_xlabel(f"metres to the right of ego in {clip.scenes[0].frame_id}")
    ax.set_ylabel("metres ahead of ego")
    ax.set_title(f"{clip.scene}: {len(recorded)} tracks, {len(moving)} moving"
                 + (f"; {len(others)} simulated clips overlaid" if others else ""), fontsize=8)
    fig.legend(handles=handles, loc="outside right upper", fontsize=6.5, frameon=False, labelspacing=0.7)
    return fig
