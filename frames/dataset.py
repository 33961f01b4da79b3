"""Frames at dataset scale: one frames Parquet file or a directory of them, read in row groups, never whole.

The frames schema (frames.rows) is one row per entity per frame, and a frame's rows are contiguous: every
extractor writes a frame's rows together (FramesWriter), and so does `r2s extract --jobs` (a frame never spans
two part files). Readers rely on that to cut the data into frames without a global sort, so it is checked: a
frame id that occurs in two places is refused, never silently split into two frames.

`FramesDataset.open` reads only footers (files, schemas, row-group sizes). `check` streams every row group
once, dictionary-encoded, and refuses the whole dataset on the first bad row, with the same one-line messages
as frames.rows.validate_frames (ids are printed into generated programs, so a bad id refuses the input
before any frame is synthesized). `runs` streams only the frame_id column and yields where each frame is.
Workers read their own rows with read_frame_rows (a file and a row range, through the same footer checks and a
check of every value as decoded), so frame data need not pass through the process that plans the work. A run's
check (`check(road=...)`) decodes and checks, in the same pass, every value of every column its workers will
read (FramesPart.read_columns), so a corrupt value refuses the run before a part of it is written.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from frames.schema import FRAMES_COLUMNS, FRAMES_SCHEMA, OPTIONAL_COLUMNS, ROAD_COLUMNS, FramesError
from storage.frame_index import FrameIndex, frame_hashes
from storage.parquet import (
    check_column_types,
    check_value_sizes,
    dataset_files,
    filesystem,
    footer,
    null_count,
    open_file,
    read_rows,
)
from synth.scene import EGO_ID, ENTITY_TYPES, SceneError, check_frame_id, check_identifier

# What the check reads: the columns validate_frames looks at. String columns are read dictionary-encoded:
# a frame id or entity id repeats on many rows, so the work is per distinct value, not per row.
CHECK_COLUMNS = ("frame_id", "entity_id", "type", "x", "y", "heading", "is_ego")
DICTIONARY_COLUMNS = ("frame_id", "entity_id", "type")
# Text columns are bounded before a byte of them is decoded (storage.parquet.check_value_sizes): ids are at most
# 256 characters (frame ids; entity ids 64), so an average of MAX_VALUE_BYTES a value is far above any real file.
STRING_COLUMNS = tuple(f.name for f in FRAMES_SCHEMA if pa.types.is_string(f.type))
# Every text column a frames file may have (a run's check reads them dictionary-encoded).
TEXT_COLUMNS = STRING_COLUMNS + tuple(c for c, t in {**OPTIONAL_COLUMNS, **ROAD_COLUMNS}.items() if pa.types.is_string(t))
MAX_VALUE_BYTES = 1024
OPTIONAL_SCHEMA = pa.schema(list(OPTIONAL_COLUMNS.items()))


class CorruptValues(FramesError):
    """Values that do not decode to their column's type; the message names the file."""


@dataclass(frozen=True)
class FramesPart:
    path: str  # inside the dataset's filesystem
    rows: int
    row_groups: tuple[int, ...]  # rows per row group
    optional: tuple[str, ...]  # optional columns this file has
    road: tuple[str, ...] = ()  # road columns this file has (its frames name their map: r2s run --lanes reads them)

    @property
    def columns(self) -> tuple[str, ...]:
        return FRAMES_COLUMNS + self.optional

    def read_columns(self, road: bool) -> tuple[str, ...]:
        """What a worker of `r2s run` reads of this part: the frames and optional columns it has, and its road
        columns when the run gives each frame its road (--lanes)."""
        return self.columns + (self.road if road else ())


@dataclass(frozen=True)
class CheckedFrames:
    """What FramesDataset.check found in a valid dataset."""

    frames: int
    index: FrameIndex  # of the frame ids
    largest: int  # rows (ego's included) of the largest frame: r2s query bounds its joins by it


