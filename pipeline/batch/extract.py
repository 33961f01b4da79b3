"""`r2s extract` (extract, its Python API: `from pipeline import extract`), and with --jobs N or a dataset output
the input's pieces (Source.units) extracted in parallel worker
processes, each into its own part file, written atomically.

The parts (and the maps of their scenarios, in _maps/: frames.maps) are staged in a hidden directory beside
the output and take its place only when every piece is done
and the whole dataset passed the frames check (a frame id given by two pieces is refused, as one writer would
refuse it): a failure or a kill leaves the previous output or none, never part of one. Parts are named by the
piece's position in the input, so the output is the same whatever the order pieces finish in. Memory: each
worker streams its frames into its part in row groups (frames.writer); the coordinator holds a count.
"""

from __future__ import annotations

import dataclasses
import os
import shutil
import sys
from collections import Counter
from concurrent.futures import as_completed
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
from joblib.externals.loky import get_reusable_executor
from tqdm import tqdm

from extractors.base import ExtractOptions, ExtractTally, Source
from extractors.categories import CategorySelection
from extractors.registry import source as source_named
from extractors.sniff import wrong_source_hint
from frames.dataset import FramesDataset
from frames.maps import check_maps_target, maps_dir, maps_writer, replace_maps
from frames.rows import FramesError
from frames.schema import MAPS_DIR
from frames.writer import frames_writer
from pipeline.batch.parent import watch_parent
from pipeline.errors import UserError
from pipeline.outputs import check_apart, check_folder, scratch_beside, staged_directory
from storage.atomic import atomic_path
from storage.frame_index import FrameIndex, frame_hashes

PART = "part-{:06d}.parquet"


@dataclass(frozen=True)
class UnitResult:
    index: int
    frames: int
    rows: int
    scenes: tuple[str, ...]  # scene names, in order: a name met in an earlier piece is that piece's
    tally: ExtractTally
    frame_hashes: tuple[Any, Any]  # (hi, lo) of its frame ids (storage.frame_index): 16 bytes a frame


@dataclass(frozen=True)
class ExtractSummary:
    """What an extraction wrote (`r2s extract`'s last line is `line()`): scenarios read, frames and rows written,
    and what it left out and why (ExtractTally.notes)."""

    scenarios: int
    frames: int
    rows: int
    out: str
    notes: str

    def line(self) -> str:
        return (f"{self.scenarios} scenarios, {self.frames} frames, {self.rows} rows -> {self.out}"
                f"{'; ' + self.notes if self.notes else ''}")


def extract(source: str, input_path: str | os.PathLike, out: str | os.PathLike, *, categories: str = "all",
            radius: float = 50.0, every: int = 1, max_entities: int = 1000, jobs: int = 1,
            strict_maps: bool = False, warn=None, **source_options: Any) -> ExtractSummary:
    """`r2s extract SOURCE INPUT --out OUT` in-process (docs/api.md): the source's recorded data at `input_path`
    to a frames file (`out` ends in .parquet) or dataset directory, with the maps beside it. `source_options` are
    the fields of the source's options class (nuscenes: version, scenes, min_visibility, min_lidar_pts; mcap and
    rosbag: topics, pose_topic, fixed_frame, ego_frame, max_chunk_bytes). A map that breaks a rule is repaired or
    dropped and counted (docs/formats.md), or with `strict_maps` refused. Bad input raises an InputError before
    anything is written; `warn` receives the warnings `r2s extract` prints (default: stderr)."""
    input_path, out = str(input_path), str(out)
    check_apart(out, [("input", input_path)], directory=not out.endswith(".parquet"))
    try:
        src = source_named(source)
    except KeyError as exc:
        raise UserError(exc.args[0]) from None
    own = {f.name for f in dataclasses.fields(src.options)} - {f.name for f in dataclasses.fields(ExtractOptions)}
    unknown = sorted(set(source_options) - own)
    if unknown:
        raise UserError(f"source {source} has no option {unknown[0]!r} (its options: {', '.join(sorted(own)) or 'none'})")
    try:
        options = src.options(radius=radius, categories=CategorySelection.parse(categories, src.taxonomy),
                              every=every, max_entities=max_entities, strict_maps=strict_maps, **source_options)
    except ValueError as exc:
        raise UserError(str(exc)) from None
    if jobs < 1:
        raise UserError(f"--jobs must be at least 1, got {jobs}")
    tally = ExtractTally(**({"warn": warn} if warn is not None else {}))
    try:
        if jobs > 1 or is_dataset(out):
            frames, rows = extract_parallel(src, input_path, out, options, jobs, tally)
        else:
            frames, rows = _extract_file(src, input_path, out, options, tally)
    except (FramesError, UserError):
        # a source that found nothing to read may have been given another source's input: say which
        if hint := wrong_source_hint(source, input_path):
            raise UserError(hint) from None
        raise
    return ExtractSummary(tally.scenarios_read, frames, rows, out, tally.notes())


