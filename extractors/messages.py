"""Annotation and pose messages of robotics logs, decoded by any reader, as boxes and ego poses.

Shared by the mcap and rosbag sources. A decoded message may be a protobuf object, a ROS message object
(mcap-ros2-support, rosbags) or a JSON dict; fields are read by name from any of them. Supported layouts:

annotations   foxglove.SceneUpdate (protobuf, JSON, ROS 2 foxglove_msgs): one box per entity, from its first
              cube (pose, size x = length, y = width); category = the entity's metadata "category" (as the
              nuScenes-to-MCAP converter writes it), track = entity id.
              vision_msgs/Detection3DArray (ROS 2; ROS 1 noetic): category = results[0].hypothesis.class_id
              (ROS 1: results[0].id), track = detection id, box = bbox.center / bbox.size.
              visualization_msgs/MarkerArray: CUBE markers being added; category = ns, track = ns/id.
ego pose      tf2_msgs/TFMessage and foxglove.FrameTransform(s): the fixed frame -> ego frame transform;
              or a pose topic: geometry_msgs/PoseStamped, PoseWithCovarianceStamped, nav_msgs/Odometry,
              foxglove.PoseInFrame.
speed         an object's from its message where the message carries one (a `velocity` or `twist` field, as
              tracker outputs do), else from its track: the positions of the same track id in the neighbouring
              annotation messages (at most 0.5 s away, extractors.speed), placed in the fixed frame (ego-frame
              boxes through the ego pose). The ego's from odometry (nav_msgs/Odometry twist), else from its poses
              the same way. Null where none of these is there.
"""

from __future__ import annotations

import argparse
import bisect
import math
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from extractors import argoverse2, nuscenes, scenarionet
from extractors.base import (
    ExtractError,
    ExtractOptions,
    ExtractTally,
    FrameBuilder,
    RecordedObject,
    comma_list,
    global_to_ego,
    quaternion_yaw,
    vehicle_to_ego,
)
from extractors.categories import Taxonomy
from extractors.speed import MAX_GAP_S, track_speeds
from synth.pose import SE2
from synth.scene import ENTITY_TYPES

# Robotics logs (MCAP, ROS bags) carry whatever category strings their writer chose: nuScenes names (the
# nuScenes-to-MCAP converters), Argoverse / ScenarioNet names, or the Scenic class itself.
TAXONOMY = Taxonomy("logs", {**scenarionet.TAXONOMY.classes, **argoverse2.TAXONOMY.classes, **nuscenes.TAXONOMY.classes,
                             **{c: c for c in ENTITY_TYPES}})
SCENE_UPDATE = ("foxglove.SceneUpdate", "foxglove_msgs/msg/SceneUpdate", "foxglove_msgs/SceneUpdate")
DETECTIONS = ("vision_msgs/msg/Detection3DArray", "vision_msgs/Detection3DArray")
MARKERS = ("visualization_msgs/msg/MarkerArray", "visualization_msgs/MarkerArray")
ANNOTATION_TYPES = SCENE_UPDATE + DETECTIONS + MARKERS
TF_TYPES = ("tf2_msgs/msg/TFMessage", "tf2_msgs/TFMessage", "foxglove.FrameTransform", "foxglove.FrameTransforms",
            "foxglove_msgs/msg/FrameTransform", "foxglove_msgs/msg/FrameTransforms")
POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/PoseStamped",
              "geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs/PoseWithCovarianceStamped",
              "nav_msgs/msg/Odometry", "nav_msgs/Odometry", "foxglove.PoseInFrame", "foxglove_msgs/msg/PoseInFrame")
DEFAULT_ANNOTATION_TOPIC = "/markers/annotations"
POSE_TOLERANCE_NS = 100_000_000  # an ego pose further than 0.1 s from the annotations does not place them
MARKER_CUBE, MARKER_ADD = 1, 0