@dataclass(frozen=True)
class FramesDataset:
    source: str  # as the user gave it
    parts: tuple[FramesPart, ...]

    @classmethod
    def open(cls, path: str | os.PathLike) -> FramesDataset:
        pafs, files = dataset_files(str(path), "frames", FramesError)
        parts = []
        for f in files:
            where = f if len(files) > 1 else str(path)
            meta = footer(pafs, f, where, FramesError)
            schema = check_footer(meta, where)
            # A row without a frame id belongs to no frame: refused here, where even `r2s scene` (which reads only
            # its frame's rows, and a filter on frame_id never matches a null) sees it.
            nulls = null_count(meta, "frame_id")
            if nulls is None:
                try:
                    with pafs.open_input_file(f) as handle:
                        nulls = pq.ParquetFile(handle).read(columns=["frame_id"]).column("frame_id").null_count
                except (pa.ArrowException, OSError, ValueError) as exc:
                    raise FramesError(f"{where} is not a readable Parquet file ({type(exc).__name__}: "
                                      f"{str(exc)[:120]})") from None
            if nulls:
                raise FramesError(f"{where}: column frame_id has {nulls} missing value(s): every row belongs to a frame")
            optional = tuple(c for c in OPTIONAL_COLUMNS if c in schema.names)
            road = tuple(c for c in ROAD_COLUMNS if c in schema.names)
            parts.append(FramesPart(f, meta.num_rows,
                                    tuple(meta.row_group(i).num_rows for i in range(meta.num_row_groups)), optional,
                                    road))
        return cls(str(path), tuple(parts))

    @property
    def rows(self) -> int:
        return sum(p.rows for p in self.parts)

    @property
    def url(self) -> str:
        """How workers name this dataset's filesystem (local paths stay paths)."""
        return self.source if "://" in self.source else ""

    def where(self, part: FramesPart) -> str:
        return part.path if len(self.parts) > 1 else self.source

    def row_groups(self, part: FramesPart, columns: tuple[str, ...],
                   dictionary: tuple[str, ...] = DICTIONARY_COLUMNS) -> Iterator[pa.Table]:
        pf = open_file(self.url, part.path, tuple(c for c in dictionary if c in columns))
        for i in range(len(part.row_groups)):
            yield pf.read_row_group(i, columns=list(columns))

    def check(self, hasher=None, road: bool | None = None) -> CheckedFrames:
        """Validate every row (streaming); return the number of frames, the index of their ids and the rows of the
        largest frame. A `hasher`
        (frames.frame_hash.FrameHasher) is fed the same row groups, with the columns it hashes, so the
        content of every frame is hashed in the same pass. With `road` (a run's check: whether its workers read
        the road columns), every value of every column the run's workers read (FramesPart.read_columns) is
        decoded and checked as they check it (_valid: UTF-8, dictionary indices, list offsets), with their message:
        a corrupt value the rules do not read is found here, before the run writes anything, not by a worker
        after parts of the run are written."""
        checker = FramesCheck()
        for part in self.parts:
            columns = CHECK_COLUMNS
            if hasher is not None:
                columns += tuple(c for c in hasher.columns if c in part.columns + part.road and c not in CHECK_COLUMNS)
            decoded = () if road is None else tuple(c for c in part.read_columns(road) if c not in columns)
            # Their text read dictionary-encoded, as the rules' ids are: a category, a scene, a lane repeats on
            # many rows, and a dictionary's values and indices are what a worker's plain read decodes to, so each
            # distinct value is checked (and hashed) once.
            dictionary = DICTIONARY_COLUMNS + tuple(c for c in columns + decoded if c in TEXT_COLUMNS)
            try:
                for table in self.row_groups(part, columns + decoded, dictionary):
                    if road is not None:  # the rules' columns too: their corrupt values refused in the workers' words
                        _valid(table, self.where(part))
                    checker.feed(table)
                    if hasher is not None:
                        hasher.feed(table, *_run_starts(_dictionary(table.column("frame_id"))))
                checker.end_part()
                if hasher is not None:
                    hasher.end_part()
            except CorruptValues:
                raise  # it names the file already, as a worker's refusal does
            except FramesError as exc:
                raise FramesError(f"{self.where(part)}: {exc}") from None
            except (pa.ArrowException, OSError) as exc:
                raise FramesError(f"{self.where(part)} is not a readable Parquet file "
                                  f"({type(exc).__name__}: {str(exc)[:120]})") from None
        index = checker.index()
        if checker.frames == 0:
            raise FramesError(f"{self.source} has no frames")
        hi, lo = index.duplicated()
        if len(hi):
            raise FramesError(f"{self.source}: {self._split_frame_message(hi[:1], lo[:1])}")
        if checker.ego_problem:
            raise FramesError(f"{self.source}: {checker.ego_problem}")
        return CheckedFrames(checker.frames, index, checker.largest)

    def _split_frame_message(self, hi: np.ndarray, lo: np.ndarray) -> str:
        wanted = FrameIndex(hi, lo)
        places = []
        for runs in self.runs():
            h = frame_hashes(runs.ids)
            for i in np.flatnonzero(wanted.contains(*h)):
                places.append((runs.ids[i], self.where(self.parts[runs.part]), int(runs.starts[i])))
                if len(places) == 2:
                    fid, f1, r1 = places[0]
                    _, f2, r2 = places[1]
                    return (f"frame {fid!r} occurs in two places ({f1} row {r1}, {f2 if f2 != f1 else 'and'} row "
                            f"{r2}): a frame's rows must be contiguous (one frame, one block of rows)")
        return "a frame id occurs in two places: a frame's rows must be contiguous"

    def runs(self) -> Iterator[FrameRuns]:
        """Where each frame is: per row group, the frames that end in it (a frame that continues into the next
        row group is given once, whole). Reads only the frame_id column."""
        for k, part in enumerate(self.parts):
            stitch = _Stitch()
            offset = 0
            for table in self.row_groups(part, ("frame_id",)):
                ids = _dictionary(table.column("frame_id"))
                starts, run_ids = _run_starts(ids)
                done = stitch.add(starts + offset, run_ids, table.num_rows)
                offset += table.num_rows
                if done is not None:
                    yield FrameRuns(k, *done)
            last = stitch.finish(offset)
            if last is not None:
                yield FrameRuns(k, *last)

    def read_all(self) -> pa.Table:
        """Every row, checked, as one table (small data: tests, `r2s eval-frontend`; runs stream instead): the
        frames columns, then the optional and road columns that some part has (null in the parts without them), so
        that a reader sees what `r2s query` and `r2s scene` see (map_heading, the lane facts)."""
        self.check()
        extra = {**OPTIONAL_COLUMNS, **ROAD_COLUMNS}
        optional = [c for c in extra if any(c in (*p.optional, *p.road) for p in self.parts)]
        schema = pa.schema(list(FRAMES_SCHEMA) + [(c, extra[c]) for c in optional])
        tables = []
        for part in self.parts:
            try:
                table = open_file(self.url, part.path).read(columns=list(part.columns + part.road))
            except (pa.ArrowException, OSError) as exc:  # the check read some columns; a page of another is bad
                raise FramesError(f"{self.where(part)} is not a readable Parquet file "
                                  f"({type(exc).__name__}: {str(exc)[:120]})") from None
            _valid(table, self.where(part))
            for c in optional:
                if c not in part.optional and c not in part.road:
                    table = table.append_column(c, pa.nulls(table.num_rows, extra[c]))
            try:  # the footer check holds the frames and optional columns to their kinds, not the road columns
                tables.append(table.select(schema.names).cast(schema))
            except (pa.ArrowException, ValueError) as exc:
                raise FramesError(f"{self.where(part)}: a road column does not have the schema's type "
                                  f"({str(exc)[:120]})") from None
        return pa.concat_tables(tables)

    def find(self, frame_id: str) -> pa.Table | None:
        """The rows of one frame (row-group statistics skip most of a large dataset), with their road columns, or
        None."""
        import pyarrow.dataset as ds  # it loads pandas: only a lookup pays for it, not `r2s extract --help`

        pafs, _ = filesystem(self.source)
        dataset = ds.dataset([p.path for p in self.parts], format="parquet", filesystem=pafs)
        columns = list(FRAMES_COLUMNS) + [c for c in (*OPTIONAL_COLUMNS, *ROAD_COLUMNS) if c in dataset.schema.names]
        try:
            table = dataset.to_table(columns=columns, filter=ds.field("frame_id") == frame_id)
        except (pa.ArrowException, OSError) as exc:
            raise FramesError(f"{self.source} is not a readable frames dataset ({str(exc)[:120]})") from None
        _valid(table, self.source)
        return table if table.num_rows else None


