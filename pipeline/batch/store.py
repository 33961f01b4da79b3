"""Where `r2s run` keeps its rows: part files, each written atomically as soon as it is full (ScenarioNet's
temp-file-then-rename discipline), never all rows in memory.

Two layouts, chosen by --out:
- a dataset directory (any --out not ending in .parquet): `<out>/part-000000.parquet`, ... The directory is the
  result, readable as one table by pandas, pyarrow.dataset, DuckDB and polars while the run goes on, and after.
- one file (--out ending in .parquet, as before): parts go to `<out>.parts/`, and at the end they are merged
  into `<out>` by streaming row batches (bounded memory), after the rows of an earlier `<out>`.

A kill at any moment leaves only whole files. On start, the rows already there are read a few short columns at
a time (frame_id, config_hash, version, frame_hash: column projection), hashed (storage.frame_index), and sorted
out: the last row of a frame wins (output file, then parts in order); rows of frames not in the input, written by
another version or synthesis revision (version, synth.version.ROWS_VERSION), computed from other rows of the frame
or another road (frame_hash, frames.frame_hash) or with another config are dropped (their files rewritten
without them, atomically), and the frames left are done. So a resumed run computes each frame once, reuses a
program only for the same rows, road, code and config, and the output holds every frame of the input exactly once
when the run ends.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

from frames.frame_hash import frame_keys, from_hex
from pipeline.batch.lock import OutputLock
from pipeline.errors import UserError
from pipeline.outputs import output_place
from pipeline.programs import (
    LATER_COLUMNS,
    PROGRAMS_SCHEMA,
    UNIT_COLUMNS,
    ProgramsError,
    as_programs,
    check_programs_schema,
    check_programs_values,
)
from storage.atomic import atomic_path, temp_prefix
from storage.frame_index import FrameIndex, frame_hashes

PART_PREFIX, PART_SUFFIX = "part-", ".parquet"
TMP_PREFIX = ".part-"
# Rows per row group in a merged single file: a programs row carries ~10 KB of text, so readers that go one
# row group at a time (the report, the merge itself) stay within a few tens of MB.
MERGE_BATCH_ROWS = 2048


@dataclass(frozen=True)
class ResumePlan:
    done: FrameIndex  # frames whose row is kept (computed earlier from the same rows with this config)
    stale: int  # frames whose row had another config hash: recomputed, row dropped
    stale_example: str | None
    outdated: int  # frames whose row another version or synthesis revision wrote: recomputed, row dropped
    outdated_example: str | None
    outdated_version: str | None  # the version that row records
    changed: int  # frames whose rows changed since their row was computed: recomputed, row dropped
    changed_example: str | None
    unhashed: int  # frames whose row has no frame_hash (an older writer): recomputed, row dropped
    foreign: int  # rows of frames that are not in the input: dropped
    superseded: int  # older rows of a frame that has a later one (a kill during the merge): dropped
    drops: dict[Path, np.ndarray] = field(default_factory=dict)  # rows (indices) to drop, per file
    warnings: tuple[str, ...] = ()


def is_single_file(out: str | os.PathLike) -> bool:
    out = Path(out)
    return out.suffix == ".parquet" and not out.is_dir()


class RunStore:
    def __init__(self, out: str | os.PathLike, schema: pa.Schema = PROGRAMS_SCHEMA) -> None:
        self.out = Path(out)
        self.schema = schema  # the rows' (PROGRAMS_SCHEMA, or WINDOW_SCHEMA for r2s run --window)
        self.single_file = is_single_file(out)
        # a link given as a dataset --out is written through (pipeline.outputs.output_place), even one that
        # points to a folder not made yet
        self.parts = Path(f"{self.out}.parts") if self.single_file else output_place(self.out)
        self._next = 0
        self.rows_written = 0  # rows of the parts this store wrote: what a stopped run says it saved
        self._lock = None
        self._unreadable: list[Path] = []

    def describe(self) -> str:
        return str(self.out) if not self.single_file else f"{self.out} (parts in {self.parts})"

    def check_writable(self) -> None:
        """Refuse, before anything is written, an output that a run must not overwrite or cannot create."""
        if self.single_file:
            if self.parts.exists() and not self.parts.is_dir():
                raise UserError(f"{self.parts} exists and is not a directory (it holds the parts of a run)")
        elif self.out.exists():
            if not self.out.is_dir():
                raise UserError(f"--out {self.out} is a file; a dataset output is a directory "
                                "(name a .parquet file for one file)")
            foreign = sorted(p.name for p in self.out.iterdir() if not _ours(p.name))
            if foreign:
                raise UserError(f"--out {self.out} holds files that are not parts of a run "
                                f"({', '.join(foreign[:3])}); choose an empty or new directory")
        # Where files will be created, tried for real before any frame is computed (os.access says yes to root
        # on a read-only mount): the output's directory (lock, merge) and the directory of the parts.
        for where in dict.fromkeys((_existing(self.out.parent), _existing(self.parts))):
            _probe(where)

    def lock(self) -> None:
        """Hold `<out>`'s lock (pipeline.batch.lock: a file beside the output, locked by the kernel) until
        `unlock()` or the end of the process, or refuse: two runs on one output would overwrite each other's parts
        and merge under each other."""
        self._lock = OutputLock(self.out)
        self._lock.acquire()

    def unlock(self) -> None:
        if self._lock is not None:
            self._lock.release()
            self._lock = None

    def part_files(self) -> list[Path]:
        if not self.parts.is_dir():
            return []
        parts = [p for p in self.parts.iterdir() if p.name.startswith(PART_PREFIX) and p.suffix == PART_SUFFIX]
        return sorted(parts, key=lambda p: (_part_number(p), p.name))

    def sources(self) -> list[Path]:
        """Files holding rows, oldest first: the single output file (if any), then the parts in order."""
        head = [self.out] if self.single_file and self.out.is_file() else []
        return head + self.part_files()

    # ------------------------------------------------------------------------------------------------ resume

    def plan(self, frames: FrameIndex, contents: FrameIndex, config_hash: str, version: str) -> ResumePlan:
        """What the rows already written mean for this run (see the module docstring). `frames`: the input's
        frame ids; `contents`: its frames with what they are computed from (frames.frame_hash.FrameHasher.keys);
        `version`: what this run's rows record (synth.version.ROWS_VERSION)."""
        his, los, src, rows, same, current, fresh, hashed = [], [], [], [], [], [], [], []
        warnings = []
        sources = self.sources()
        for s, path in enumerate(sources):
            try:
                table = _read_keys(path)
                names = pq.read_schema(path).names
                missing = [n for n in self.schema.names if n not in names and n not in LATER_COLUMNS]
                if missing:  # rows of the other kind (per frame, per window, per clip) are never mixed in one output
                    kind = next((UNIT_COLUMNS[n] for n in UNIT_COLUMNS if n in names), "per-frame")
                    raise ProgramsError(f"{path} holds rows without column(s) {', '.join(missing)}: {kind} programs")
            except ProgramsError as exc:
                # Never overwrite or delete a file we may not have written: an unreadable output file, or a part
                # of a dataset directory, refuses the run. Parts beside a single file are ours alone (they
                # were renamed into place whole, so the damage came from outside): recompute their frames.
                if not self.single_file or path == self.out:
                    raise UserError(f"--out {exc}; remove it or choose another --out") from None
                warnings.append(f"ignoring unreadable part {path.name} ({exc}); its frames are recomputed")
                self._unreadable.append(path)
                continue
            hi, lo = frame_hashes(table.column("frame_id").to_numpy(zero_copy_only=False))
            his.append(hi)
            los.append(lo)
            src.append(np.full(len(hi), s, np.int32))
            rows.append(np.arange(len(hi), dtype=np.int64))
            same.append(np.asarray(pc.equal(table.column("config_hash"), config_hash).to_numpy(zero_copy_only=False)))
            current.append(np.asarray(pc.fill_null(pc.equal(table.column("version"), version), False).to_numpy(
                zero_copy_only=False), dtype=bool))
            lane0, lane1, valid = from_hex(table.column("frame_hash"))
            kh, kl = frame_keys(hi, lo, lane0, lane1)
            fresh.append(valid & contents.contains(kh, kl))
            hashed.append(valid)
        for p in self.part_files():
            self._next = max(self._next, _part_number(p) + 1)
        if not his:
            return ResumePlan(FrameIndex.of([]), 0, None, 0, None, None, 0, None, 0, 0, 0, {}, tuple(warnings))
        hi, lo, src, rows, same, current, fresh, hashed = (np.concatenate(a) for a in (his, los, src, rows, same,
                                                                                         current, fresh, hashed))
        del his, los
        order = np.lexsort((rows, src, lo, hi))  # by frame, then oldest first
        h, lw = hi[order], lo[order]
        last = np.ones(len(order), dtype=bool)
        last[:-1] = (h[1:] != h[:-1]) | (lw[1:] != lw[:-1])
        in_input = frames.contains(h, lw)
        ok, current, fresh, hashed = same[order], current[order], fresh[order], hashed[order]
        # Why a frame of the input is recomputed, one reason each, in this order: what it was computed from is
        # unknown (no frame hash), or by another version (whose hash may cover other things), or its rows changed,
        # or the configuration did.
        keep = last & in_input & current & fresh & ok
        unhashed = last & in_input & ~hashed
        outdated = last & in_input & hashed & ~current
        changed = last & in_input & hashed & current & ~fresh
        stale = last & in_input & current & fresh & ~ok
        foreign = last & ~in_input
        drop = order[~keep]
        drops = {}
        for s in np.unique(src[drop]):
            drops[sources[s]] = np.sort(rows[drop][src[drop] == s])

        def example(mask: np.ndarray, column: str = "frame_id") -> str | None:
            if not mask.any():
                return None
            first = order[int(np.argmax(mask))]
            return str(_read_keys(sources[src[first]]).column(column)[int(rows[first])].as_py())

        return ResumePlan(FrameIndex(h[keep], lw[keep]), int(stale.sum()), example(stale), int(outdated.sum()),
                          example(outdated), example(outdated, "version"), int(changed.sum()), example(changed),
                          int(unhashed.sum()), int(foreign.sum()), int((~last).sum()), drops, tuple(warnings))

    def apply(self, plan: ResumePlan) -> None:
        """Rewrite the files that hold dropped rows without them (each atomically; an emptied part goes)."""
        for path in self._unreadable:
            path.unlink(missing_ok=True)
        for path, drop in plan.drops.items():
            keep = np.ones(pq.ParquetFile(path).metadata.num_rows, dtype=bool)
            keep[drop] = False
            if not keep.any() and path != self.out:
                path.unlink()
                continue
            with _writing(path), atomic_path(path) as tmp:
                _copy_rows(path, tmp, keep, self.schema)

    def remove_temporaries(self) -> None:
        """Temporary files of a killed run: only our own names, inside the parts directory."""
        if self.parts.is_dir():
            for p in self.parts.iterdir():
                if p.name.startswith((TMP_PREFIX, f".{self.out.name}.")) and p.name.endswith(".tmp"):
                    p.unlink(missing_ok=True)

    # ------------------------------------------------------------------------------------------------ writing

    def write_part(self, table: pa.Table) -> Path:
        with _writing(self.parts):
            self.parts.mkdir(parents=True, exist_ok=True)
        path = self.parts / f"{PART_PREFIX}{self._next:06d}{PART_SUFFIX}"
        self._next += 1
        with _writing(path), atomic_path(path) as tmp:  # .part-NNNNNN.parquet.*.tmp: hidden from dataset readers
            pq.write_table(table, tmp, compression="zstd")
        self.rows_written += table.num_rows
        return path

    def finish(self) -> None:
        """One file: the earlier output and the parts, merged into `<out>` (atomically), then the parts go. A kill
        in between leaves parts whose rows are also in the output; the next start drops the older copies."""
        if not self.single_file:
            return
        sources = self.sources()
        if sources == [self.out]:
            return
        with _writing(self.out), atomic_path(self.out) as tmp:
            with pq.ParquetWriter(tmp, self.schema, compression="zstd") as writer:
                for path in sources:
                    for batch in _batches(path, self.schema):
                        writer.write_batch(batch, row_group_size=MERGE_BATCH_ROWS)
        if self.parts.is_dir():
            shutil.rmtree(self.parts)

    def status_counts(self) -> Counter:
        counts: Counter = Counter()
        for path in self.sources():
            status = pq.read_table(path, columns=["status"]).column("status")
            counts.update(dict(zip(*np.unique(status.to_numpy(zero_copy_only=False).astype(str),
                                              return_counts=True))))
        return Counter({k: int(v) for k, v in counts.items()})