@dataclass(frozen=True)
class LogOptions(ExtractOptions):
    """The options of the sources that read robotics logs (mcap, rosbag)."""

    topics: tuple[str, ...] = ()
    pose_topic: str | None = None
    fixed_frame: str = "map"
    ego_frame: str = "base_link"
    max_chunk_bytes: int = 256 * 2**20

    @classmethod
    def add_options(cls, g: argparse._ArgumentGroup) -> None:
        g.add_argument("--topics", type=comma_list, default=(), metavar="T,...",
                       help="annotation topics (default: every SceneUpdate / Detection3DArray / MarkerArray topic)")
        g.add_argument("--pose-topic", metavar="T",
                       help="ego pose topic (PoseStamped, Odometry, PoseInFrame); default /tf")
        g.add_argument("--fixed-frame", default="map", metavar="F", help="global frame of the ego pose")
        g.add_argument("--ego-frame", default="base_link", metavar="F", help="the vehicle's frame")
        g.add_argument("--max-chunk-mb", type=float, default=256, metavar="MB",
                       help="refuse compressed chunks that claim to decompress to more than this")

    @classmethod
    def options_from(cls, args: argparse.Namespace, **common: Any) -> LogOptions:
        return cls(topics=args.topics, pose_topic=args.pose_topic, fixed_frame=args.fixed_frame,
                   ego_frame=args.ego_frame, max_chunk_bytes=int(args.max_chunk_mb * 2**20), **common)


def first_field(obj: Any, *names: str, default: Any = None) -> Any:
    """The first present field of obj among names (dict key or attribute): the layouts spell one field
    differently (sec / secs / seconds), and a message may be a dict, a ROS object or a protobuf."""
    for name in names:
        value = obj.get(name) if isinstance(obj, dict) else getattr(obj, name, None)
        if value is not None:
            return value
    return default


def stamp_ns(t: Any) -> int | None:
    """A ROS 1 / ROS 2 / foxglove / protobuf timestamp in nanoseconds; None if absent or zero."""
    if t is None:
        return None
    sec = first_field(t, "sec", "secs", "seconds", default=0)
    nsec = first_field(t, "nsec", "nanosec", "nsecs", "nanos", default=0)
    ns = int(sec) * 1_000_000_000 + int(nsec)
    return ns or None


def _float_or_zero(v: Any) -> float:
    """An absent coordinate is 0, as the message layouts default it."""
    return float(v) if v is not None else 0.0


def _planar_speed(v: Any) -> float:
    """|(x, y)| of a velocity or twist field (Twist, TwistWithCovariance, a plain vector), NaN without one."""
    if v is None:
        return math.nan
    v = first_field(v, "twist", default=v)  # TwistWithCovariance wraps the twist once more
    v = first_field(v, "linear", default=v)
    return math.hypot(_float_or_zero(first_field(v, "x")), _float_or_zero(first_field(v, "y")))


def _message_speed(obj: Any) -> float | None:
    s = _planar_speed(first_field(obj, "velocity", "twist"))
    return s if math.isfinite(s) else None


def _pose(p: Any) -> tuple[float, float, float]:
    """(x, y, yaw) of a geometry pose (position + orientation quaternion)."""
    pos = first_field(p, "position", "translation", default={})
    q = first_field(p, "orientation", "rotation", default={})
    w = _float_or_zero(first_field(q, "w", default=1.0))
    yaw = quaternion_yaw(w, *(_float_or_zero(first_field(q, axis)) for axis in ("x", "y", "z")))
    return _float_or_zero(first_field(pos, "x")), _float_or_zero(first_field(pos, "y")), float(yaw)


@dataclass(frozen=True)
class RawBox:
    """A box in the frame its message names (not yet in our ego frame): yaw radians CCW from +x."""

    frame: str
    track_id: str
    category: str
    x: float
    y: float
    yaw: float
    length: float | None
    width: float | None
    speed: float | None = None  # from the message itself, where it carries a velocity


