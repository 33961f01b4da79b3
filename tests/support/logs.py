"""MCAP files and ROS bags written by the tests from real nuScenes values (the shipped excerpt's 13 tables),
in the message layouts real converters use. The tables are read here as plain JSON, independently of the
extractors."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

EXCERPT_TABLES = Path(__file__).resolve().parents[2] / "data" / "nuscenes-mini-excerpt" / "v1.0-mini"
T0_NS = 1_532_402_927_647_951_000  # a nuScenes-like epoch so stamps are non-zero


@dataclass(frozen=True)
class Ann:
    token: str
    category: str
    translation: tuple[float, float, float]
    rotation: tuple[float, float, float, float]  # w, x, y, z
    size: tuple[float, float, float]  # w, l, h (nuScenes order)


@dataclass(frozen=True)
class Sample:
    t_ns: int
    ego_translation: tuple[float, float, float]
    ego_rotation: tuple[float, float, float, float]
    anns: tuple[Ann, ...]

    @property
    def ego_yaw(self) -> float:
        w, x, y, z = self.ego_rotation
        return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))

    def in_vehicle_frame(self, a: Ann) -> tuple[float, float, float]:
        """(forward, left, yaw) of an annotation in the ego vehicle's frame (ROS base_link)."""
        dx = a.translation[0] - self.ego_translation[0]
        dy = a.translation[1] - self.ego_translation[1]
        c, s = math.cos(self.ego_yaw), math.sin(self.ego_yaw)
        w, x, y, z = a.rotation
        yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
        return dx * c + dy * s, -dx * s + dy * c, yaw - self.ego_yaw


def scenes() -> dict[str, list[Sample]]:
    """scene name -> its samples in order, from the excerpt tables."""
    t = {n: json.loads((EXCERPT_TABLES / f"{n}.json").read_text()) for n in (
        "scene", "sample", "sample_data", "ego_pose", "sample_annotation", "instance", "category")}
    by = {n: {r["token"]: r for r in rows} for n, rows in t.items()}
    sd_of = {r["sample_token"]: r for r in t["sample_data"]}
    cat_of = {i["token"]: by["category"][i["category_token"]]["name"] for i in t["instance"]}
    anns_of: dict[str, list[Ann]] = {}
    for a in t["sample_annotation"]:
        anns_of.setdefault(a["sample_token"], []).append(
            Ann(a["instance_token"], cat_of[a["instance_token"]], tuple(a["translation"]), tuple(a["rotation"]),
                tuple(a["size"])))
    out = {}
    for sc in t["scene"]:
        samples, tok = [], sc["first_sample_token"]
        while tok:
            s = by["sample"][tok]
            pose = by["ego_pose"][sd_of[tok]["ego_pose_token"]]
            samples.append(Sample(T0_NS + s["timestamp"] * 1000, tuple(pose["translation"]), tuple(pose["rotation"]),
                                  tuple(anns_of.get(tok, []))))
            tok = s["next"]
        out[sc["name"]] = samples
    return out


def _sec_nsec(ns: int) -> tuple[int, int]:
    return divmod(ns, 1_000_000_000)


# --- foxglove SceneUpdate, as the nuScenes-to-MCAP converter writes it (map frame, /tf map -> base_link) ---

def write_foxglove_protobuf(path: Path, samples: list[Sample]) -> None:
    from foxglove_schemas_protobuf.CubePrimitive_pb2 import CubePrimitive
    from foxglove_schemas_protobuf.FrameTransform_pb2 import FrameTransform
    from foxglove_schemas_protobuf.KeyValuePair_pb2 import KeyValuePair
    from foxglove_schemas_protobuf.Pose_pb2 import Pose
    from foxglove_schemas_protobuf.Quaternion_pb2 import Quaternion
    from foxglove_schemas_protobuf.SceneEntity_pb2 import SceneEntity
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate
    from foxglove_schemas_protobuf.Vector3_pb2 import Vector3
    from mcap_protobuf.writer import Writer

    def quat(r):
        return Quaternion(w=r[0], x=r[1], y=r[2], z=r[3])

    with open(path, "wb") as fh:
        w = Writer(fh)
        for s in samples:
            tf = FrameTransform(parent_frame_id="map", child_frame_id="base_link",
                                translation=Vector3(x=s.ego_translation[0], y=s.ego_translation[1], z=0.0),
                                rotation=quat(s.ego_rotation))
            tf.timestamp.FromNanoseconds(s.t_ns)
            w.write_message("/tf", tf, log_time=s.t_ns, publish_time=s.t_ns)
            ents = []
            for a in s.anns:
                e = SceneEntity(frame_id="map", id=a.token[:4], frame_locked=True,
                                metadata=[KeyValuePair(key="category", value=a.category)],
                                cubes=[CubePrimitive(pose=Pose(position=Vector3(x=a.translation[0], y=a.translation[1],
                                                                                z=a.translation[2]),
                                                               orientation=quat(a.rotation)),
                                                     size=Vector3(x=a.size[1], y=a.size[0], z=a.size[2]))])
                e.timestamp.FromNanoseconds(s.t_ns)
                ents.append(e)
            w.write_message("/markers/annotations", SceneUpdate(entities=ents), log_time=s.t_ns, publish_time=s.t_ns)
            car = SceneEntity(frame_id="base_link", id="car")  # the converter's ego model: no cubes
            w.write_message("/markers/car", SceneUpdate(entities=[car]), log_time=s.t_ns, publish_time=s.t_ns)
        w.finish()


