"""What an extractor input looks like, so that a wrong `r2s extract SOURCE` gets a line naming the right one.

Every source says what its input looks like (Source.look_at_file, look_at_entry); this asks them all. Only
consulted when the asked-for source found nothing it could read (it never overrides a source that works). Cheap
on any input: a file is told by its first bytes; a folder by the names of at most MAX_ENTRIES entries,
up to MAX_DEPTH levels down (a ScenarioNet database or an Argoverse 2 split can hold 10^5 files).
"""

from __future__ import annotations

import os
from itertools import islice
from pathlib import Path

from extractors.base import Look
from extractors.registry import sources
from storage.regular_files import open_regular

MAX_ENTRIES = 2000
MAX_DEPTH = 4


def head(path: Path, n: int = 32) -> bytes:
    """The first n bytes of a file (b"" if it cannot be read)."""
    try:
        with open_regular(path) as fh:  # a FIFO among the entries must not block the hint
            return fh.read(n)
    except OSError:
        return b""


def _file_look(path: Path) -> Look | None:
    first = head(path)
    for source in sources():
        if look := source.look_at_file(path, first):
            return look
    return None


def _dir_look(top: str, entry: os.DirEntry, depth: int) -> Look | None:
    is_dir = entry.is_dir(follow_symlinks=False)
    for source in sources():
        if look := source.look_at_entry(top, Path(entry.path), is_dir, depth):
            return look
    return None


def looks_like(input_path: str) -> list[Look]:
    """The sources whose input this looks like, one Look each, nearest evidence first."""
    path = Path(input_path)
    if path.is_file():
        look = _file_look(path)
        return [look] if look else []
    if not path.is_dir():
        return []
    found: dict[str, Look] = {}
    level, seen = [path], 0
    for depth in range(MAX_DEPTH + 1):
        below = []
        for folder in level:
            try:
                with os.scandir(folder) as it:
                    entries = sorted(islice(it, MAX_ENTRIES - seen), key=lambda e: e.name)
            except OSError:
                continue
            for entry in entries:
                seen += 1
                look = _dir_look(input_path, entry, depth)
                if look and look.source not in found:
                    found[look.source] = look
                if entry.is_dir(follow_symlinks=False):
                    below.append(Path(entry.path))
            if seen >= MAX_ENTRIES:
                return list(found.values())
        level = below
    return list(found.values())


def wrong_source_hint(source: str, input_path: str) -> str | None:
    """One line saying what INPUT looks like and which source reads it, when it does not look like `source`."""
    looks = looks_like(input_path)
    if not looks or any(look.source == source for look in looks):
        return None
    what = " and ".join(look.what for look in looks)
    use = " or ".join(f"`r2s extract {look.source} {look.path}`" for look in looks)
    return f"{input_path} looks like {what}, not input of the {source} source: use {use}"
