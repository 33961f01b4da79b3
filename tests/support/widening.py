"""The independent widening rule the numpy offset rings are checked against (synth.road.lane_geometry
.offset_rings; docs/formats.md, "A lane without a polygon"), shared by the random-lane tests and the real Waymo
maps' tests."""

from __future__ import annotations

import shapely

from synth.road.lane_geometry import BEVEL_MERGE, dedup


def geos_ring(line, left, right):
    """The independent rule: GEOS's buffer of the line (both sides at once where they agree, else the union of
    two single-sided ones), flat caps, bevel joins, its largest part's outer ring."""
    g = shapely.LineString(dedup(tuple(line)))
    area = (shapely.buffer(g, left, cap_style="flat", join_style="bevel") if left == right else
            shapely.union(shapely.buffer(g, left, cap_style="flat", join_style="bevel", single_sided=True),
                          shapely.buffer(g, -right, cap_style="flat", join_style="bevel", single_sided=True)))
    area = area if area.geom_type == "Polygon" else max(area.geoms, key=lambda p: p.area)
    return shapely.Polygon(area.exterior)


def bound(left, right):
    """How far an accepted offset ring may lie from the buffer (metres): a merged bevel's miter point lies beyond
    the bevel's chord by at most its gap squared over 4 half widths."""
    return BEVEL_MERGE ** 2 / (4 * min(left, right)) + 1e-7
