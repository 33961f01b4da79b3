"""ROS 1 .bag files and ROS 2 bags (sqlite3 or mcap storage), through rosbags, as frames.

Input: a .bag file, a ROS 2 bag directory (metadata.yaml), or a directory holding .bag files. The message
layouts and topic choice are those of extractors.messages (Detection3DArray, MarkerArray, foxglove
SceneUpdate; ego pose from /tf or --pose-topic). Types come from the definitions stored in the bag; bags
without them fall back to the ROS 2 Humble types plus vision_msgs, which rosbags does not ship.
Resource bounds: the .mcap files of a ROS 2 bag get the mcap source's full check; ROS 1 chunks are
decompressed with a cap of --max-chunk-mb.
"""

from __future__ import annotations

import bz2
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from extractors import messages
from extractors.base import ExtractError, ExtractTally, Look, MapSink, Source, require_path
from extractors.mcap import check_mcap
from extractors.messages import (
    LogOptions,
    PoseTrack,
    choose_annotation_topics,
    choose_pose_topics,
    message_frames,
    pose_samples,
)
from extractors.sniff import head
from storage.regular_files import check_regular

DESCRIPTION = "ROS 1 .bag or ROS 2 bag directory (sqlite3 / mcap storage) through rosbags"
TAXONOMY = messages.TAXONOMY
ROSBAG1_MAGIC = b"#ROSBAG V2.0"
ROSBAG2_METADATA = b"rosbag2_bagfile_information"  # the top key of a ROS 2 bag's metadata.yaml

# vision_msgs (ROS 2 Humble), which the rosbags typestores do not carry.
VISION_MSGS = {
    "vision_msgs/msg/ObjectHypothesis": "string class_id\nfloat64 score\n",
    "vision_msgs/msg/ObjectHypothesisWithPose": (
        "vision_msgs/ObjectHypothesis hypothesis\ngeometry_msgs/PoseWithCovariance pose\n"),
    "vision_msgs/msg/BoundingBox3D": "geometry_msgs/Pose center\ngeometry_msgs/Vector3 size\n",
    "vision_msgs/msg/Detection3D": (
        "std_msgs/Header header\nvision_msgs/ObjectHypothesisWithPose[] results\n"
        "vision_msgs/BoundingBox3D bbox\nstring id\n"),
    "vision_msgs/msg/Detection3DArray": "std_msgs/Header header\nvision_msgs/Detection3D[] detections\n",
}


