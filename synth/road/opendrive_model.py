"""The values of a linked OpenDRIVE road network (synth.road.opendrive builds them, synth.road.opendrive_group
groups lanes side by side into one road, pipeline/export/opendrive.py writes them): roads with their lanes, links,
junctions, crosswalks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NO_MARK = ("none", "standard", "both")  # an edge no recorded road line runs along (synth.road.opendrive.ROAD_MARKS)


@dataclass(frozen=True)
class Side:
    """A lane of a road right of its lane -1 (lane -2, -3, ...): the recorded lanes it follows, its width at each
    point of the road's reference line, its right edge's mark."""

    lanes: tuple[str, ...]
    widths: tuple[float, ...]
    mark: tuple[str, str, str] = NO_MARK


LANE_SEP = " | "  # how a road's name joins its lanes' names (lane -1's first), each " > "-joined


@dataclass(frozen=True)
class Link:
    """A road's predecessor or successor: another road (met at its `contact` end) or a junction."""

    kind: str  # "road" or "junction"
    id: int
    contact: str | None = None  # "start" or "end" for a road


@dataclass(frozen=True)
class Road:
    """One OpenDRIVE road: its reference line (points in the recentred frame, consecutive ones distinct), lane
    -1's width at each point (its centre is the reference line), the recorded lanes lane -1 follows, its junction
    (-1: none) and links; the lanes right of lane -1 (`side`: lanes of one road side by side,
    synth.road.opendrive_group), and each lane's (-1 first) predecessor and successor lane (`lane_links`; empty:
    lane -1 links to lane -1 of a linked road)."""

    id: int
    lanes: tuple[str, ...]
    points: tuple[tuple[float, float], ...]
    widths: tuple[float, ...]
    junction: int = -1
    predecessor: Link | None = None
    successor: Link | None = None
    marks: tuple[tuple[str, str, str], tuple[str, str, str]] = (NO_MARK, NO_MARK)  # left and right edge (ROAD_MARKS)
    side: tuple[Side, ...] = ()
    lane_links: tuple[tuple[int | None, int | None], ...] = ()

    @property
    def name(self) -> str:
        return LANE_SEP.join(" > ".join(lanes) for lanes in self.lane_names)

    @property
    def lane_names(self) -> tuple[tuple[str, ...], ...]:
        """The recorded lanes each lane follows: lane -1's, -2's, ..."""
        return (self.lanes,) + tuple(s.lanes for s in self.side)

    def centre_offsets(self, lane: int) -> np.ndarray:
        """Lane `lane`'s (-1, -2, ...) centre's offset (left positive) from the reference line at each point."""
        w = np.asarray([self.widths] + [s.widths for s in self.side], dtype=float)
        k = -lane - 1
        return np.zeros(w.shape[1]) if k == 0 else -(w[0] / 2 + w[1:k].sum(axis=0) + w[k] / 2)

    @property
    def s(self) -> tuple[float, ...]:
        """The distance along the reference line of each point."""
        d = np.hypot(*np.diff(np.asarray(self.points), axis=0).T) if len(self.points) > 1 else np.zeros(0)
        return tuple(np.concatenate([[0.0], np.cumsum(d)]).tolist())


@dataclass(frozen=True)
class Junction:
    """A junction: its connections, each (incoming road, connecting road, the incoming road's lane), the
    connecting road entered at its start, its lane -1 from that lane."""

    id: int
    connections: tuple[tuple[int, int, int], ...]


@dataclass(frozen=True)
class Crosswalk:
    """A recorded crosswalk as an object of the road nearest its centroid: at (s, t) on the road's reference
    line, its outline's corners (u, v) in the frame there (u along the reference line, v to its left)."""

    feature_id: str
    road: int
    s: float
    t: float
    outline: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Network:
    """A linked road network: roads, junctions, the offset subtracted from every coordinate (the recorded frame's
    point that is the network's origin) and what could not be kept (notes for the user)."""

    roads: tuple[Road, ...]
    junctions: tuple[Junction, ...]
    offset: tuple[float, float]
    notes: tuple[str, ...] = ()
    crosswalks: tuple[Crosswalk, ...] = ()