def annotation_boxes(msg: Any, schema: str) -> tuple[int | None, list[RawBox]]:
    """(header stamp ns or None, boxes) of one annotation message of a type in ANNOTATION_TYPES."""
    boxes: list[RawBox] = []
    stamp = None
    if schema in SCENE_UPDATE:
        for ent in first_field(msg, "entities", default=[]):
            cubes = list(first_field(ent, "cubes", default=[]))
            if not cubes:
                continue
            meta = {first_field(kv, "key"): first_field(kv, "value") for kv in first_field(ent, "metadata", default=[])}
            x, y, yaw = _pose(first_field(cubes[0], "pose", default={}))
            size = first_field(cubes[0], "size", default={})
            eid = str(first_field(ent, "id", default=""))
            frame = str(first_field(ent, "frame_id", default=""))
            boxes.append(RawBox(frame, eid, str(meta.get("category") or eid), x, y, yaw,
                                first_field(size, "x"), first_field(size, "y"), _message_speed(ent)))
            stamp = stamp or stamp_ns(first_field(ent, "timestamp"))
    elif schema in DETECTIONS:
        header = first_field(msg, "header", default={})
        stamp = stamp_ns(first_field(header, "stamp"))
        for i, det in enumerate(first_field(msg, "detections", default=[])):
            results = list(first_field(det, "results", default=[]))
            if results:
                hyp = first_field(results[0], "hypothesis")
                cat = first_field(hyp, "class_id") if hyp is not None else first_field(results[0], "id", default="")
                cat = str(cat)
            else:
                cat = ""
            bbox = first_field(det, "bbox", default={})
            x, y, yaw = _pose(first_field(bbox, "center", default={}))
            size = first_field(bbox, "size", default={})
            frame = (first_field(first_field(det, "header", default={}), "frame_id")
                     or first_field(header, "frame_id", default=""))
            boxes.append(RawBox(str(frame), str(first_field(det, "id") or i), cat, x, y, yaw,
                                first_field(size, "x"), first_field(size, "y"), _message_speed(det)))
    elif schema in MARKERS:
        for m in first_field(msg, "markers", default=[]):
            if (int(first_field(m, "type", default=-1)) != MARKER_CUBE
                    or int(first_field(m, "action", default=0)) != MARKER_ADD):
                continue
            header = first_field(m, "header", default={})
            stamp = stamp or stamp_ns(first_field(header, "stamp"))
            x, y, yaw = _pose(first_field(m, "pose", default={}))
            scale = first_field(m, "scale", default={})
            ns = str(first_field(m, "ns", default=""))
            track = f"{ns}/{first_field(m, 'id', default=0)}"
            boxes.append(RawBox(str(first_field(header, "frame_id", default="")), track, ns, x, y, yaw,
                                first_field(scale, "x"), first_field(scale, "y")))
    else:  # pragma: no cover - callers pass only ANNOTATION_TYPES
        raise ValueError(schema)
    return stamp, boxes


def pose_samples(msg: Any, schema: str, options: LogOptions,
                 log_ns: int) -> list[tuple[int, float, float, float, float]]:
    """(t ns, x, y, yaw, speed) ego poses in the fixed frame carried by one tf or pose message; speed (m/s) is the
    odometry's twist where the message is Odometry, else NaN."""
    out = []
    if schema in TF_TYPES:
        transforms = first_field(msg, "transforms")
        for tf in (transforms if transforms is not None else [msg]):
            header = first_field(tf, "header")
            parent = first_field(header, "frame_id") if header is not None else first_field(tf, "parent_frame_id")
            if parent != options.fixed_frame or first_field(tf, "child_frame_id") != options.ego_frame:
                continue
            t = stamp_ns(first_field(header, "stamp")) if header is not None else stamp_ns(first_field(tf, "timestamp"))
            body = first_field(tf, "transform", default=tf)
            out.append((t or log_ns, *_pose(body), math.nan))
    else:
        header = first_field(msg, "header")
        t = stamp_ns(first_field(header, "stamp")) if header is not None else stamp_ns(first_field(msg, "timestamp"))
        pose = first_field(msg, "pose", default={})
        pose = first_field(pose, "pose", default=pose)  # Odometry / PoseWithCovariance wrap the pose once more
        out.append((t or log_ns, *_pose(pose), _planar_speed(first_field(msg, "twist"))))
    return out