def check_footer(meta: pq.FileMetaData, where: str) -> pa.Schema:
    """What a frames file's footer must say before a value of it is decoded, for every reader of frames: the
    frames columns, of their types (a speed stored as text is refused), and text columns of bounded size
    (storage.parquet.check_value_sizes). Returns the file's schema."""
    try:
        schema = meta.schema.to_arrow_schema()
    except (pa.ArrowException, ValueError) as exc:
        raise FramesError(f"{where} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:120]})") from None
    missing = [c for c in FRAMES_COLUMNS if c not in schema.names]
    if missing:
        raise FramesError(f"{where} is not a frames file: it lacks column(s) {', '.join(missing)}")
    check_column_types(schema, FRAMES_SCHEMA, where, FramesError)
    check_column_types(schema, OPTIONAL_SCHEMA, where, FramesError)  # a speed stored as text, ...
    check_value_sizes(meta, STRING_COLUMNS, MAX_VALUE_BYTES, where, FramesError)
    return schema


def read_frame_rows(url: str, path: str, start: int, stop: int, columns: tuple[str, ...]) -> pa.Table:
    """Rows [start, stop) of one frames file as a worker of `r2s run` reads them (storage.parquet.read_rows), through
    the checks of every reader of frames: the footer of the file as opened now (check_footer: the file may have
    been replaced since the run checked it, and a replaced file is opened afresh), then every value as decoded
    (UTF-8, dictionary indices). A FramesError names the file."""
    check_footer(open_file(url, path).metadata, path)
    try:
        rows = read_rows(url, path, start, stop, columns)
    except (pa.ArrowException, OSError) as exc:
        raise FramesError(f"{path} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:120]})") from None
    return _valid(rows, path)


