"""The road of a window: the one road a window program's Scenic text stands on (docs/dsl.md, "Programs over a
window").

Each frame of a window carries its own road: the map features near ego at that instant, in that frame's ego frame.
The window's Scenic text is rendered on its first frame, while an entity first seen later may be in a lane that
only a later frame's road holds; with the first frame's road alone, its `in lane "ID"` would name no region and no
sample could meet it. So the window's road is every frame's road brought into the first frame's ego frame through
the frames' worlds (scene JSON's `world`: a point of a frame's ego frame goes to the world by that frame's pose,
and from there into the first frame's ego frame), one feature per feature id: its shape from the first frame that
holds it (the first frame's own features exactly as that frame has them), its lane links the union of the frames'
(a frame's road drops the links to lanes beyond it, synth.road.roadmap.links_within, so a chain that leaves one frame's
road is completed by the next). The result is part of one map, each feature once however many frames the window
has, and holds every lane, crosswalk and intersection that a clause or a lane fact of any frame names (each
frame's road holds those of its own frame).

Frames without a world are taken to be in one frame (their roads united as they are given, as a scene without a
world is its own world: synth.world.WorldPose.identity); some with a world and some without, or roads of two maps,
are refused in one line. Values in and out, no I/O.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

from synth.road.roadmap import MapFeature, Points, RoadMap
from synth.scene import Scene, SceneError
from synth.world import WorldPose


class WindowRoadError(SceneError):
    """Frames whose roads cannot be brought into one frame (two maps, a world in some frames only). One line."""


def window_road(scenes: Sequence[Scene]) -> RoadMap | None:
    """The road of a window of frames (in time order) in its first frame's ego frame: every frame's road features,
    each feature id once (module docstring); None if no frame has a road. The first frame's road itself when the
    other frames add no feature and no lane link to it."""
    carrying = [s for s in scenes if s.road is not None]
    if not carrying:
        return None
    first = scenes[0]
    _check_one_frame(first, carrying)
    features: dict[str, MapFeature] = {}
    changed = first.road is None
    for scene in carrying:
        move = _mover(scene.world, first.world)
        for f in scene.road.features:
            held = features.get(f.feature_id)
            if held is None:
                features[f.feature_id] = move(f)
                changed = changed or scene is not first
                continue
            if held.kind != f.kind:
                raise WindowRoadError(f"feature {f.feature_id!r} is a {held.kind.replace('_', ' ')} in one frame's "
                                      f"road and a {f.kind.replace('_', ' ')} in frame {scene.frame_id!r}'s")
            linked = _linked(held, f)
            if linked is not held:
                features[f.feature_id] = linked
                changed = True
    if not changed:
        return first.road
    return RoadMap.of(carrying[0].road.map_id, features.values())


def _check_one_frame(first: Scene, carrying: Sequence[Scene]) -> None:
    """Refuse roads that cannot be brought into the first frame's: of two maps, or some frames with a world (the
    first frame's included) and some without."""
    maps = {s.road.map_id: s for s in carrying}
    if len(maps) > 1:
        (a, sa), (b, sb) = list(maps.items())[:2]
        raise WindowRoadError(f"frame {sa.frame_id!r} has a road of map {a!r} and frame {sb.frame_id!r} one of map "
                              f"{b!r}: a window's frames are of one scene, on one map")
    frames = [first, *carrying]
    placed = [s for s in frames if s.world is not None]
    if placed and len(placed) < len(frames):
        bare = next(s for s in frames if s.world is None)
        raise WindowRoadError(f"frame {placed[0].frame_id!r} has a world and frame {bare.frame_id!r} none: a window's "
                              "roads are brought into its first frame's through each frame's world (scene JSON)")


def _mover(source: WorldPose | None, target: WorldPose | None) -> Callable[[MapFeature], MapFeature]:
    """A feature of a frame posed at `source` as the frame posed at `target` sees it; unchanged (exactly) where the
    two poses are one (no worlds at all, or ego still: a parked ego's frames share every coordinate)."""
    if source is None or target is None or (source.x, source.y, source.heading) == (target.x, target.y,
                                                                                   target.heading):
        return lambda f: f

    def move(pts: Points) -> Points:
        return tuple(target.local(*source.point(x, y)) for x, y in pts)

    return lambda f: f.with_(polygon=move(f.polygon), line=move(f.line))


def _linked(held: MapFeature, other: MapFeature) -> MapFeature:
    """A lane's links as one frame's road gives them, completed by another frame's: successors and predecessors
    united (in order of first mention), a neighbour the first road lacks taken from the other."""
    links = dict(successors=tuple(dict.fromkeys(held.successors + other.successors)),
                 predecessors=tuple(dict.fromkeys(held.predecessors + other.predecessors)),
                 left=held.left if held.left is not None else other.left,
                 right=held.right if held.right is not None else other.right)
    return held if all(getattr(held, k) == v for k, v in links.items()) else held.with_(**links)