class PoseTrack:
    """Ego poses by time; lookups take the nearest pose within POSE_TOLERANCE_NS."""

    def __init__(self, samples: Iterable[tuple[int, float, float, float, float]]) -> None:
        s = sorted(samples)
        self.times = [t for t, *_ in s]
        self.poses = [tuple(p[:3]) for _, *p in s]
        # Odometry's speed where the pose topic is odometry, else the poses' own differences.
        odometry = np.array([p[3] for _, *p in s], dtype=float)
        xy = np.array([p[:2] for p in self.poses], dtype=float).reshape(-1, 2)
        # Seconds from the first pose (nanoseconds since 1970 as a float would blur short steps).
        seconds = (np.array(self.times, dtype=np.int64) - (self.times[0] if self.times else 0)) * 1e-9
        differenced = track_speeds(seconds, xy[:, 0], xy[:, 1])
        self.speeds = np.where(np.isfinite(odometry), odometry, differenced)

    def __len__(self) -> int:
        return len(self.times)

    def _nearest(self, t: int) -> int | None:
        i = bisect.bisect_left(self.times, t)
        best = min((j for j in (i - 1, i) if 0 <= j < len(self.times)), key=lambda j: abs(self.times[j] - t),
                   default=None)
        return None if best is None or abs(self.times[best] - t) > POSE_TOLERANCE_NS else best

    def at(self, t: int) -> tuple[float, float, float] | None:
        best = self._nearest(t)
        return None if best is None else self.poses[best]

    def speed_at(self, t: int) -> float | None:
        """The ego's speed at the pose nearest t (odometry, else differenced poses); None where unknown."""
        best = self._nearest(t)
        return None if best is None or not math.isfinite(self.speeds[best]) else float(self.speeds[best])


def ground_positions(raw: list[RawBox], t: int, poses: PoseTrack, options: LogOptions) -> dict[str, tuple]:
    """track id -> (x, y) in the fixed frame, for the boxes that can be placed there (ego-frame boxes need the
    ego pose at t): what track differencing takes."""
    out = {b.track_id: (b.x, b.y) for b in raw if b.frame == options.fixed_frame}
    in_ego = [b for b in raw if b.frame == options.ego_frame]
    pose = poses.at(t) if in_ego else None
    if pose is not None:
        ego = SE2.body(*pose)  # the ego frame of a log is a body frame (x forward, y left)
        out.update({b.track_id: ego.apply(b.x, b.y) for b in in_ego})
    return out


@dataclass(frozen=True)
class _Message:
    index: int
    t: int  # ns
    raw: list[RawBox]
    ground: dict[str, tuple]


def _differenced(track: str, cur: _Message, prev: _Message | None, nxt: _Message | None) -> float | None:
    """A track's speed at `cur` from its positions in the neighbouring messages (extractors.speed's rule)."""
    here = cur.ground.get(track)
    if here is None:
        return None
    near = [m for m in (prev, nxt) if m is not None and track in m.ground and 0 < abs(m.t - cur.t) <= MAX_GAP_S * 1e9]
    if not near:
        return None
    a, b = (near[0], near[-1]) if len(near) == 2 else ((near[0], cur) if near[0] is prev else (cur, near[0]))
    (x0, y0), (x1, y1) = a.ground[track], b.ground[track]
    return math.hypot(x1 - x0, y1 - y0) / ((b.t - a.t) * 1e-9)


def to_ego_boxes(raw: list[RawBox], t: int, poses: PoseTrack, options: LogOptions,
                 where: str) -> list[RecordedObject]:
    """Boxes in the ego frame: from the vehicle frame directly, from the fixed frame through the ego pose."""
    out: list[RecordedObject] = []
    in_ego = [b for b in raw if b.frame == options.ego_frame]
    in_fixed = [b for b in raw if b.frame == options.fixed_frame]
    other = {b.frame for b in raw} - {options.ego_frame, options.fixed_frame}
    if other:
        raise ExtractError(
            f"{where}: boxes in frame {sorted(other)[0]!r}, neither the fixed frame {options.fixed_frame!r} nor the "
            "ego frame {!r} (set --fixed-frame / --ego-frame)".format(options.ego_frame)
        )
    if in_ego:
        x, y, h = vehicle_to_ego([b.x for b in in_ego], [b.y for b in in_ego], [b.yaw for b in in_ego])
        out += [RecordedObject(b.track_id, b.category, float(x[i]), float(y[i]), float(h[i]), b.length, b.width,
                               speed=b.speed) for i, b in enumerate(in_ego)]
    if in_fixed:
        pose = poses.at(t)
        if pose is None:
            raise ExtractError(
                f"{where}: no ego pose ({options.fixed_frame} -> {options.ego_frame}) within "
                f"{POSE_TOLERANCE_NS / 1e9:g} s of the annotations at t={t / 1e9:.3f} s (see --pose-topic)"
            )
        x, y, h = global_to_ego(*pose, [b.x for b in in_fixed], [b.y for b in in_fixed], [b.yaw for b in in_fixed])
        out += [RecordedObject(b.track_id, b.category, float(x[i]), float(y[i]), float(h[i]), b.length, b.width,
                               speed=b.speed) for i, b in enumerate(in_fixed)]
    return out