def _valid(table: pa.Table, where: str) -> pa.Table:
    """Rows as read are what their types say: pyarrow checks neither UTF-8 nor dictionary indices on reading, and
    a corrupt page that still decompresses would reach pandas (exit 1) or a program."""
    for name in table.column_names:  # column by column, to name it (a table's own message gives its position)
        try:
            table.column(name).validate(full=True)
        except pa.ArrowException as exc:
            raise CorruptValues(f"{where} holds corrupt values in column {name} ({str(exc)[:160]})") from None
    return table


@dataclass(frozen=True)
class FrameRuns:
    """Consecutive frames of one part: frame i has rows starts[i] .. starts[i] + lengths[i] of the part."""

    part: int
    starts: np.ndarray  # int64
    lengths: np.ndarray  # int64
    ids: np.ndarray  # object (str)


# ------------------------------------------------------------------------------------------------ runs of frames

def _dictionary(column: pa.ChunkedArray | pa.Array) -> pa.DictionaryArray:
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    if not pa.types.is_dictionary(arr.type):
        return pc.dictionary_encode(arr)
    try:  # as read from a file: pyarrow does not check that each index is within the dictionary
        arr.validate(full=True)
    except pa.ArrowException as exc:
        raise FramesError(f"a dictionary-encoded column is corrupt ({str(exc)[:100]})") from None
    return arr