def write_foxglove_json(path: Path, samples: list[Sample], compression: str = "zstd") -> None:
    from mcap.writer import CompressionType, Writer

    def q(r):
        return {"w": r[0], "x": r[1], "y": r[2], "z": r[3]}

    with open(path, "wb") as fh:
        w = Writer(fh, compression=CompressionType.ZSTD if compression == "zstd" else CompressionType.LZ4)
        w.start()
        su = w.register_schema("foxglove.SceneUpdate", "jsonschema", b"{}")
        ft = w.register_schema("foxglove.FrameTransform", "jsonschema", b"{}")
        ann_ch = w.register_channel("/markers/annotations", "json", su)
        tf_ch = w.register_channel("/tf", "json", ft)
        for s in samples:
            sec, nsec = _sec_nsec(s.t_ns)
            tf = {"timestamp": {"sec": sec, "nsec": nsec}, "parent_frame_id": "map", "child_frame_id": "base_link",
                  "translation": {"x": s.ego_translation[0], "y": s.ego_translation[1], "z": 0.0},
                  "rotation": q(s.ego_rotation)}
            w.add_message(tf_ch, log_time=s.t_ns, data=json.dumps(tf).encode(), publish_time=s.t_ns)
            ents = [{"timestamp": {"sec": sec, "nsec": nsec}, "frame_id": "map", "id": a.token[:4],
                     "metadata": [{"key": "category", "value": a.category}],
                     "cubes": [{"pose": {"position": dict(zip("xyz", a.translation)), "orientation": q(a.rotation)},
                                "size": {"x": a.size[1], "y": a.size[0], "z": a.size[2]}}]} for a in s.anns]
            w.add_message(ann_ch, log_time=s.t_ns, data=json.dumps({"entities": ents}).encode(), publish_time=s.t_ns)
        w.finish()


# --- ROS messages (vision_msgs / visualization_msgs / tf2_msgs / nav_msgs) ---

def _yaw_quat(yaw: float) -> dict:
    return {"x": 0.0, "y": 0.0, "z": math.sin(yaw / 2), "w": math.cos(yaw / 2)}


def detections_in_base_link(s: Sample, ros1: bool = False) -> dict:
    """Detection3DArray as a dict, boxes in the ego vehicle frame (base_link: x forward, y left)."""
    sec, nsec = _sec_nsec(s.t_ns)
    stamp = {"sec": sec, "nanosec": nsec}
    dets = []
    for a in s.anns:
        fwd, left, yaw = s.in_vehicle_frame(a)
        pose = {"position": {"x": fwd, "y": left, "z": 0.0}, "orientation": _yaw_quat(yaw)}
        dets.append({"header": {"stamp": stamp, "frame_id": "base_link"},
                     "results": [{"hypothesis": {"class_id": a.category, "score": 1.0},
                                  "pose": {"pose": pose, "covariance": [0.0] * 36}}],
                     "bbox": {"center": pose, "size": {"x": a.size[1], "y": a.size[0], "z": a.size[2]}},
                     "id": a.token})
    return {"header": {"stamp": stamp, "frame_id": "base_link"}, "detections": dets}


def markers_in_map(s: Sample) -> dict:
    sec, nsec = _sec_nsec(s.t_ns)
    header = {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": "map"}
    markers = [{"header": header, "ns": a.category, "id": i, "type": 1, "action": 0,
                "pose": {"position": dict(zip("xyz", a.translation)),
                         "orientation": dict(zip("wxyz", a.rotation))},
                "scale": {"x": a.size[1], "y": a.size[0], "z": a.size[2]}, "text": a.token}
               for i, a in enumerate(s.anns)]
    markers.append({"header": header, "ns": "labels", "id": 999, "type": 9, "action": 0, "pose": {}, "scale": {},
                    "text": "a text marker, not a box"})
    return {"markers": markers}


def tf_message(s: Sample) -> dict:
    sec, nsec = _sec_nsec(s.t_ns)
    return {"transforms": [{"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": "map"},
                            "child_frame_id": "base_link",
                            "transform": {"translation": {"x": s.ego_translation[0], "y": s.ego_translation[1],
                                                          "z": 0.0},
                                          "rotation": dict(zip("wxyz", s.ego_rotation))}}]}


