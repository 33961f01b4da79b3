"""`r2s extract SOURCE INPUT --out frames.parquet`: recorded data in, the one frames schema out."""

from __future__ import annotations

import argparse
import os
import shutil
import sys

from tqdm import tqdm

from extractors.base import ExtractOptions, ExtractTally
from extractors.categories import CategorySelection
from extractors.frames import FramesError
from extractors.registry import SOURCES, source, sources
from extractors.sniff import wrong_source_hint
from extractors.writer import frames_writer
from pipeline.batch.extract import extract_parallel, is_dataset
from pipeline.errors import UserError
from pipeline.outputs import check_apart


def add_arguments(p: argparse.ArgumentParser) -> None:
    known = sources()
    p.add_argument("source", choices=tuple(SOURCES), help="what INPUT is")
    p.add_argument("input", help=", ".join(f"{s.input_help} ({s.name})" for s in known))
    p.add_argument("--out", required=True, metavar="PATH",
                   help="frames Parquet file to write (atomically), or a dataset directory (one part file per "
                        "input file, log or bag) if PATH does not end in .parquet")
    p.add_argument("--jobs", type=int, default=1, metavar="N",
                   help="extract N input files (logs, bags) at once, in worker processes (default 1)")
    p.add_argument("--radius", type=float, default=50.0, metavar="M", help="keep objects within M metres of ego")
    p.add_argument("--categories", default="all", metavar="C",
                   help="all (default: every type, so a query for pedestrians finds them), vehicles, or a comma "
                        "list of Scenic classes / raw categories "
                        "(Car,Pedestrian or human.pedestrian,vehicle.car)")
    p.add_argument("--every", type=int, default=1, metavar="K", help="keep every K-th frame")
    p.add_argument("--max-entities", type=int, default=1000, metavar="N",
                   help="refuse a frame with more than N entities")
    # each source's own options, one group per options class (sources that share options share the group)
    families: dict[type[ExtractOptions], list[str]] = {}
    for s in known:
        if s.options is not ExtractOptions:
            families.setdefault(s.options, []).append(s.name)
    for options, names in families.items():
        options.add_options(p.add_argument_group(" / ".join(names)))


def run(args: argparse.Namespace) -> int:
    check_apart(args.out, [("input", args.input)], directory=not str(args.out).endswith(".parquet"))
    src = source(args.source)
    try:
        options = src.options.options_from(
            args, radius=args.radius, categories=CategorySelection.parse(args.categories, src.taxonomy),
            every=args.every, max_entities=args.max_entities)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if args.jobs < 1:
        raise UserError(f"--jobs must be at least 1, got {args.jobs}")
    tally = ExtractTally(warn=lambda line: tqdm.write(line, file=sys.stderr))

    if args.jobs > 1 or is_dataset(args.out):
        try:
            frames, rows = extract_parallel(src, args.input, args.out, options, args.jobs, tally)
        except (FramesError, UserError):
            if hint := wrong_source_hint(args.source, args.input):
                raise UserError(hint) from None
            raise
        _summary(tally, frames, rows, args.out)
        return 0
    from extractors.maps import check_maps_target, maps_dir, maps_writer, replace_maps

    # The maps go beside the file (F.maps/), staged until the frames are written.
    target = maps_dir(args.out)
    check_maps_target(target)
    staged = target.with_name(f".{target.name}.{os.getpid()}.tmp")
    try:
        with frames_writer(args.out) as out, maps_writer(staged / "part-000000.parquet") as maps:
            bar = tqdm(src.extract(args.input, options, tally, maps=maps.add), desc=f"extract {args.source}",
                       unit=" frames", file=sys.stderr, disable=None, leave=False)
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
        replace_maps(staged, target)
    finally:
        shutil.rmtree(staged, ignore_errors=True)
    _summary(tally, out.frames, out.rows, args.out)
    return 0


def _summary(tally, frames: int, rows: int, out: str) -> None:
    notes = tally.notes()
    sys.stderr.write(f"r2s extract: {tally.scenarios_read} scenarios, {frames} frames, {rows} rows -> "
                     f"{out}{'; ' + notes if notes else ''}\n")
