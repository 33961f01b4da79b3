"""Where `r2s run` keeps its rows: part files in `<out>.parts/`, each written atomically as a chunk finishes,
consolidated into `<out>` atomically at the end (ScenarioNet's temp-file-then-rename discipline).

A kill at any moment leaves only whole files: the output of an earlier run, whole parts, and maybe a
temporary file that the next start removes. Reading them back oldest first (output, then parts in order)
and letting the last row of a frame win makes a resumed run exact, with never a duplicate row.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from extractors.atomic import atomic_path
from pipeline.errors import UserError
from pipeline.programs import ProgramsError, programs_table, read_programs_table
from pipeline.run import Row

PART_PREFIX, PART_SUFFIX = "part-", ".parquet"


class RunStore:
    def __init__(self, out: str | os.PathLike) -> None:
        self.out = Path(out)
        self.parts = Path(f"{self.out}.parts")
        self._next = 0
        self._lock_fd: int | None = None

    def check_writable(self) -> None:
        """Refuse, before anything is written, an output that a run must not overwrite or cannot create."""
        if self.out.is_dir():
            raise UserError(f"--out {self.out} is a directory, not a programs file")
        if self.parts.exists() and not self.parts.is_dir():
            raise UserError(f"{self.parts} exists and is not a directory (it holds the parts of a run)")
        parent = self.out.parent
        if parent.exists() and not os.access(parent, os.W_OK):
            raise UserError(f"cannot write in {parent}")

    def lock(self) -> None:
        """Hold `<out>`'s lock for the rest of this process, or refuse: two runs on one output would overwrite
        each other's parts and consolidate under each other. The lock is an flock on an empty file in the temp
        directory named by the output's resolved path (nothing appears beside the output, so refused input still
        writes nothing there); the kernel drops it when the process ends, however it ends: no stale lock."""
        import fcntl
        import hashlib
        import tempfile

        key = hashlib.sha256(str(self.out.resolve()).encode()).hexdigest()[:24]
        path = Path(tempfile.gettempdir()) / f"r2s-run-{key}.lock"
        fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            raise UserError(f"another r2s run on this machine is writing {self.out} (lock {path}); "
                            "wait for it or choose another --out") from None
        self._lock_fd = fd  # kept open: closing it would release the lock

    def existing_rows(self) -> tuple[list[Row], list[str]]:
        """Rows of an earlier run (output first, then parts in order) and warnings about unreadable parts."""
        rows: list[Row] = []
        if self.out.exists():
            try:
                rows.extend(_rows(self.out))
            except ProgramsError as exc:  # never overwrite a file we did not write
                raise UserError(f"--out {exc}; remove it or choose another --out") from None
        warnings = []
        for part in self.part_files():
            try:
                rows.extend(_rows(part))
            except ProgramsError as exc:  # parts are renamed whole, so this is outside damage: recompute
                warnings.append(f"ignoring unreadable part {part.name} ({exc}); its frames are recomputed")
            self._next = max(self._next, _part_number(part) + 1)
        return rows, warnings

    def part_files(self) -> list[Path]:
        if not self.parts.is_dir():
            return []
        return sorted(p for p in self.parts.iterdir() if p.name.startswith(PART_PREFIX) and p.suffix == PART_SUFFIX)

    def remove_temporaries(self) -> None:
        """Temporary files of a killed run: only inside the parts directory, which only `r2s run` writes."""
        if self.parts.is_dir():
            for p in self.parts.iterdir():
                if p.name.startswith(".") and p.name.endswith(".tmp"):
                    p.unlink(missing_ok=True)

    def write_part(self, rows: list[Row]) -> Path:
        self.parts.mkdir(parents=True, exist_ok=True)
        path = self.parts / f"{PART_PREFIX}{self._next:06d}{PART_SUFFIX}"
        self._next += 1
        _write(programs_table(rows), path)
        return path

    def consolidate(self, rows: list[Row]) -> None:
        """The final file first (atomically), then the parts: a kill in between leaves parts whose rows are
        also in the output, which the next start reads as the same rows."""
        _write(programs_table(rows), self.out)
        if self.parts.is_dir():
            shutil.rmtree(self.parts)


def _write(table: pa.Table, path: Path) -> None:
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def _rows(path: Path) -> list[Row]:
    # Arrow rows, not pandas: nullable integers come back as int or None, not NaN.
    return read_programs_table(path).to_pylist()


def _part_number(path: Path) -> int:
    try:
        return int(path.name[len(PART_PREFIX): -len(PART_SUFFIX)])
    except ValueError:
        return -1
