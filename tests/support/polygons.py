"""An independent reference for point-in-polygon (docs/formats.md, "Lane facts"): everything in fractions, the
crossing's x computed and compared (not the sign test synth.road.lane_facts uses)."""

from __future__ import annotations

from fractions import Fraction


def rational_covers(ring, px, py) -> bool:
    """Whether the closed polygon `ring` holds (px, py): on an edge (collinear and within its box), or inside by an
    odd number of crossings of the ray to its right."""
    F = Fraction
    px, py = F(px), F(py)
    inside = False
    for (ax, ay), (bx, by) in zip(ring, ring[1:] + ring[:1]):
        ax, ay, bx, by = F(ax), F(ay), F(bx), F(by)
        on_line = (bx - ax) * (py - ay) == (by - ay) * (px - ax)
        if on_line and min(ax, bx) <= px <= max(ax, bx) and min(ay, by) <= py <= max(ay, by):
            return True
        if (ay > py) != (by > py) and ax + (py - ay) * (bx - ax) / (by - ay) > px:
            inside = not inside
    return inside
