"""`r2s report --query PATTERN --frames FRAMES`: the section's count, top frames, programs and render commands,
checked against the brute force (tests/support/query_bruteforce.py) and the programs file, read as plain Markdown."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from frames.rows import scene_to_rows, write_frames
from pipeline.programs import programs_table, result_row
from pipeline.report.document import md_html_text
from synth.config import SynthConfig
from synth.patterns.one_frame import parse_pattern
from synth.synthesize import synthesize
from tests.support import assert_one_line_error, run_r2s
from tests.support.query_bruteforce import brute_matches

TOP = 3
# Two vehicles one behind the other, heading the same way: 14 of the 18 shipped frames, 0 to 7 bindings each.
FOLLOWING = ("a = new Vehicle on Range(-50, 50) @ Range(-50, 50), facing Range(0, 360) deg\n"
             "b = new Vehicle ahead of a by Range(1, 15), facing Range(-30, 30) deg relative to a\n")


@pytest.fixture(scope="module")
def inputs(real_frames, tmp_path_factory) -> tuple[Path, Path]:
    d = tmp_path_factory.mktemp("report-query")
    frames = d / "frames.parquet"
    write_frames([r for s in real_frames for r in scene_to_rows(s, source="test")], frames)
    config = SynthConfig()
    programs = d / "programs.parquet"
    pq.write_table(programs_table([result_row(synthesize(s, config)) for s in real_frames]),
                   programs)
    return frames, programs


@pytest.fixture(scope="module")
def pattern_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("pattern") / "following.dsl"
    path.write_text(FOLLOWING)
    return path


@pytest.fixture(scope="module")
def section(inputs, pattern_file, tmp_path_factory) -> str:
    frames, programs = inputs
    out = tmp_path_factory.mktemp("report") / "report"
    proc = run_r2s("report", str(programs), "--out", str(out), "--frames", str(frames), "--query",
                   str(pattern_file), "--query-top", str(TOP))
    assert proc.returncode == 0, proc.stderr
    md = (out / "report.md").read_text()
    assert "Frames matching following.dsl" in (out / "report.html").read_text()
    return md.split("## Frames matching following.dsl\n", 1)[1].split("\n## ", 1)[0]


def test_count_and_top_frames_are_the_brute_force_s(section, real_frames, inputs):
    pattern = parse_pattern(FOLLOWING)
    found = [(s.frame_id, b) for s in real_frames if (b := brute_matches(pattern, s))]
    assert len(found) > TOP  # more matching frames than the section lists
    total = sum(len(b) for _, b in found)
    assert f"{len(found)} of {len(real_frames)} frames match, with {total} binding(s)" in section
    # Most bindings first, ties in input order (a stable sort of the input order).
    expected = sorted(found, key=lambda fb: -len(fb[1]))[:TOP]
    rows = table_rows(section.split(" event(s): ", 1)[0], "| Frame")
    assert [r[0] for r in rows] == [fid for fid, _ in expected]
    programs = {r["frame_id"]: r for r in pq.read_table(inputs[1]).to_pylist()}
    frames, programs_path = inputs
    for row, (fid, bindings) in zip(rows, expected):
        assert row[1] == str(len(bindings))
        assert row[2] == ", ".join(f"{n} = {e}" for n, e in zip(pattern.names, bindings[0]))
        assert row[3] == f"{programs[fid]['cost']} (auto)"
        command = row[4].replace("\\|", "|")
        assert command.startswith(f"r2s scene {frames} ") and f" --programs {programs_path} " in command
        # The frame's program, whole, in its folded block.
        summary = md_html_text(f"{fid} (auto, optimal, cost {programs[fid]['cost']})")
        block = section.split(f"<summary>{summary}</summary>", 1)[1]
        assert block.split("```\n", 1)[1].split("\n```", 1)[0] == programs[fid]["program"].rstrip("\n")


def table_rows(text: str, header: str) -> list[list[str]]:
    return [[c.strip() for c in ln.strip("|").split(" | ")] for ln in text.splitlines()
            if ln.startswith("| ") and not ln.startswith(header)]


def test_events_are_the_brute_force_s(section, inputs):
    from frames.rows import read_frames
    from tests.support.events_bruteforce import brute_events

    events = brute_events(read_frames(inputs[0]), parse_pattern(FOLLOWING))
    assert f"{len(events)} event(s): maximal runs of consecutive frames" in section
    longest = sorted(events, key=lambda e: -e["n_frames"])[:TOP]  # stable: ties in the events' order
    rows = table_rows(section.split(" event(s): ", 1)[1], "| Scene")
    assert len(rows) == len(longest) == TOP
    for row, e in zip(rows, longest):
        names = parse_pattern(FOLLOWING).names
        assert row == [e["scene"], ", ".join(f"{n} = {i} (track {t})" for n, i, t in zip(names, e["binding"], e["tracks"])),
                       e["first_frame"], e["last_frame"], "—" if e["duration_s"] is None else f"{e['duration_s']:g}",
                       str(e["n_frames"])]


def test_the_render_command_draws_the_frame(section, tmp_path):
    row = next(ln for ln in section.splitlines() if ln.startswith("| ") and not ln.startswith("| Frame"))
    command = row.strip("|").split(" | ")[4].strip().replace("\\|", "|")
    env = {**os.environ, "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    proc = subprocess.run(command, shell=True, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    png = next(tmp_path.glob("*.png"))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("extra,needle", [
    (["--query", "{pattern}"], "--query needs --frames"),
    (["--query", "missing.dsl", "--frames", "f"], "does not exist"),
    (["--query", "{pattern}", "--frames", "f", "--query-top", "0"], "--query-top must be at least 1"),
    (["--query", "{pattern}", "--frames", "missing.parquet"], "does not exist"),
])
def test_bad_query_options_exit_2_and_write_nothing(extra, needle, inputs, pattern_file, tmp_path):
    extra = [a.format(pattern=pattern_file) for a in extra]
    proc = run_r2s("report", str(inputs[1]), "--out", str(tmp_path / "r"), *extra)
    assert_one_line_error(proc, 2, needle)
    assert not (tmp_path / "r").exists()


def test_bad_pattern_is_refused_with_its_line_and_column(inputs, tmp_path):
    bad = tmp_path / "p.dsl"
    bad.write_text("a = new Car ahead of ego by Range(0, 5), facing toward ego\nb = new Car left of c by Range(0, 1), "
                   "facing toward a\n")
    proc = run_r2s("report", str(inputs[1]), "--out", str(tmp_path / "r"), "--frames", str(inputs[0]), "--query",
                   str(bad))
    assert_one_line_error(proc, 2, "line 2 column 21")
    assert not (tmp_path / "r").exists()
