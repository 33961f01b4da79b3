"""Bird's-eye view of a scene: oriented boxes, the program's references, and sampled variants.

Geometry first (pure: the ego frame, box corners, the recorded road, which reference places which entity how),
drawing after
(matplotlib's Agg canvas, imported lazily and without pyplot, so no global figure state). Everything is drawn
in ego's frame (metres, +x right of ego, +y ahead of it, equal aspect), whatever frame the scene came in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from pipeline.variants.labels import place
from storage.atomic import atomic_path
from synth.dsl import Program
from synth.geometry import heading_vector, normalize, to_local
from synth.scene import Scene

FORMATS = ("png", "svg", "pdf")


@dataclass(frozen=True)
class RelationKind:
    label: str
    color: str
    linestyle: str  # solid: places the position; dashed: sets the heading; dotted: sets the speed
    rad: float  # curvature, so position, heading and motion arrows between the same pair stay apart


# Colour by relation kind; cost-0 kinds warm, cost-1 kinds cool.
RELATION_KINDS: dict[str, RelationKind] = {
    "sector": RelationKind("ahead of / behind / left of / right of\n(position, cost 0)", "#e66101", "-", 0.08),
    "relative_xy": RelationKind("on Range @ Range relative to\n(position, cost 1)", "#5e3c99", "-", 0.08),
    "facing": RelationKind("facing toward / away from\n(heading, cost 0)", "#1a9641", "--", -0.2),
    "relative_heading": RelationKind("facing Range deg relative to\n(heading, cost 1)", "#0571b0", "--", -0.2),
    "moving_like": RelationKind("moving like\n(motion, cost 0)", "#d01c8b", ":", 0.32),
    "relative_speed": RelationKind("moving Range m/s relative to\n(motion, cost 1)", "#4d9221", ":", 0.32),
    # Lanes: dash-dot, curved the other way from motion, so a lane arrow stays apart from the other three.
    "lane_relation": RelationKind("in lane / lane left, right of / oncoming lane of\n(lane, cost 0)", "#8c510a",
                                  "-.", -0.45),
}


@dataclass(frozen=True)
class MarkKind:
    label: str
    marker: str
    hollow: bool = False  # drawn as an outline, so the box under it stays visible


# Clauses with no reference, marked on the entity: the absolute forms (cost 2) and `stationary` (cost 0).
MARK_KINDS: dict[str, MarkKind] = {
    "absolute_position": MarkKind("absolute position (cost 2)", "*"),
    "absolute_heading": MarkKind("absolute heading (cost 2)", "x"),
    "stationary": MarkKind("stationary (motion, cost 0)", "s", hollow=True),
    "absolute_speed": MarkKind("absolute speed (cost 2)", "^"),
    "lane_fact": MarkKind("in intersection / on crosswalk / off road, lane / in lane ID / anywhere (lane)", "D",
                          hollow=True),
}

@dataclass(frozen=True)
class Family:
    fill: str  # the recorded box
    variant: str  # sampled variants: darker, since they are drawn nearly transparent
    types: tuple[str, ...]


# Footprint colours by kind of road user; ego stands out in red.
FAMILIES: dict[str, Family] = {
    "vehicle": Family("#a6bddb", "#2b5a9b",
                      ("Car", "Truck", "Bus", "Trailer", "ConstructionVehicle", "EmergencyVehicle")),
    "two-wheeler": Family("#c2a5cf", "#6a3d9a", ("Motorcycle", "Bicycle")),
    "pedestrian / animal": Family("#fee391", "#b8860b", ("Pedestrian", "Animal")),
    "static object": Family("#d9d9d9", "#525252",
                            ("Barrier", "TrafficCone", "PushableObject", "Debris", "BicycleRack", "Object")),
}
EGO_FILL, EGO_EDGE = "#e31a1c", "#67000d"
BOUND_EDGE = "#00a087"  # a match's bound entities: a thick outline no family or relation uses


@dataclass(frozen=True)
class RoadStyle:
    label: str
    face: str  # "none": drawn as a line
    edge: str
    zorder: float


# The recorded road (the scene's `road`), under everything else: areas faint, lanes outlined with their centre
# line, road lines dark.
ROAD_STYLES: dict[str, RoadStyle] = {
    "drivable_area": RoadStyle("drivable area", "#f2f2f2", "none", 0.1),
    "lane": RoadStyle("lane (centre line dotted)", "#e8eef7", "#9db3cf", 0.2),
    "intersection": RoadStyle("intersection / intersection lane", "#fbe7d3", "#e0a872", 0.3),
    "crosswalk": RoadStyle("crosswalk", "#fff7bc", "#c9a400", 0.4),
    "road_line": RoadStyle("road line", "none", "#7f7f7f", 0.5),
}


@dataclass(frozen=True)
class RoadShape:
    """One map feature as drawn: its polygon and line in ego's frame, and its style (a key of ROAD_STYLES)."""

    style: str
    polygon: tuple[tuple[float, float], ...]
    line: tuple[tuple[float, float], ...]


