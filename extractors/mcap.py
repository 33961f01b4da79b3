"""MCAP logs (foxglove.SceneUpdate in protobuf or JSON, ROS 2 Detection3DArray / MarkerArray) as frames.

Input: an .mcap file or a directory of them; scene = the file's stem, one frame per annotation message. The
message layouts and the choice of topics are in extractors.messages. Before anything is decoded the whole
file is checked record by record: a truncated file, a foreign file, a record larger than the chunk limit, or a
compressed chunk that claims (or turns out) to decompress to more than --max-chunk-mb is refused, so a
decompression bomb never gets its memory.
"""

from __future__ import annotations

import io
import json
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from extractors import messages
from extractors.base import ExtractError, ExtractTally, Look, MapSink, Source, files_with_suffix, require_path
from extractors.messages import (
    LogOptions,
    PoseTrack,
    choose_annotation_topics,
    choose_pose_topics,
    message_frames,
    pose_samples,
)
from extractors.sniff import head
from storage.regular_files import open_regular

DESCRIPTION = "MCAP files with foxglove.SceneUpdate (protobuf / JSON) or ROS 2 Detection3DArray / MarkerArray"
TAXONOMY = messages.TAXONOMY
MCAP_MAGIC = b"\x89MCAP0\r\n"


def _bounded_decompress(compression: str, data: bytes, limit: int) -> int:
    """Decompressed length of a chunk, never producing more than limit + 1 bytes."""
    if compression == "zstd":
        import zstandard

        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data)) as r:
            return len(r.read(limit + 1))
    if compression == "lz4":
        import lz4.frame

        return len(lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=limit + 1))
    if compression == "":
        return len(data)
    raise ExtractError(f"unsupported MCAP chunk compression {compression!r}")


def check_mcap(path: Path, limit: int) -> dict[str, str]:
    """Walk every record (and every chunk's records) within the limit; returns topic -> schema name."""
    from mcap.exceptions import RecordLengthLimitExceeded
    from mcap.records import Channel, Chunk, Schema
    from mcap.stream_reader import StreamReader, breakup_chunk

    schemas: dict[int, str] = {}
    channels: dict[str, int] = {}
    try:
        with open_regular(path) as fh:
            for rec in StreamReader(fh, emit_chunks=True, record_size_limit=limit).records:
                inner = [rec]
                if isinstance(rec, Chunk):
                    if rec.uncompressed_size > limit:
                        raise ExtractError(f"{path}: a chunk claims to decompress to {rec.uncompressed_size} bytes, "
                                           f"more than the limit of {limit} bytes (--max-chunk-mb)")
                    n = _bounded_decompress(rec.compression, rec.data, limit)
                    if n != rec.uncompressed_size:
                        raise ExtractError(f"{path}: a chunk decompresses to {'more than ' if n > limit else ''}{n} "
                                           f"bytes, not the {rec.uncompressed_size} it claims")
                    inner = breakup_chunk(rec)
                for r in inner:
                    if isinstance(r, Schema):
                        schemas[r.id] = r.name
                    elif isinstance(r, Channel):
                        channels[r.topic] = r.schema_id
    except ExtractError:
        raise
    except RecordLengthLimitExceeded as exc:
        raise ExtractError(
            f"{path}: a record is larger than the limit of {limit} bytes (--max-chunk-mb): {exc}"
        ) from None
    except OSError as exc:
        raise ExtractError(f"cannot read {path}: {exc.strerror or exc}") from None
    except Exception as exc:  # the mcap reader signals corrupt input with many exception types
        raise ExtractError(f"{path} is not a readable MCAP file ({type(exc).__name__}: {str(exc)[:100]})") from None
    return {topic: schemas.get(sid, "") for topic, sid in channels.items()}


class _JsonDecoderFactory:
    """Decodes JSON-encoded channels (foxglove's JSON SceneUpdate) into dicts."""

    def decoder_for(self, message_encoding: str, schema: Any) -> Callable[[bytes], Any] | None:
        return json.loads if message_encoding == "json" else None


def _decoders() -> list[Any]:
    from mcap_protobuf.decoder import DecoderFactory as ProtobufDecoderFactory
    from mcap_ros2.decoder import DecoderFactory as Ros2DecoderFactory

    return [ProtobufDecoderFactory(), Ros2DecoderFactory(), _JsonDecoderFactory()]


def _messages(path: Path, topics: list[str], schema_of: dict[str, str]) -> Iterator[tuple[str, int, Any]]:
    from mcap.reader import make_reader

    if not topics:
        return
    try:
        with open_regular(path) as fh:
            reader = make_reader(fh, decoder_factories=_decoders())
            for _, channel, message, decoded in reader.iter_decoded_messages(topics=topics, log_time_order=True):
                yield schema_of[channel.topic], int(message.log_time), decoded
    except ExtractError:
        raise
    except Exception as exc:
        raise ExtractError(f"{path}: cannot decode its messages ({type(exc).__name__}: {str(exc)[:100]})") from None


def extract(input_path: str, options: LogOptions, tally: ExtractTally | None = None,
            maps: MapSink | None = None) -> Iterator[list[dict[str, Any]]]:
    """Frames without maps (this source's recordings carry none): `maps` is never called."""
    for f in files_with_suffix(require_path(input_path, "MCAP input"), [".mcap"], "MCAP files"):
        topics = check_mcap(f, options.max_chunk_bytes)
        wanted = choose_annotation_topics(topics, options, str(f))
        pose_topics = choose_pose_topics(topics, options, str(f))
        poses = PoseTrack(p for schema, t, msg in _messages(f, pose_topics, topics)
                          for p in pose_samples(msg, schema, options, t))
        yield from message_frames("mcap", f.stem, _messages(f, wanted, topics), poses, options, str(f), tally)


class Mcap(Source):
    name = "mcap"
    description = DESCRIPTION
    input_help = ".mcap file or dir"
    taxonomy = TAXONOMY
    options = LogOptions
    extract = staticmethod(extract)

    def unit_paths(self, path: Path) -> list[Path]:
        return files_with_suffix(path, [".mcap"], "MCAP files")

    def look_at_file(self, path: Path, head: bytes) -> Look | None:
        return Look(self.name, "an MCAP file", str(path)) if head.startswith(MCAP_MAGIC) else None

    def look_at_entry(self, top: str, path: Path, is_dir: bool, depth: int) -> Look | None:
        if not is_dir and path.name.endswith(".mcap") and head(path).startswith(MCAP_MAGIC):
            return Look(self.name, "a folder of MCAP files", top)
        return None


SOURCE = Mcap()
