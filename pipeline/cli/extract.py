"""`r2s extract SOURCE INPUT --out frames.parquet`: recorded data in, the one frames schema out."""

from __future__ import annotations

import argparse
import sys

from extractors.registry import SOURCES


def _topics(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.split(",") if t.strip())


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", choices=tuple(SOURCES), help="what INPUT is")
    p.add_argument("input", help="dataroot (nuscenes), database dir or .pkl (scenarionet), log dir (argoverse2), "
                                 ".mcap file or dir (mcap), .bag file or ROS 2 bag dir (rosbag)")
    p.add_argument("--out", required=True, metavar="PATH",
                   help="frames Parquet file to write (atomically), or a dataset directory (one part file per "
                        "input file, log or bag) if PATH does not end in .parquet")
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="extract N input files (logs, bags) at once, in worker processes (default 1)")
    p.add_argument("--radius", type=float, default=50.0, metavar="M", help="keep objects within M metres of ego")
    p.add_argument("--categories", default="vehicles", metavar="C",
                   help="vehicles (default), all, or a comma list of Scenic classes / raw categories "
                        "(Car,Pedestrian or human.pedestrian,vehicle.car)")
    p.add_argument("--every", type=int, default=1, metavar="K", help="keep every K-th frame")
    p.add_argument("--max-entities", type=int, default=1000, metavar="N",
                   help="refuse a frame with more than N entities")
    g = p.add_argument_group("nuscenes")
    g.add_argument("--version", default="v1.0-mini", help="nuScenes version folder (v1.0-mini, v1.0-trainval, ...)")
    g.add_argument("--scenes", type=_topics, default=(), metavar="S,...", help="only these scene names (default: all)")
    g.add_argument("--min-visibility", type=int, default=0, metavar="V",
                   help="keep annotations with visibility level >= V (1-4; 0 keeps all)")
    g.add_argument("--min-lidar-pts", type=int, default=0, metavar="N", help="keep annotations with >= N lidar points")
    g = p.add_argument_group("mcap / rosbag")
    g.add_argument("--topics", type=_topics, default=(), metavar="T,...",
                   help="annotation topics (default: every SceneUpdate / Detection3DArray / MarkerArray topic)")
    g.add_argument("--pose-topic", metavar="T", help="ego pose topic (PoseStamped, Odometry, PoseInFrame); default /tf")
    g.add_argument("--fixed-frame", default="map", metavar="F", help="global frame of the ego pose")
    g.add_argument("--ego-frame", default="base_link", metavar="F", help="the vehicle's frame")
    g.add_argument("--max-chunk-mb", type=float, default=256, metavar="MB",
                   help="refuse compressed chunks that claim to decompress to more than this")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from extractors.base import ExtractOptions, ExtractTally
    from extractors.categories import CategorySelection
    from extractors.frames import FramesError
    from extractors.registry import source_module
    from extractors.sniff import wrong_source_hint
    from extractors.writer import frames_writer
    from pipeline.errors import UserError

    module = source_module(args.source)
    try:
        options = ExtractOptions(
            radius=args.radius, categories=CategorySelection.parse(args.categories, module.TAXONOMY),
            every=args.every, max_entities=args.max_entities, version=args.version, scenes=args.scenes,
            min_visibility=args.min_visibility, min_lidar_pts=args.min_lidar_pts, topics=args.topics,
            pose_topic=args.pose_topic, fixed_frame=args.fixed_frame, ego_frame=args.ego_frame,
            max_chunk_bytes=int(args.max_chunk_mb * 2**20),
        )
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if args.jobs < 1:
        raise UserError(f"--jobs must be at least 1, got {args.jobs}")
    tally = ExtractTally(warn=lambda line: tqdm.write(line, file=sys.stderr))
    from pipeline.batch.extract import extract_parallel, is_dataset

    if args.jobs > 1 or is_dataset(args.out):
        try:
            frames, rows = extract_parallel(args.source, args.input, args.out, options, args.jobs, tally)
        except (FramesError, UserError):
            if hint := wrong_source_hint(args.source, args.input):
                raise UserError(hint) from None
            raise
        _summary(tally, frames, rows, args.out)
        return 0
    with frames_writer(args.out) as out:
        bar = tqdm(module.extract(args.input, options, tally), desc=f"extract {args.source}", unit=" frames",
                   file=sys.stderr, disable=None, leave=False)
        try:
            for rows in bar:
                out.write_frame(rows)
            if out.frames == 0:
                raise UserError(f"no frames found in {args.input} (check the source, --categories and --topics)")
        except (FramesError, UserError):
            # a source that found nothing to read may have been given another source's input: say which
            if out.frames == 0 and (hint := wrong_source_hint(args.source, args.input)):
                raise UserError(hint) from None
            raise
    _summary(tally, out.frames, out.rows, args.out)
    return 0


def _summary(tally, frames: int, rows: int, out: str) -> None:
    notes = tally.notes()
    sys.stderr.write(f"r2s extract: {tally.scenarios_read} scenarios, {frames} frames, {rows} rows -> "
                     f"{out}{'; ' + notes if notes else ''}\n")