def odometry(s: Sample, twist: tuple[float, float] = (0.0, 0.0)) -> dict:
    """nav_msgs/Odometry: the pose in map, the twist (linear x forward, y left) in base_link, as drivers write it."""
    sec, nsec = _sec_nsec(s.t_ns)
    return {"header": {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": "map"}, "child_frame_id": "base_link",
            "pose": {"pose": {"position": {"x": s.ego_translation[0], "y": s.ego_translation[1], "z": 0.0},
                              "orientation": dict(zip("wxyz", s.ego_rotation))}, "covariance": [0.0] * 36},
            "twist": {"twist": {"linear": {"x": twist[0], "y": twist[1], "z": 0.0}}, "covariance": [0.0] * 36}}


def write_ros2_mcap(path: Path, samples: list[Sample]) -> None:
    """Detection3DArray (base_link) on /detections, MarkerArray (map) on /markers, TFMessage on /tf."""
    from mcap_ros2.writer import Writer

    from extractors.rosbag import typestore

    store = typestore()
    with open(path, "wb") as fh:
        w = Writer(fh)
        schemas = {t: w.register_msgdef(t, store.generate_msgdef(t, ros_version=2)[0]) for t in (
            "vision_msgs/msg/Detection3DArray", "visualization_msgs/msg/MarkerArray", "tf2_msgs/msg/TFMessage")}
        for s in samples:
            w.write_message("/tf", schemas["tf2_msgs/msg/TFMessage"], tf_message(s), log_time=s.t_ns)
            w.write_message("/detections", schemas["vision_msgs/msg/Detection3DArray"], detections_in_base_link(s),
                            log_time=s.t_ns)
            w.write_message("/markers", schemas["visualization_msgs/msg/MarkerArray"], markers_in_map(s),
                            log_time=s.t_ns)
        w.finish()


# --- rosbags: dicts to typestore messages ---

def to_ros(store: Any, typename: str, value: dict, ros1: bool = False) -> Any:
    """A typestore message from a (partial) dict; fields not given get their zero value."""
    _, fields = store.fielddefs[typename]
    args = {}
    for name, desc in fields:
        v = value.get(name) if isinstance(value, dict) else None
        if ros1 and name == "nanosec" and "nanosec" not in value:
            v = value.get("nsec")
        args[name] = _field(store, desc, v, ros1)
    return store.types[typename](**args)


_NUMPY = {"float64": np.float64, "float32": np.float32, "uint8": np.uint8, "int8": np.int8, "int32": np.int32,
          "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64, "int16": np.int16, "uint16": np.uint16}


def _field(store: Any, desc: tuple, v: Any, ros1: bool) -> Any:
    kind, detail = desc
    if kind == 1:  # base type
        t = detail[0]
        if t == "string":
            return "" if v is None else str(v)
        if t == "bool":
            return bool(v)
        return (float if t.startswith("float") else int)(v or 0)
    if kind == 2:  # nested message
        return to_ros(store, detail, v or {}, ros1)
    sub, n = detail
    if sub[0] == 1 and sub[1][0] in _NUMPY:  # numeric array / sequence
        data = v if v is not None else ([0] * n if kind == 3 else [])
        return np.asarray(data, dtype=_NUMPY[sub[1][0]])
    return [_field(store, sub, x, ros1) for x in (v or [])]


def write_rosbag2(path: Path, samples: list[Sample], storage: str) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer

    from extractors.rosbag import typestore

    store = typestore()
    plugin = {"sqlite3": StoragePlugin.SQLITE3, "mcap": StoragePlugin.MCAP}[storage]
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conns = {t: w.add_connection(topic, t, typestore=store) for topic, t in (
            ("/tf", "tf2_msgs/msg/TFMessage"), ("/detections", "vision_msgs/msg/Detection3DArray"))}
        for s in samples:
            for t, msg in (("tf2_msgs/msg/TFMessage", tf_message(s)),
                           ("vision_msgs/msg/Detection3DArray", _map_detections(s))):
                w.write(conns[t], s.t_ns, store.serialize_cdr(to_ros(store, t, msg), t))


def _map_detections(s: Sample) -> dict:
    """Detection3DArray with boxes in the map frame (needs the ego pose from /tf)."""
    d = detections_in_base_link(s)
    for det, a in zip(d["detections"], s.anns):
        det["header"]["frame_id"] = "map"
        det["bbox"]["center"] = {"position": dict(zip("xyz", a.translation)),
                                 "orientation": dict(zip("wxyz", a.rotation))}
    d["header"]["frame_id"] = "map"
    return d


def write_rosbag1(path: Path, samples: list[Sample], compression: str | None = None,
                  twist: list[tuple[float, float]] | None = None) -> None:
    """ROS 1 bag: MarkerArray (map frame) on /markers, ego pose as nav_msgs/Odometry on /odom (with a twist per
    sample where given)."""
    from rosbags.rosbag1 import Writer

    from extractors.rosbag import typestore

    store = typestore(ros1=True)
    w = Writer(path)
    if compression:
        w.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with w:
        conns = {t: w.add_connection(topic, t, typestore=store) for topic, t in (
            ("/odom", "nav_msgs/msg/Odometry"), ("/markers", "visualization_msgs/msg/MarkerArray"))}
        for k, s in enumerate(samples):
            odo = odometry(s, twist[k]) if twist else odometry(s)
            for t, msg in (("nav_msgs/msg/Odometry", odo), ("visualization_msgs/msg/MarkerArray", markers_in_map(s))):
                w.write(conns[t], s.t_ns, store.serialize_ros1(to_ros(store, t, msg, ros1=True), t))
