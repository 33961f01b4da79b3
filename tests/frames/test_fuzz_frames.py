"""Fuzzing the frames Parquet reader (issue 22): a real frames file, extracted from the shipped excerpt, with its
bytes mutated (flips, insertions, deletions, duplicated spans, truncation). Every input must read as frames or
raise FramesError: never another exception, never a crash.

As for the pickles (test_fuzz_pickle.py), the examples run in a child process capped in address space, with an
alarm per example, derandomized and bounded so that CI runs the same few seconds every time."""

from __future__ import annotations

import collections
import resource
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

from hypothesis import HealthCheck, example, given, settings

from tests.support import ROOT
from tests.support.extract import EXCERPT
from tests.support.mutate import EDITS, mutated

HEADROOM = 2**30
ALARM_S = 20


def test_the_frames_reader_fuzz_finds_nothing_in_a_child_process():
    proc = subprocess.run([sys.executable, "-c", "from tests.frames.test_fuzz_frames import main; main()"],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-3000:], proc.stderr[-3000:])
    assert "fuzzed frames" in proc.stdout


def _on_alarm(signum, frame):
    raise TimeoutError(f"an example ran more than {ALARM_S} s")


def main() -> None:
    from frames.rows import FramesError, read_frames
    from pipeline.cli import main as r2s

    with open("/proc/self/statm") as fh:
        vm = int(fh.read().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (vm + HEADROOM, resource.getrlimit(resource.RLIMIT_AS)[1]))
    work = Path(tempfile.mkdtemp())
    seed = work / "frames.parquet"
    assert r2s(["extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(seed)]) == 0
    original = seed.read_bytes()
    counts = collections.Counter()

    @settings(derandomize=True, max_examples=150, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(EDITS)
    @example([("flip", 0.1875, 0.0, b"\x01")])  # a page of a row group cut short (pyarrow raised OSError past it)
    def run(edits):
        data = mutated(original, edits, max_span=256)
        path = work / "fuzz.parquet"
        path.write_bytes(bytes(data))
        signal.signal(signal.SIGALRM, _on_alarm)
        signal.alarm(ALARM_S)
        try:
            read_frames(path)
            counts["read"] += 1
        except FramesError as exc:
            # one line is the CLI's rule, not checked here: pyarrow's own messages span lines (issue 22 item 13)
            counts["refused on more than one line" if "\n" in str(exc) else "refused"] += 1
        finally:
            signal.alarm(0)
    run()
    print("fuzzed frames", dict(counts))