def _existing(path: Path) -> Path:
    """The directory itself if it exists, else its nearest existing ancestor (where mkdir will create it)."""
    path = path.absolute()
    while not path.is_dir() and path != path.parent:
        path = path.parent
    return path


def _probe(directory: Path) -> None:
    """Create and remove a file in `directory`, or refuse with the system's reason (read-only, no permission)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=temp_prefix(directory / "probe"), suffix=".tmp", dir=directory)
        os.close(fd)
        os.unlink(tmp)
    except OSError as exc:
        raise UserError(f"cannot write in {directory}: {exc.strerror or exc}") from None


@contextmanager
def _writing(path: Path) -> Iterator[None]:
    """An output that cannot be written (a full disk, a read-only or vanished directory) is bad input, one line:
    the atomic write has removed its temporary, and the files already there are whole."""
    try:
        yield
    except OSError as exc:
        raise UserError(f"cannot write {path}: {exc.strerror or exc}") from None


def _ours(name: str) -> bool:
    return (name.startswith(PART_PREFIX) and name.endswith(PART_SUFFIX)) or (
        name.startswith(TMP_PREFIX) and name.endswith(".tmp"))


def _read_keys(path: Path) -> pa.Table:
    """frame_id, config_hash, version and frame_hash of a programs file, and status to check it: a resume reads five
    short columns (column projection), never the programs' text. A file written before frame_hash gets nulls."""
    try:
        pf = pq.ParquetFile(path, read_dictionary=["status", "config_hash", "version"])
        check_programs_schema(pf.schema_arrow, str(path))
        keys = ["frame_id", "config_hash", "version", "status", "frame_hash"]
        table = pf.read(columns=[c for c in keys if c in pf.schema_arrow.names])
        if "frame_hash" not in table.column_names:
            table = table.append_column("frame_hash", pa.nulls(table.num_rows, pa.string()))
    except ProgramsError:
        raise
    except (pa.ArrowException, OSError, ValueError) as exc:
        raise ProgramsError(f"{path} is not a readable Parquet file ({type(exc).__name__}: {str(exc)[:120]})") from None
    check_programs_values(table, str(path))
    return table


def _batches(path: Path, schema: pa.Schema):
    pf = pq.ParquetFile(path)
    names = [c for c in schema.names if c in pf.schema_arrow.names]
    for batch in pf.iter_batches(batch_size=MERGE_BATCH_ROWS, columns=names):
        yield as_programs(batch, schema)


def _copy_rows(source: Path, target: Path, keep: np.ndarray, schema: pa.Schema) -> None:
    with pq.ParquetWriter(target, schema, compression="zstd") as writer:
        offset = 0
        for batch in _batches(source, schema):
            mask = keep[offset: offset + batch.num_rows]
            offset += batch.num_rows
            if mask.any():
                writer.write_batch(batch.filter(pa.array(mask)), row_group_size=MERGE_BATCH_ROWS)


def _part_number(path: Path) -> int:
    try:
        return int(path.name[len(PART_PREFIX): -len(PART_SUFFIX)])
    except ValueError:
        return -1
