"""`r2s extract SOURCE INPUT --out frames.parquet`: recorded data in, the one frames schema out."""

from __future__ import annotations

import argparse
import dataclasses
import sys

from tqdm import tqdm

from extractors.base import ExtractOptions
from extractors.categories import CategorySelection
from extractors.registry import SOURCES, source, sources
from pipeline.errors import UserError


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
    p.add_argument("--strict-maps", action="store_true",
                   help="refuse (exit 2) a map that breaks a rule of the map format, instead of repairing or "
                        "dropping the feature (counted in the summary) or extracting the frames without road "
                        "columns when the map cannot be used at all")
    # each source's own options, one group per options class (sources that share options share the group)
    families: dict[type[ExtractOptions], list[str]] = {}
    for s in known:
        if s.options is not ExtractOptions:
            families.setdefault(s.options, []).append(s.name)
    for options, names in families.items():
        options.add_options(p.add_argument_group(" / ".join(names)))


def run(args: argparse.Namespace) -> int:
    from pipeline.batch.extract import extract

    src = source(args.source)
    # the source's own options as its options class reads them from the command line
    common = {"radius": 50.0, "categories": CategorySelection.parse("all", src.taxonomy), "every": 1,
              "max_entities": 1000}
    try:
        own = src.options.options_from(args, **common)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    base = {f.name for f in dataclasses.fields(ExtractOptions)}
    source_options = {f.name: getattr(own, f.name) for f in dataclasses.fields(own) if f.name not in base}
    summary = extract(args.source, args.input, args.out, categories=args.categories, radius=args.radius,
                      every=args.every, max_entities=args.max_entities, jobs=args.jobs,
                      strict_maps=args.strict_maps,
                      warn=lambda line: tqdm.write(line, file=sys.stderr), **source_options)
    sys.stderr.write(f"r2s extract: {summary.line()}\n")
    return 0