def road_shapes(scene: Scene) -> tuple[RoadShape, ...]:
    """The scene's road in ego's frame (as ego_frame places the boxes), areas first so lines lie on top."""
    if scene.road is None:
        return ()
    ego = scene.ego

    def local(pts):
        return tuple(to_local(x - ego.x, y - ego.y, ego.heading) for x, y in pts)

    shapes = []
    for f in scene.road.features:
        style = "intersection" if f.kind == "lane" and f.is_intersection else f.kind
        shapes.append(RoadShape(style, local(f.polygon), local(f.line)))
    return tuple(sorted(shapes, key=lambda r: ROAD_STYLES[r.style].zorder))


def family_of(etype: str) -> str:
    return next((name for name, f in FAMILIES.items() if etype in f.types), "static object")


@dataclass(frozen=True)
class Footprint:
    """An entity as drawn: its oriented rectangle in ego's frame (not extractors.base.RecordedObject, a recorded detection)."""

    id: str
    type: str
    x: float
    y: float
    heading: float  # degrees, counter-clockwise from +y, in ego's frame
    length: float
    width: float

    def corners(self) -> tuple[tuple[float, float], ...]:
        fx, fy = heading_vector(self.heading)
        rx, ry = fy, -fx  # ego-frame right of the heading
        hl, hw = self.length / 2, self.width / 2
        return tuple((self.x + a * hl * fx + b * hw * rx, self.y + a * hl * fy + b * hw * ry)
                     for a, b in ((1, 1), (1, -1), (-1, -1), (-1, 1)))

    def front(self) -> tuple[float, float]:
        fx, fy = heading_vector(self.heading)
        return (self.x + fx * self.length / 2, self.y + fy * self.length / 2)


def ego_frame(scene: Scene) -> dict[str, Footprint]:
    """Every entity as a box in ego's frame (ego at the origin facing +y), by id, in scene order."""
    ego = scene.ego
    out = {}
    for e in scene.entities:
        lx, ly = to_local(e.x - ego.x, e.y - ego.y, ego.heading)
        length, width = e.dimensions()
        out[e.id] = Footprint(e.id, e.type, lx, ly, normalize(e.heading - ego.heading), length, width)
    return out


@dataclass(frozen=True)
class Reference:
    ref: str
    entity: str
    kind: str  # a key of RELATION_KINDS


@dataclass(frozen=True)
class Mark:
    entity: str
    kind: str  # a key of MARK_KINDS


def references(program: Program) -> tuple[tuple[Reference, ...], tuple[Mark, ...]]:
    """(arrows from reference to entity, marks of the clauses without a reference), in statement order."""
    arrows, marks = [], []
    for st in program.statements:
        for _, clause in st.clauses():
            kind = clause.drawn_as  # an arrow from its reference, or a mark on the entity (Clause.drawn_as)
            if kind in MARK_KINDS:
                marks.append(Mark(st.id, kind))
            else:
                arrows.append(Reference(clause.ref, st.id, kind))
    return tuple(arrows), tuple(marks)