def choose_annotation_topics(available: dict[str, str], options: LogOptions, where: str) -> list[str]:
    """The annotation topics to read: --topics (checked), else the one annotation topic, else the converter's."""
    if options.topics:
        for t in options.topics:
            if t not in available:
                raise ExtractError(f"{where} has no topic {t!r} (topics: {', '.join(sorted(available)) or 'none'})")
            if available[t] not in ANNOTATION_TYPES:
                raise ExtractError(f"{where}: topic {t} carries {available[t]}, not an annotation type "
                                   f"({', '.join(sorted(set(ANNOTATION_TYPES)))})")
        return list(options.topics)
    found = sorted(t for t, s in available.items() if s in ANNOTATION_TYPES)
    if len(found) == 1:
        return found
    if DEFAULT_ANNOTATION_TOPIC in found:
        return [DEFAULT_ANNOTATION_TOPIC]
    if not found:
        raise ExtractError(f"{where} has no annotation topic (SceneUpdate, Detection3DArray or MarkerArray)")
    raise ExtractError(f"{where} has several annotation topics ({', '.join(found)}): choose with --topics")


def choose_pose_topics(available: dict[str, str], options: LogOptions, where: str) -> list[str]:
    if options.pose_topic:
        t = options.pose_topic
        if t not in available:
            raise ExtractError(f"{where} has no topic {t!r} (topics: {', '.join(sorted(available)) or 'none'})")
        if available[t] not in TF_TYPES + POSE_TYPES:
            raise ExtractError(f"{where}: pose topic {t} carries {available[t]}, not a pose or tf message")
        return [t]
    return [t for t, s in available.items() if s in TF_TYPES]


def message_frames(
    source: str, scene: str, messages: Iterable[tuple[str, int, Any]], poses: PoseTrack, options: LogOptions,
    where: str, tally: ExtractTally | None = None,
) -> Iterator[list[dict[str, Any]]]:
    """One frame per annotation message (schema, log time ns, decoded message), frame_id `<scene>/<index>`.

    Messages are read one ahead of the frame they make, so that a track's speed can come from its position in the
    next message as well as the previous one (every message counts as a neighbour, --every or not)."""
    builder = FrameBuilder(source, TAXONOMY, options, tally)

    def frame(cur: _Message, prev: _Message | None, nxt: _Message | None) -> list[dict[str, Any]]:
        boxes = to_ego_boxes(cur.raw, cur.t, poses, options, f"{where} message {cur.index}")
        boxes = [b if b.speed is not None else replace(b, speed=_differenced(b.track_id, cur, prev, nxt))
                 for b in boxes]
        # the ego's pose in the fixed frame, where the log gives one: the frames keep it (map_x, map_y, map_heading)
        ego = RecordedObject("ego", "ego", 0.0, 0.0, 0.0, speed=poses.speed_at(cur.t), world=poses.at(cur.t))
        return builder.frame(scene, cur.index, cur.t // 1000, ego, boxes)

    window: list[_Message] = []  # the previous message, the one whose frame is due, the next one
    for index, (schema, log_ns, msg) in enumerate(messages):
        stamp, raw = annotation_boxes(msg, schema)
        t = stamp or log_ns
        window = (window + [_Message(index, t, raw, ground_positions(raw, t, poses, options))])[-3:]
        if len(window) >= 2:
            due = window[-2]
            if due.index % options.every == 0:
                yield frame(due, window[-3] if len(window) == 3 else None, window[-1])
    if window and window[-1].index % options.every == 0:
        yield frame(window[-1], window[-2] if len(window) >= 2 else None, None)