def _run_starts(ids: pa.DictionaryArray) -> tuple[np.ndarray, np.ndarray]:
    """First row of each run of equal frame ids, and the id of each run."""
    if ids.null_count:
        raise FramesError("column frame_id has a missing value")
    idx = ids.indices.to_numpy()
    if len(idx) == 0:
        return np.zeros(0, np.int64), np.zeros(0, object)
    starts = np.concatenate(([0], np.flatnonzero(idx[1:] != idx[:-1]) + 1)).astype(np.int64)
    return starts, ids.dictionary.take(pa.array(idx[starts])).to_numpy(zero_copy_only=False)


class _Stitch:
    """Joins a frame that continues from one row group into the next: the last run of a row group is held
    back until the next one shows whether it goes on."""

    def __init__(self) -> None:
        self.open: tuple[int, str] | None = None  # (start row, id) of the held-back run

    def add(self, starts: np.ndarray, ids: np.ndarray, n_rows: int):
        if len(starts) == 0:
            return None
        if self.open is not None and ids[0] == self.open[1]:
            starts = starts.copy()
            starts[0] = self.open[0]
        elif self.open is not None:
            starts = np.concatenate(([self.open[0]], starts))
            ids = np.concatenate((np.array([self.open[1]], dtype=object), ids))
        self.open = (int(starts[-1]), ids[-1])
        if len(starts) == 1:
            return None
        return starts[:-1], np.diff(starts), ids[:-1]

    def finish(self, n_rows: int):
        if self.open is None:
            return None
        start, fid = self.open
        self.open = None
        return np.array([start], np.int64), np.array([n_rows - start], np.int64), np.array([fid], dtype=object)


# ------------------------------------------------------------------------------------------------------ checking

def _used(codes: np.ndarray, size: int) -> np.ndarray:
    """The dictionary codes that occur (a dictionary may hold values no row uses)."""
    return np.flatnonzero(np.bincount(codes, minlength=size)) if len(codes) else np.zeros(0, np.int64)