def _extent(boxes: Sequence[Footprint], margin: float) -> tuple[float, float, float, float]:
    xs = [c[0] for b in boxes for c in b.corners()]
    ys = [c[1] for b in boxes for c in b.corners()]
    return (min(xs) - margin, max(xs) + margin, min(ys) - margin, max(ys) + margin)


@dataclass(frozen=True)
class View:
    scene: Scene
    program: Program | None = None
    samples: tuple[Scene, ...] = ()
    subtitle: str = ""
    bound: tuple[tuple[str, str], ...] = ()  # (pattern name, entity id): a query's match, outlined and named


# Variants are drawn in their entity's colour (and its recorded box outlined and labelled in it), from this palette
# of dark, distinct hues; entities near each other get different ones (entity_colours).
ENTITY_PALETTE = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#8c564b", "#e377c2", "#1192a0", "#9a9a00",
                  "#ff7f0e", "#393b79", "#637939", "#8c6d31", "#843c39", "#7b4173", "#3182bd", "#e6550d",
                  "#31a354", "#756bb1", "#636363", "#a55194")
LABEL_GID = "r2s-entity-label"  # every entity's label carries it (the tests find the labels by it)
LEADER_COLOUR = "#8a8a8a"


def entity_colours(boxes: dict[str, Footprint]) -> dict[str, str]:
    """A palette colour for every non-ego entity, in scene order, each the colour whose nearest earlier holder is
    farthest away (first in palette order on ties): with 20 colours, two entities that share one are far apart."""
    taken: dict[str, list[Footprint]] = {c: [] for c in ENTITY_PALETTE}
    out = {}
    for b in boxes.values():
        if b.id == "ego":
            continue
        colour = max(ENTITY_PALETTE, key=lambda c: min((math.hypot(b.x - o.x, b.y - o.y) for o in taken[c]),
                                                        default=math.inf))
        taken[colour].append(b)
        out[b.id] = colour
    return out


