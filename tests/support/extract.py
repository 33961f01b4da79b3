"""Helpers of the extractor tests: the r2s command run in this process (the heavy dataset readers are imported
once per session instead of once per subprocess), with the same one-line-error check as conftest's."""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from pipeline.cli import main

EXCERPT = Path(__file__).resolve().parents[2] / "data" / "nuscenes-mini-excerpt"


@dataclass
class Result:
    returncode: int
    stdout: str
    stderr: str


def r2s(capsys, *args: str) -> Result:
    capsys.readouterr()
    code = main(list(args))
    out, err = capsys.readouterr()
    return Result(code, out, err)


def frames_of(extract, path, **options) -> pd.DataFrame:
    """All rows a source module's extract yields, as one table; options are that source's (Source.options)."""
    options = importlib.import_module(extract.__module__).SOURCE.options(**options)
    return pd.DataFrame([r for frame in extract(str(path), options) for r in frame])


def assert_refused(result: Result, out: Path, contains: str) -> None:
    """Exit 2, one line naming the problem, no traceback, and no output file (nor a temporary one)."""
    assert result.returncode == 2, (result.returncode, result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert contains.lower() in lines[0].lower(), lines[0]
    assert not out.exists()
    assert not out.parent.exists() or not any(out.parent.iterdir())