class FramesCheck:
    """validate_frames for a stream of tables (row groups) whose frames are contiguous: the same rules and the
    same messages, in bounded memory. Frame ids go into a FrameIndex so that a frame occurring twice is found."""

    def __init__(self) -> None:
        self.frames = 0
        self._hashes: list[tuple[np.ndarray, np.ndarray]] = []
        self._open: tuple[str, int, set[str]] | None = None  # frame continuing into the next table
        self._good_ids: set[str] = set()
        self.ego_problem: str | None = None
        self.largest = 0  # rows of the largest frame so far

    def feed(self, table: pa.Table) -> None:
        n = table.num_rows
        if n == 0:
            return
        fid = _dictionary(table.column("frame_id"))
        starts, ids = _run_starts(fid)
        for k, name in enumerate(ids):  # printed into programs' file names and reports: printable, 1 to 256
            try:
                check_frame_id(name)
            except SceneError as exc:
                raise FramesError(f"{exc} (row {int(starts[k])} of its row group)") from None
        lengths = np.diff(np.append(starts, n))

        def frame_at(row: int) -> str:
            return str(ids[np.searchsorted(starts, row, side="right") - 1])

        for c in ("x", "y", "heading"):
            values = table.column(c).to_numpy()
            bad = ~np.isfinite(values.astype(float, copy=False))
            if bad.any():
                raise FramesError(f"column {c} has a missing or non-finite value (frame {frame_at(int(np.argmax(bad)))})")
        types = _dictionary(table.column("type"))
        codes = types.indices.drop_null().to_numpy()
        used = set(types.dictionary.take(pa.array(_used(codes, len(types.dictionary)))).to_pylist())
        unknown = sorted(used - set(ENTITY_TYPES)) + (["None"] if types.null_count else [])
        if unknown:
            raise FramesError(f"unknown entity type(s) {', '.join(map(repr, unknown[:5]))}")

        ego = pc.fill_null(table.column("is_ego"), False).to_numpy().astype(bool)
        egos = np.add.reduceat(ego.astype(np.int64), starts)
        continues = self._open is not None and ids[0] == self._open[0]
        if continues:
            egos[0] += self._open[1]
        elif self._open is not None:
            self._close()
        closed = egos[:-1]
        if (closed != 1).any():
            self._no_ego(ids[int(np.argmax(closed != 1))])

        entities = _dictionary(table.column("entity_id"))
        if entities.null_count:
            raise FramesError(f"entity id missing (frame {frame_at(int(np.argmax(np.asarray(entities.is_null()))))})")
        ent = entities.indices.to_numpy()
        names = entities.dictionary.to_pylist()
        for k in _used(ent, len(names)):
            name = names[k]
            if name not in self._good_ids:
                try:
                    check_identifier(name, "entity id")
                except SceneError as exc:
                    raise FramesError(f"{exc} (frame {frame_at(int(np.argmax(ent == k)))})") from None
                self._good_ids.add(name)
        ego_code = names.index(EGO_ID) if EGO_ID in names else -1
        mismatch = (ent == ego_code) != ego
        if mismatch.any():
            raise FramesError(f"frame {frame_at(int(np.argmax(mismatch)))!r}: the id 'ego' belongs to the ego row only")
        self._check_unique_entities(ent, names, starts, lengths, ids, continues)

        first_new = 1 if continues else 0
        sizes = lengths.copy()
        if continues:  # the open frame's rows so far: its entity ids, each once (checked above)
            sizes[0] += len(self._open[2])
        self.largest = max(self.largest, int(sizes.max()))
        if continues:
            self._open[2].update(names[k] for k in ent[: lengths[0]])
        self._hashes.append(frame_hashes(ids[first_new:]))
        self.frames += len(ids) - first_new
        last = len(starts) - 1
        if last > 0 or not continues:
            self._open = (str(ids[-1]), int(egos[-1]), {names[k] for k in ent[starts[-1]:]})
        else:
            self._open = (self._open[0], int(egos[-1]), self._open[2])

    def _check_unique_entities(self, ent, names, starts, lengths, ids, continues) -> None:
        run = np.repeat(np.arange(len(starts), dtype=np.int64), lengths)
        width = len(names) + 1
        key = run * width + ent
        if len(starts) * width <= 4 * len(ent) + 10**6:
            counts = np.bincount(key, minlength=len(starts) * width)
            twice = np.flatnonzero(counts > 1)
            dup = int(twice[0]) if len(twice) else None
        else:
            sk = np.sort(key)
            same = np.flatnonzero(sk[1:] == sk[:-1])
            dup = int(sk[same[0]]) if len(same) else None
        if dup is not None:
            raise FramesError(f"frame {ids[dup // width]!r} has entity id {names[dup % width]!r} twice")
        if continues:
            seen = self._open[2]
            for k in ent[: lengths[0]]:
                if names[k] in seen:
                    raise FramesError(f"frame {ids[0]!r} has entity id {names[k]!r} twice")

    def _close(self) -> None:
        fid, egos, _ = self._open
        self._open = None
        if egos != 1:
            self._no_ego(fid)

    def _no_ego(self, fid: str) -> None:
        # Said at the end: a frame whose rows are in two places has an ego in one half only, and "two places"
        # is the message that tells what is wrong.
        if self.ego_problem is None:
            self.ego_problem = f"frame {fid!r} does not have exactly one ego row"

    def end_part(self) -> None:
        """A frame never continues into another file (it would be a frame id in two places)."""
        if self._open is not None:
            self._close()

    def index(self) -> FrameIndex:
        self.end_part()
        return FrameIndex.of(self._hashes)


def check_table(table: pa.Table) -> None:
    """validate_frames for one in-memory table (a writer's batch of whole frames)."""
    checker = FramesCheck()
    checker.feed(table)
    hi, lo = checker.index().duplicated()
    if len(hi):
        dup = FrameIndex(hi[:1], lo[:1])
        ids = _run_starts(_dictionary(table.column("frame_id")))[1]
        fid = next(i for i in ids if dup.contains(*frame_hashes([i]))[0])
        raise FramesError(f"frame {fid!r} occurs in two places: a frame's rows must be contiguous")
    if checker.ego_problem:
        raise FramesError(checker.ego_problem)