def _extract_file(src: Source, input_path: str, out: str, options: ExtractOptions,
                  tally: ExtractTally) -> tuple[int, int]:
    """One frames file, written as the frames stream, and its maps beside it (F.maps/), staged until the frames
    are written."""
    target = maps_dir(out)
    real = check_maps_target(target)
    staged = real.with_name(f".{real.name}.{os.getpid()}.tmp")  # beside its place: a link's folder is replaced
    try:
        with frames_writer(out) as written, maps_writer(staged / "part-000000.parquet") as maps:
            bar = tqdm(src.extract(input_path, options, tally, maps=maps.add), desc=f"extract {src.name}",
                       unit=" frames", file=sys.stderr, disable=None, leave=False)
            for rows in bar:
                written.write_frame(rows)
            if written.frames == 0:
                raise UserError(f"no frames found in {input_path} (check the source, --categories and --topics)")
        replace_maps(staged, target)
    finally:
        shutil.rmtree(staged, ignore_errors=True)
    return written.frames, written.rows


def extract_unit(source: Source, unit: str, index: int, options: ExtractOptions, stage: str) -> UnitResult:
    """One piece into `stage/part-<index>.parquet` and its maps into `stage/_maps/part-<index>.parquet` (nothing
    when it has no frame or no map). The source itself goes to the worker (pickled by its class's name), so a
    source need only be importable there, not registered."""
    tally = ExtractTally()
    scenes: list[str] = []
    path = Path(stage) / PART.format(index)
    map_path = Path(stage) / MAPS_DIR / PART.format(index)
    with frames_writer(path) as out, maps_writer(map_path) as maps:
        for rows in source.extract(unit, options, tally, maps=maps.add):
            if not scenes or scenes[-1] != rows[0]["scene"]:
                scenes.append(rows[0]["scene"])
            out.write_frame(rows)
    if out.frames == 0:
        path.unlink(missing_ok=True)
        map_path.unlink(missing_ok=True)
    return UnitResult(index, out.frames, out.rows, tuple(scenes), tally, frame_hashes(sorted(out.frame_ids)))


def add_tally(total: ExtractTally, part: ExtractTally) -> None:
    for f in fields(ExtractTally):
        value = getattr(part, f.name)
        if isinstance(value, (int, Counter)) and not isinstance(value, bool) and not f.name.startswith("_"):
            setattr(total, f.name, getattr(total, f.name) + value)


def is_dataset(out: str) -> bool:
    p = Path(out)
    return p.is_dir() or p.suffix != ".parquet"


def extract_parallel(source: Source, input_path: str, out: str, options: ExtractOptions, jobs: int,
                     tally: ExtractTally) -> tuple[int, int]:
    """Extract every piece of the input (in `jobs` worker processes when jobs > 1) into `out`: a dataset
    directory of parts (replaced whole: pipeline.outputs.staged_directory), or one file merged from them.
    Returns (frames, rows)."""
    target = Path(out)
    if is_dataset(out):
        check_folder(target, _frames_parts, FRAMES_PARTS)
        units = source.units(input_path)
        with staged_directory(target, _frames_parts, FRAMES_PARTS) as stage:  # a crashed extraction's is removed
            return _extract_into(stage, source, units, input_path, options, jobs, tally)
    units = source.units(input_path)
    with scratch_beside(target) as stage:
        frames, rows = _extract_into(stage, source, units, input_path, options, jobs, tally)
        check_maps_target(maps_dir(target))
        _merge(stage, target)
        replace_maps(stage / MAPS_DIR, maps_dir(target))
        return frames, rows


