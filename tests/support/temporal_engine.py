"""The temporal engine's matches in the form of tests/support/temporal_bruteforce: r2s query's `--all` rows mapped to
track tuples through the frames' own (scene, id) -> track."""

from __future__ import annotations

from pathlib import Path

import pyarrow.parquet as pq

from frames.rows import read_frames
from pipeline.query.mining import query_frames
from synth.patterns.temporal import parse_temporal


def engine_temporal(frames_path: Path, text: str, out_dir: Path) -> dict:
    """{frame_id: {tracks tuple}} from `--all`, mapped to tracks by the frames' own (scene, id) -> track."""
    pattern = parse_temporal(text)
    out = out_dir / "all.parquet"
    query_frames(frames_path, pattern, out, all_bindings=True, log=lambda s: None)
    frames = read_frames(frames_path)
    track = frames[~frames.is_ego].groupby(["scene", "entity_id"]).track_id.agg(set).to_dict()
    got: dict[str, set] = {}
    for r in pq.read_table(out).to_pylist():
        ids = tuple(r["binding"][n] for n in pattern.names)
        tracks = []
        for i in ids:
            (t,) = track[(r["scene"], i)]  # one track per id within a scene (stable ids)
            tracks.append(t)
        got.setdefault(r["frame_id"], set()).add(tuple(tracks))
    return got
