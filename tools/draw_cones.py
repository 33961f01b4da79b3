"""Draws docs/cones.png, the picture of what the DSL's direction words mean (docs/dsl.md#what-the-words-mean):
the four sectors of `ahead of / left of / behind / right of REF` (cones of half-width delta1 about REF's heading
turned by 0, 90, 180, 270 degrees), the gaps between them, `within` (distance alone), `facing toward` (delta2) and
`moving like` (speed alone). Run from the repository's root: `python tools/draw_cones.py [OUT.png]`; the same
matplotlib gives the same bytes (tests/test_cones_picture.py redraws it and compares)."""

from __future__ import annotations

import math
import sys
from pathlib import Path

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, FancyArrowPatch, Polygon, Rectangle, Wedge

from synth.config import SynthConfig

REACH = 20.0  # metres drawn
SECTORS = (("ahead of", 0.0, "#e66101"), ("left of", 90.0, "#1a9641"), ("behind", 180.0, "#0571b0"),
           ("right of", 270.0, "#7b3294"))


def _car(ax, x, y, heading, color, label=None, at=(1.6, -1.6), ha="left"):
    """A 4.5 x 1.9 m box at (x, y) facing `heading` (degrees counter-clockwise from +y, the DSL's convention)."""
    t = math.radians(heading)
    fx, fy = -math.sin(t), math.cos(t)
    lx, ly = math.cos(t), math.sin(t)
    pts = [(x + sx * 0.95 * lx + sy * 2.25 * fx, y + sx * 0.95 * ly + sy * 2.25 * fy)
           for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    ax.add_patch(Polygon(pts, closed=True, facecolor=color, edgecolor="#303030", linewidth=0.8, zorder=3))
    ax.add_patch(FancyArrowPatch((x, y), (x + 2.2 * fx, y + 2.2 * fy), arrowstyle="-|>", mutation_scale=8,
                                 color="white" if color == "#e31a1c" else "#303030", lw=0.8, zorder=4))
    if label:
        ax.text(x + at[0], y + at[1], label, fontsize=7.5, zorder=5, ha=ha, va="top")


def draw(config: SynthConfig | None = None):
    config = config or SynthConfig()
    d1, d2 = config.delta1, config.delta2
    fig = Figure(figsize=(11.5, 5.6), dpi=120, layout="constrained")
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.15, 1]})

    # Left: the four sectors about REF (here ego, facing up).
    for name, phi, color in SECTORS:
        # matplotlib's angles are from +x counter-clockwise; the DSL's headings from +y: +90.
        left.add_patch(Wedge((0, 0), REACH, 90 + phi - d1, 90 + phi + d1, facecolor=color, alpha=0.25,
                             edgecolor=color, linewidth=1.0))
        t = math.radians(90 + phi)
        left.text(0.8 * REACH * math.cos(t) + (2.5 if phi in (0.0, 180.0) else 0), 0.8 * REACH * math.sin(t)
                  + (1.5 if phi in (90.0, 270.0) else 0), f"{name} REF\n(±{d1:g}°)", fontsize=8, color=color,
                  ha="left" if phi in (0.0, 180.0) else "center", va="center", fontweight="bold")
    left.add_patch(Circle((0, 0), 8, fill=False, linestyle="--", edgecolor="#555555", linewidth=1.0))
    left.text(6.5, -11.0, "within Range(0, 8) of REF\n(dashed): any direction", fontsize=7.5, color="#555555")
    _car(left, 0, 0, 0, "#e31a1c", "REF")
    _car(left, -9.5, 9.5, 20, "#a6bddb", "x: in no sector\n(45° off every axis)", at=(-1.5, 5.5), ha="center")
    left.set_xlim(-REACH - 1, REACH + 1)
    left.set_ylim(-REACH - 1, REACH + 1)
    left.set_aspect("equal")
    left.grid(True, color="#eeeeee")
    left.set_title(f"position: a cone of half-width δ1 = {d1:g}° about REF's heading turned by 0, 90, 180, 270°\n"
                   "(distance between centres in the Range); between the cones no direction word holds",
                   fontsize=8.5)
    left.set_xlabel("metres to REF's right")
    left.set_ylabel("metres ahead of REF")

    # Right: facing toward (the entity's heading within delta2 of the bearing to REF) and moving like (speed only).
    _car(right, 0, 0, 0, "#e31a1c", "REF")
    x, y = -8.0, 12.0
    toward = math.degrees(math.atan2(-y, -x)) - 90.0  # the bearing from (x, y) to REF, DSL convention
    right.add_patch(Wedge((x, y), 9, 90 + toward - d2, 90 + toward + d2, facecolor="#1a9641", alpha=0.3,
                          edgecolor="#1a9641"))
    _car(right, x, y, toward + 3.0, "#a6bddb", f"a: facing toward REF\n(heading within δ2 = {d2:g}°\nof the bearing to REF)",
         at=(-3.0, 6.5), ha="center")
    _car(right, 9.0, 10.0, 0.0, "#a6bddb", "b: 8 m/s")
    _car(right, 9.0, -6.0, 180.0, "#a6bddb", "c: 8.5 m/s,\nthe other way")
    right.add_patch(Rectangle((-19.0, -17.0), 39.0, 6.0, facecolor="#fdf6e3", edgecolor="#c9a400", linewidth=0.8))
    right.text(-18.2, -14.0, f"b moving like c: |8 − 8.5| <= DV = {config.dv:g} m/s, though they drive opposite ways:\n"
               "`moving like` compares speeds only, never directions", fontsize=7.5, va="center")
    right.set_xlim(-20, 21)
    right.set_ylim(-18, 22)
    right.set_aspect("equal")
    right.grid(True, color="#eeeeee")
    right.set_title("heading: `facing toward REF` is a cone of δ2 at the entity;\nmotion: `moving like REF` is speed only",
                    fontsize=8.5)
    right.set_xlabel("metres")
    return fig


def main(argv: list[str]) -> int:
    out = Path(argv[0] if argv else "docs/cones.png")
    draw().savefig(out, format="png", metadata={"Software": None})
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