def _extract_into(stage: Path, source: Source, units: list[str], input_path: str, options: ExtractOptions,
                  jobs: int, tally: ExtractTally) -> tuple[int, int]:
    """The parts of every piece, checked, in `stage` (their maps in stage/_maps/, absent without a map)."""
    (stage / MAPS_DIR).mkdir()
    results = []
    bar = tqdm(total=len(units), desc=f"extract {source.name}", unit=" inputs", file=sys.stderr, disable=None,
               leave=False)
    for result in _map(source, units, options, str(stage), jobs):
        results.append(result)
        bar.update(1)
    bar.close()
    kept = _keep_first_scenes(sorted(results, key=lambda r: r.index), units, stage, tally)
    frames, rows = sum(r.frames for r in kept), sum(r.rows for r in kept)
    if frames == 0:
        raise UserError(f"no frames found in {input_path} (check the source, --categories and --topics)")
    _check(stage, kept)
    if not any((stage / MAPS_DIR).iterdir()):
        (stage / MAPS_DIR).rmdir()
    return frames, rows


def _map(source, units, options, stage, jobs):
    if jobs <= 1:
        for i, unit in enumerate(units):
            yield extract_unit(source, unit, i, options, stage)
        return
    executor = get_reusable_executor(max_workers=min(jobs, len(units)), initializer=watch_parent,
                                     initargs=(os.getpid(),))  # its workers end with this process
    futures = [executor.submit(extract_unit, source, unit, i, options, stage) for i, unit in enumerate(units)]
    try:
        for future in as_completed(futures):
            yield future.result()
    except BaseException:
        for f in futures:
            f.cancel()
        # Wait for the killed workers to be gone: one still writing would leave files in the staging
        # directory after it is removed.
        executor.shutdown(wait=True, kill_workers=True)
        raise


def _keep_first_scenes(results: list[UnitResult], units: list[str], stage: Path,
                       tally: ExtractTally) -> list[UnitResult]:
    """A scene already given by an earlier piece is that piece's (the same scene converted twice): the later
    piece is skipped with a warning, as a single reader skips it. Returns the pieces kept."""
    seen: dict[str, int] = {}
    kept = []
    for r in results:
        clash = next((s for s in r.scenes if s in seen), None)
        if clash is not None:
            (stage / PART.format(r.index)).unlink(missing_ok=True)
            (stage / MAPS_DIR / PART.format(r.index)).unlink(missing_ok=True)
            tally.skip("duplicate scenario id", f"r2s extract: skipping {units[r.index]}: scenario {clash!r} was "
                       f"already read from {units[seen[clash]]}")
            continue
        seen.update(dict.fromkeys(r.scenes, r.index))
        add_tally(tally, r.tally)
        kept.append(r)
    return kept


def _check(stage: Path, kept: list[UnitResult]) -> None:
    """Frame ids unique across the parts. Each part was validated as it was written (frames.writer), so only
    the workers' frame-id hashes are compared here; re-reading every part cost the coordinator ~3 s per 50,000
    frames, alone while the workers wait. A clash is then named by the full check of the staged dataset."""
    hi, _ = FrameIndex.of(r.frame_hashes for r in kept).duplicated()
    if len(hi):
        FramesDataset.open(stage).check()


FRAMES_PARTS = "frames parts"


def _frames_parts(entry: os.DirEntry) -> bool:
    """What `r2s extract --out DIR` writes there: part files, and _maps/ of part files."""
    if entry.name == MAPS_DIR and entry.is_dir(follow_symlinks=False):
        return _only_parts(Path(entry.path))
    return entry.is_file(follow_symlinks=False) and _is_part(entry.name)


def _is_part(name: str) -> bool:
    return name.startswith("part-") and name.endswith(".parquet")


def _only_parts(folder: Path) -> bool:
    return all(p.is_file() and not p.is_symlink() and _is_part(p.name) for p in folder.iterdir())


def _merge(stage: Path, target: Path) -> None:
    """The parts, in order, into one file, a row group at a time."""
    parts = sorted(stage.glob("part-*.parquet"))
    schema = pq.ParquetFile(parts[0]).schema_arrow
    with atomic_path(target) as tmp, pq.ParquetWriter(tmp, schema, compression="zstd") as writer:
        for part in parts:
            pf = pq.ParquetFile(part)
            if pf.schema_arrow != schema:
                raise UserError(f"the pieces of the input give frames with different columns ({part.name})")
            for i in range(pf.metadata.num_row_groups):
                writer.write_table(pf.read_row_group(i))