def typestore(ros1: bool = False) -> Any:
    """The rosbags typestore (ROS 1 Noetic or ROS 2 Humble) with vision_msgs registered."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    types: dict = {}
    for name, text in VISION_MSGS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def bag_paths(path: Path) -> list[tuple[Path, bool]]:
    """(bag, is ROS 1) for a .bag file, a ROS 2 bag directory, or a directory of .bag files."""
    if path.is_file():
        if path.suffix != ".bag":
            raise ExtractError(f"{path} is not a ROS 1 .bag file nor a ROS 2 bag directory")
        return [(path, True)]
    if (path / "metadata.yaml").exists():  # even when it is no regular file: _open refuses it by name
        return [(path, False)]
    bags = sorted(path.rglob("*.bag"))
    if not bags:
        raise ExtractError(f"{path} is neither a ROS 2 bag (no metadata.yaml) nor holds ROS 1 .bag files")
    return [(b, True) for b in bags]


def _bounded(decompress: Callable[[bytes], bytes], limit: int, where: Path) -> Callable[[bytes], bytes]:
    import lz4.frame

    def run(data: bytes) -> bytes:
        if decompress is bz2.decompress:
            out = bz2.BZ2Decompressor().decompress(data, max_length=limit + 1)
        elif decompress is lz4.frame.decompress:
            out = lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1)
        else:
            out = decompress(data)
        if len(out) > limit:
            raise ExtractError(f"{where}: a chunk decompresses to more than {limit // 2**20} MB (--max-chunk-mb)")
        return out

    return run


def _cap_ros1_chunks(reader: Any, limit: int, where: Path) -> None:
    """rosbags decompresses a ROS 1 chunk whole; give each chunk a decompressor that stops past the limit."""
    for sub in getattr(reader, "readers", []):
        chunks = getattr(sub, "chunks", None)
        if not isinstance(chunks, dict):
            continue
        for pos, chunk in list(chunks.items()):
            if hasattr(chunk, "decompressor"):
                chunks[pos] = chunk._replace(decompressor=_bounded(chunk.decompressor, limit, where))


def _open(bag: Path, ros1: bool, options: LogOptions) -> Any:
    from rosbags.highlevel import AnyReader

    # rosbags opens the files itself: each must be a regular file first (a FIFO would block it, /dev/zero fill
    # memory). A ROS 2 bag directory holds its metadata.yaml and its storage files, nothing else.
    for f in [bag] if ros1 else sorted(p for p in bag.iterdir() if not p.is_dir()):
        try:
            check_regular(f)
        except OSError as exc:
            raise ExtractError(f"{f} {exc.strerror}") from None
    if not ros1:
        for f in sorted(bag.glob("*.mcap")):
            check_mcap(f, options.max_chunk_bytes)
    reader = AnyReader([bag], default_typestore=typestore(ros1))
    reader.open()
    if ros1:
        _cap_ros1_chunks(reader, options.max_chunk_bytes, bag)
    return reader


def _messages(reader: Any, bag: Path, topics: list[str]) -> Iterator[tuple[str, int, Any]]:
    conns = [c for c in reader.connections if c.topic in topics]
    if not conns:
        return
    try:
        for conn, t, raw in reader.messages(connections=conns):
            yield conn.msgtype, int(t), reader.deserialize(raw, conn.msgtype)
    except ExtractError:
        raise
    except Exception as exc:
        raise ExtractError(f"{bag}: cannot read its messages ({type(exc).__name__}: {str(exc)[:100]})") from None


def extract(input_path: str, options: LogOptions, tally: ExtractTally | None = None,
            maps: MapSink | None = None) -> Iterator[list[dict[str, Any]]]:
    """Frames without maps (this source's recordings carry none): `maps` is never called."""
    for bag, ros1 in bag_paths(require_path(input_path, "bag")):
        try:
            reader = _open(bag, ros1, options)
        except ExtractError:
            raise
        except Exception as exc:  # rosbags reports corrupt bags with its own error classes and others
            raise ExtractError(f"{bag} is not a readable bag ({type(exc).__name__}: {str(exc)[:100]})") from None
        try:
            topics = {c.topic: c.msgtype for c in reader.connections}
            wanted = choose_annotation_topics(topics, options, str(bag))
            pose_topics = choose_pose_topics(topics, options, str(bag))
            poses = PoseTrack(p for schema, t, msg in _messages(reader, bag, pose_topics)
                              for p in pose_samples(msg, schema, options, t))
            yield from message_frames("rosbag", bag.stem, _messages(reader, bag, wanted), poses, options, str(bag),
                                      tally)
        finally:
            reader.close()


class Rosbag(Source):
    name = "rosbag"
    description = DESCRIPTION
    input_help = ".bag file or ROS 2 bag dir"
    taxonomy = TAXONOMY
    options = LogOptions
    extract = staticmethod(extract)

    def unit_paths(self, path: Path) -> list[Path]:
        return [bag for bag, _ in bag_paths(path)]

    def look_at_file(self, path: Path, head: bytes) -> Look | None:
        if head.startswith(ROSBAG1_MAGIC):
            return Look(self.name, "a ROS 1 bag", str(path))
        if path.name == "metadata.yaml" and _is_ros2_metadata(path):
            return Look(self.name, "the metadata.yaml of a ROS 2 bag", str(path.parent))
        return None

    def look_at_entry(self, top: str, path: Path, is_dir: bool, depth: int) -> Look | None:
        if is_dir:
            return None
        if path.name == "metadata.yaml" and _is_ros2_metadata(path):
            return Look(self.name, "a ROS 2 bag (metadata.yaml)", top if depth == 0 else str(path.parent))
        if path.name.endswith(".bag") and head(path).startswith(ROSBAG1_MAGIC):
            return Look(self.name, "a folder of ROS 1 bags (.bag)", top)
        return None


def _is_ros2_metadata(path: Path) -> bool:
    return ROSBAG2_METADATA in head(path, 256)


SOURCE = Rosbag()