def draw(view: View):
    """A matplotlib Figure (Agg canvas) of the view."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D
    from matplotlib.patches import FancyArrowPatch, Patch, Polygon

    boxes = ego_frame(view.scene)
    sample_boxes = [b for s in view.samples for b in ego_frame(s).values() if b.id != "ego"]
    x0, x1, y0, y1 = _extent([*boxes.values(), *sample_boxes], margin=4.0)
    n = len(boxes)
    # Plot side ~ 9 in on the longer axis (12 in beyond 40 entities, so a dense frame's labels have room); the
    # legend gets its own strip on the right.
    side = 9.0 if n <= 40 else 12.0
    span = max(x1 - x0, y1 - y0)
    w_in, h_in = max(5.0, side * (x1 - x0) / span), max(4.0, side * (y1 - y0) / span)
    fig = Figure(figsize=(w_in + 3.0, h_in + 0.9), dpi=150, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    font = 7.0 if n <= 25 else 6.0 if n <= 70 else 5.0
    colours = entity_colours(boxes) if view.samples else {}

    road = draw_road(ax, view.scene)
    # Dense enough that where variants pile up reads as likely, sparse enough that single ones still show.
    alpha = max(0.06, min(0.3, 2.0 / max(1, len(view.samples))))
    for b in sample_boxes:
        color = colours.get(b.id, FAMILIES[family_of(b.type)].variant)
        ax.add_patch(Polygon(b.corners(), closed=True, facecolor=color, edgecolor=color, linewidth=0.3,
                             alpha=alpha, zorder=1))
    bound = {eid for _, eid in view.bound}
    for b in boxes.values():
        ego = b.id == "ego"
        face, edge = (EGO_FILL, EGO_EDGE) if ego else (FAMILIES[family_of(b.type)].fill, colours.get(b.id, "#303030"))
        ax.add_patch(Polygon(b.corners(), closed=True, facecolor=face, edgecolor=edge,
                             linewidth=1.2 if ego or b.id in colours else 0.7, zorder=3))
        ax.annotate("", xy=b.front(), xytext=(b.x, b.y), zorder=4,
                    arrowprops={"arrowstyle": "-|>", "color": "white" if ego else "#303030", "lw": 0.8,
                                "mutation_scale": 6, "shrinkA": 0, "shrinkB": 0})
        if b.id in bound:
            ax.add_patch(Polygon(b.corners(), closed=True, facecolor="none", edgecolor=BOUND_EDGE, linewidth=2.4,
                                 zorder=3.5))

    handles = [Patch(facecolor=EGO_FILL, edgecolor=EGO_EDGE, label="ego")]
    present = {family_of(b.type) for b in boxes.values() if b.id != "ego"}
    handles += [Patch(facecolor=f.fill, edgecolor="#303030", label=name) for name, f in FAMILIES.items()
                if name in present]
    handles.append(Line2D([], [], color="#303030", marker=">", markersize=4, linewidth=0.8,
                          label="heading (arrow from the centre)"))
    if view.bound:
        handles.append(Patch(facecolor="none", edgecolor=BOUND_EDGE, linewidth=2.4,
                             label="bound by the match\n(id = pattern name)"))
    drawn = {r.style for r in road}
    handles += [Patch(facecolor=st.face, edgecolor=st.edge, label=st.label) if st.face != "none" else
                Line2D([], [], color=st.edge, label=st.label) for name, st in ROAD_STYLES.items() if name in drawn]
    if view.samples:
        handles.append(Patch(facecolor=ENTITY_PALETTE[0], edgecolor=ENTITY_PALETTE[0], alpha=0.3,
                             label=f"{len(view.samples)} sampled variants (translucent),\neach in its entity's "
                                   "colour: the outline\nand label of its recorded box"))
    if view.program is not None:
        arrows, marks = references(view.program)
        for r in arrows:
            k = RELATION_KINDS[r.kind]
            a, e = boxes[r.ref], boxes[r.entity]
            ax.add_patch(FancyArrowPatch((a.x, a.y), (e.x, e.y), arrowstyle="-|>", mutation_scale=9, color=k.color,
                                         linestyle=k.linestyle, lw=1.0, alpha=0.85, shrinkA=3, shrinkB=3, zorder=5,
                                         connectionstyle=f"arc3,rad={k.rad}"))
        used = {r.kind for r in arrows}
        handles += [Line2D([], [], color=k.color, linestyle=k.linestyle, label=k.label)
                    for name, k in RELATION_KINDS.items() if name in used]
        for name, k in MARK_KINDS.items():
            ids = [m.entity for m in marks if m.kind == name]
            if ids:
                colour = {"facecolors": "none", "edgecolors": "black"} if k.hollow else {"c": "black"}
                ax.scatter([boxes[i].x for i in ids], [boxes[i].y for i in ids], marker=k.marker, s=40, zorder=7,
                           linewidths=1.0, **colour)
                handles.append(Line2D([], [], color="black", marker=k.marker, linestyle="none", label=k.label,
                                      **({"markerfacecolor": "none"} if k.hollow else {})))
    handles.append(Line2D([], [], color=LEADER_COLOUR, linewidth=0.5,
                          label="label placed away from its box\n(the line leads to it)"))

    ax.set_xlim(x0, x1)
    ax.set_ylim(y0, y1)
    ax.set_aspect("equal")
    ax.grid(True, color="#e5e5e5", linewidth=0.6, zorder=0)
    ax.set_axisbelow(True)
    ax.set_xlabel("metres to the right of ego")
    ax.set_ylabel("metres ahead of ego")
    title = f"{view.scene.frame_id}: ego and {n - 1} entities"
    ax.set_title(f"{title}\n{view.subtitle}" if view.subtitle else title, fontsize=8)
    fig.legend(handles=handles, loc="outside right upper", fontsize=7, frameon=False, labelspacing=0.9)
    _label(fig, ax, boxes, view, colours, font)
    return fig


def draw_road(ax, scene: Scene) -> tuple[RoadShape, ...]:
    """The scene's road drawn on the axes (areas filled, lanes outlined with their centre lines dotted, road lines
    dark), under everything else; returns its shapes (the legend names their styles)."""
    from matplotlib.patches import Polygon

    road = road_shapes(scene)
    for r in road:
        st = ROAD_STYLES[r.style]
        if r.polygon:
            ax.add_patch(Polygon(r.polygon, closed=True, facecolor=st.face, edgecolor=st.edge, linewidth=0.5,
                                 zorder=st.zorder))
        if r.line:
            ax.plot(*zip(*r.line), color=st.edge if st.face == "none" else "#b7c6da", linewidth=0.8,
                    linestyle="-" if st.face == "none" else ":", zorder=st.zorder + 0.05)
    return road


def _label(fig, ax, boxes: dict[str, Footprint], view: View, colours: dict[str, str], font: float) -> None:
    """Every entity's id (a match's with its pattern names), placed by pipeline.variants.labels where it overlaps
    no other label and no box, with a leader line when it sits away from its box. Last, once the layout is fixed:
    the labels are placed in its pixels, and kept out of it (set_in_layout) so that saving does not move it."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    to_px = ax.transData.transform
    rects = {}
    for b in boxes.values():
        px = to_px(b.corners())
        rects[b.id] = (float(px[:, 0].min()), float(px[:, 1].min()), float(px[:, 0].max()), float(px[:, 1].max()))
    names = {eid: [n for n, e in view.bound if e == eid] for eid in boxes}
    order = sorted(boxes.values(), key=lambda b: (b.id != "ego", not names[b.id], math.hypot(b.x, b.y)))
    texts, sizes = [], []
    for b in order:
        ego, named = b.id == "ego", bool(names[b.id])
        text = ax.text(0, 0, f"{b.id} = {', '.join(names[b.id])}" if named else b.id, fontsize=font, ha="center",
                       va="center", zorder=8, gid=LABEL_GID, clip_on=True,
                       color=BOUND_EDGE if named else EGO_EDGE if ego else colours.get(b.id, "#202020"),
                       fontweight="bold" if ego or named else "normal",
                       # a light halo, so a label stays legible over an arrow or a variant
                       bbox={"boxstyle": "square,pad=0.05", "facecolor": "white", "edgecolor": "none", "alpha": 0.75})
        text.set_in_layout(False)
        ext = text.get_window_extent(renderer)
        texts.append(text)
        sizes.append((ext.width + 2.0, ext.height + 1.0))
    frame = ax.get_window_extent(renderer)
    spots = place(sizes, [rects[b.id] for b in order], list(rects.values()),
                  (frame.x0, frame.y0, frame.x1, frame.y1))
    to_data = ax.transData.inverted().transform
    for text, spot, b in zip(texts, spots, order):
        x0, y0, x1, y1 = spot.rect
        text.set_position(tuple(to_data(((x0 + x1) / 2, (y0 + y1) / 2))))
        if spot.leader:
            # From the label's edge nearest the box to the box's centre.
            cx, cy = to_px((b.x, b.y))
            ex, ey = min(max(cx, x0), x1), min(max(cy, y0), y1)
            (ax_, ay_), (bx_, by_) = to_data((ex, ey)), (b.x, b.y)
            (line,) = ax.plot([ax_, bx_], [ay_, by_], color=LEADER_COLOUR, linewidth=0.5, zorder=7.5)
            line.set_in_layout(False)


def save(fig, path: str | Path) -> None:
    """Write the figure atomically; the format is the file's suffix (png, svg or pdf)."""
    fmt = Path(path).suffix.lstrip(".").lower()
    with atomic_path(path) as tmp:
        # No timestamps or version strings in the file: the same view gives the same bytes.
        meta = {"Software": None} if fmt == "png" else {"Creator": None} if fmt == "svg" else {"Producer": None,
                                                                                             "CreationDate": None}
        fig.savefig(tmp, format=fmt, metadata=meta, bbox_inches="tight", pad_inches=0.15)

