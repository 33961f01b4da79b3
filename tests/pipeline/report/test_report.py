"""`r2s report` as a user runs it, on programs synthesized in-process from the shipped real nuScenes frames.

Every number the tests compare is recomputed here from the DataFrame or the DSL text by other means (plain
pandas, regular expressions), not with the report's own functions.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from PIL import Image

from pipeline.programs import failure_row, programs_table, read_programs, result_row
from pipeline.report.plots import PLOT_FILES
from pipeline.report.stats import bucket_label
from synth.config import SynthConfig
from synth.synthesize import synthesize
from tests.support import assert_one_line_error, run_r2s

SIDE_BY_SIDE = "## Strategies side by side (Table 3 layout)"
ERROR_MESSAGE = "CertificationError: the solver refutes the statements of car3"


def _rows(frames, strategies: tuple[str, ...]) -> list[dict]:
    """auto on every frame; other strategies on frames up to 20 entities, the larger ones recorded as failures."""
    rows = []
    for strategy in strategies:
        config = SynthConfig(strategy=strategy)
        for scene in frames:
            n = len(scene.others)
            if strategy == "auto" or n <= 20:
                rows.append(result_row(synthesize(scene, config)))
            elif n <= 80:
                rows.append(failure_row(scene.frame_id, "timeout", "time limit 60 s", n, config, runtime_s=60.0,
                                        peak_rss_mb=512.0))
            else:
                rows.append(failure_row(scene.frame_id, "error", ERROR_MESSAGE, n, config))
    return rows


def _write(rows: list[dict], path: Path) -> Path:
    pq.write_table(programs_table(rows), path)
    return path


@pytest.fixture(scope="module")
def two_strategies(real_frames, tmp_path_factory) -> Path:
    return _write(_rows(real_frames, ("auto", "astar-cpa")), tmp_path_factory.mktemp("programs") / "programs.parquet")


@pytest.fixture(scope="module")
def report(two_strategies, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("reports") / "report"
    proc = run_r2s("report", str(two_strategies), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    (out.parent / "stdout.txt").write_text(proc.stdout)
    return out


def test_report_ends_with_one_summary_line(two_strategies, report):
    """Like every verb, one line: frames, configs, and per config its optimal share and median runtime (recomputed
    here with pandas), then where the report is."""
    import pandas as pd

    lines = (report.parent / "stdout.txt").read_text().splitlines()
    assert len(lines) == 1 and lines[0].startswith("r2s report: ") and lines[0].endswith(f" -> {report / 'report.html'}")
    df = pd.read_parquet(two_strategies)
    assert f" {df.frame_id.nunique()} frames; 2 configs; " in lines[0]
    for strategy, group in df.groupby("strategy"):
        optimal = 100.0 * (group.status == "optimal").mean()
        median = 1000 * group[group.status != "error"].runtime_s.median()
        assert f"{strategy}: {optimal:.1f}% optimal, median {median:.1f} ms" in lines[0], (strategy, lines[0])


def _table(md: str, heading: str) -> list[list[str]]:
    """The first Markdown table under a heading, header row included, as lists of cells."""
    section = md.split(f"## {heading}\n", 1)[1]
    lines = [ln for ln in section.split("\n## ", 1)[0].splitlines() if ln.startswith("|")]
    return [[c.strip() for c in ln.strip("|").split(" | ")] for ln in lines if not ln.startswith("|:")]


def _by_name(table: list[list[str]]) -> dict[str, dict[str, str]]:
    header, *rows = table
    return {r[0]: dict(zip(header, r)) for r in rows}


def test_strategy_numbers_match_an_independent_count(report, two_strategies):
    df = read_programs(two_strategies)
    md = (report / "report.md").read_text()
    table = _by_name(_table(md, "By strategy"))
    assert set(table) == {"auto", "astar-cpa"}
    for strategy, rows in df.groupby("strategy"):
        line = table[strategy]
        assert line["Frames"] == str(len(rows))
        assert line["Optimal %"] == f"{100 * (rows['status'] == 'optimal').mean():.1f}%"
        for status in ("optimal", "feasible", "timeout", "memout", "error"):
            assert line[status] == str((rows["status"] == status).sum()), status
        costs = rows["cost"].dropna()
        assert line["Mean cost"] == f"{costs.mean():.2f}"
        assert line["SMT queries"] == str(int(rows["smt_queries"].fillna(0).sum()))
    assert table["astar-cpa"]["timeout"] == "1" and table["astar-cpa"]["error"] == "1"


def test_bucket_lines_cover_every_frame(report, two_strategies):
    df = read_programs(two_strategies)
    header, *rows = _table((report / "report.md").read_text(), "By entity count")
    frames = {(r[0], r[1]): int(r[header.index("Frames")]) for r in rows}
    expected = df.assign(b=df["n_entities"].map(bucket_label)).groupby(["b", "strategy"]).size()
    assert frames == {k: int(v) for k, v in expected.items()}
    # Ascending N, not text order ("11-20" sorts before "6-10" as text).
    order = list(dict.fromkeys(r[0] for r in rows))
    assert order == sorted(order, key=lambda b: int(re.match(r"\d+", b).group()))


def test_bucket_edges():
    assert [bucket_label(n) for n in (0, 1, 5, 6, 10, 11, 20, 21, 40, 41, 80, 81, 500)] == [
        "0", "1-5", "1-5", "6-10", "6-10", "11-20", "11-20", "21-40", "21-40", "41-80", "41-80", "81+", "81+"]


# One DSL statement: id = new Type POSITION, HEADING (numbers may carry a sign and decimals).
_RANGE = r"Range\([-+\d.e]+, [-+\d.e]+\)"
_STATEMENT = re.compile(
    rf"^\w+ = new \w+ (?:(?P<dir>ahead of|behind|left of|right of) \w+ by {_RANGE}"
    rf"|on {_RANGE} @ {_RANGE}(?P<relpos> relative to \w+)?), "
    rf"facing (?:(?P<facing>toward|away from) \w+|{_RANGE} deg(?P<relhead> relative to \w+)?)$")


def _regex_counts(programs) -> dict[str, int]:
    counts = dict.fromkeys(("ahead", "behind", "left", "right", "relative position", "absolute position",
                            "toward", "away", "relative heading", "absolute heading"), 0)
    for text in programs:
        for line in text.splitlines():
            m = _STATEMENT.match(line)
            assert m, line
            counts[m["dir"].split()[0] if m["dir"] else ("relative position" if m["relpos"] else "absolute position")] += 1
            counts[m["facing"].split()[0] if m["facing"] else ("relative heading" if m["relhead"] else "absolute heading")] += 1
    return counts


def test_relation_counts_match_the_dsl_text(report, two_strategies):
    df = read_programs(two_strategies)
    table = _by_name(_table((report / "report.md").read_text(), "Relation usage"))
    total = dict.fromkeys(table, 0)
    for strategy, rows in df.groupby("strategy"):
        counts = _regex_counts(rows["program"].dropna())
        assert sum(counts.values()) == 2 * int(rows.loc[rows["program"].notna(), "n_entities"].sum())
        for kind, k in counts.items():
            assert table[kind][strategy] == str(k), (strategy, kind)
            total[kind] += k
    assert {kind: int(line["Total"]) for kind, line in table.items()} == total
    assert total["ahead"] + total["behind"] + total["left"] + total["right"] > 0  # real frames use relations


def test_every_plot_is_a_real_png(report):
    md = (report / "report.md").read_text()
    for name in PLOT_FILES:
        path = report / name
        assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name
        assert path.stat().st_size > 15_000, name  # axes, labels and data, not a blank canvas
        with Image.open(path) as img:
            img.verify()
        with Image.open(path) as img:
            assert img.format == "PNG" and img.width >= 700 and img.height >= 400, (name, img.size)
            assert len(img.convert("RGB").getcolors(maxcolors=1 << 16) or range(1 << 16)) > 20, name
        assert f"]({name})" in md


def test_html_is_self_contained(report):
    page = (report / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and page.rstrip().endswith("</html>")
    assert page.count('src="data:image/png;base64,') == len(PLOT_FILES)
    assert "<style>" in page and "<link" not in page and "<script" not in page
    assert "By strategy" in page and "Relation usage" in page


def test_side_by_side_marks_timeouts_and_errors(report, real_frames):
    md = (report / "report.md").read_text()
    assert SIDE_BY_SIDE in md
    header, *rows = _table(md, "Strategies side by side (Table 3 layout)")
    assert header[:2] == ["Frame", "N"] and "astar-cpa: Time (s)" in header and "auto: Time (s)" in header
    assert len(rows) == len(real_frames)
    assert [int(r[1]) for r in rows] == sorted(int(r[1]) for r in rows)
    line = {r[0]: dict(zip(header, r)) for r in rows}
    big = sorted(real_frames, key=lambda s: len(s.others))
    assert line[big[-2].frame_id]["astar-cpa: Time (s)"] == "TO"
    assert line[big[-1].frame_id]["astar-cpa: Time (s)"] == "ERR"
    assert "**" in md.split(SIDE_BY_SIDE, 1)[1].split("\n## ", 1)[0]  # the fastest time in a row is bold


def test_failures_are_listed(report, real_frames):
    header, *rows = _table((report / "report.md").read_text(), "Failures")
    biggest = max(real_frames, key=lambda s: len(s.others)).frame_id
    assert ["astar-cpa", "error", "1", ERROR_MESSAGE, biggest] in rows


def test_one_strategy_has_no_side_by_side_table(real_frames, tmp_path):
    programs = _write(_rows(real_frames[:4], ("auto",)), tmp_path / "p.parquet")
    proc = run_r2s("report", str(programs), "--out", str(tmp_path / "r"))
    assert proc.returncode == 0, proc.stderr
    md = (tmp_path / "r" / "report.md").read_text()
    assert SIDE_BY_SIDE not in md and "## By strategy" in md
    assert "No frame failed." in md


def test_rerun_replaces_the_report_byte_for_byte(two_strategies, report, tmp_path):
    out = tmp_path / "again"
    for _ in range(2):  # the second run replaces the first report
        proc = run_r2s("report", str(two_strategies), "--out", str(out))
        assert proc.returncode == 0, proc.stderr
    names = sorted(os.listdir(out))
    assert names == sorted(os.listdir(report))
    for name in names:  # same programs file, same bytes: no dates, no random names inside
        assert (out / name).read_bytes() == (report / name).read_bytes(), name
    assert sorted(os.listdir(tmp_path)) == ["again"]  # no staging directory left behind


def _assert_nothing_written(proc, out: Path, contains: str) -> None:
    assert_one_line_error(proc, 2, contains)
    assert not out.exists()
    assert not [p for p in out.parent.iterdir() if p.name.startswith(f".{out.name}.")]


def test_corrupt_programs_file(tmp_path):
    bad = tmp_path / "programs.parquet"
    bad.write_bytes(b"PAR1 this is not parquet at all" * 10)
    _assert_nothing_written(run_r2s("report", str(bad), "--out", str(tmp_path / "r")), tmp_path / "r", "parquet")


def test_wrong_schema(tmp_path):
    other = tmp_path / "frames.parquet"
    pq.write_table(pa.table({"frame_id": ["a"], "x": [1.0]}), other)
    _assert_nothing_written(run_r2s("report", str(other), "--out", str(tmp_path / "r")), tmp_path / "r",
                            "not a programs file")


def test_missing_programs_file(tmp_path):
    _assert_nothing_written(run_r2s("report", str(tmp_path / "none.parquet"), "--out", str(tmp_path / "r")),
                            tmp_path / "r", "does not exist")


def test_empty_programs_file(tmp_path):
    empty = _write([], tmp_path / "programs.parquet")
    _assert_nothing_written(run_r2s("report", str(empty), "--out", str(tmp_path / "r")), tmp_path / "r",
                            "nothing to report")


def test_refuses_to_replace_a_directory_of_other_files(two_strategies, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    proc = run_r2s("report", str(two_strategies), "--out", str(out))
    assert_one_line_error(proc, 2, "not part of a report")
    assert os.listdir(out) == ["notes.txt"] and (out / "notes.txt").read_text() == "keep me"


@pytest.mark.parametrize("column, value, message", [
    ("cost", "three", "type"),
    ("frame_id", None, "frame_id has a missing value"),
    ("status", "done", "unknown status"),
])
def test_programs_files_with_wrong_types_or_values_exit_2_everywhere(two_strategies, tmp_path, column, value,
                                                                      message):
    """A programs file is input too (`r2s report`, and `r2s run --out` resuming into it): typed, not trusted."""
    table = pq.read_table(two_strategies)
    values = table.column(column).to_pylist()
    values[0] = value
    field = table.schema.field(column)
    if isinstance(value, str) and not pa.types.is_string(field.type):
        field = pa.field(column, pa.string())  # a file whose writer put text where the schema has a number
        values = [None if v is None else str(v) for v in values]
    bad = table.set_column(table.schema.get_field_index(column), field, pa.array(values, type=field.type))
    path = tmp_path / "bad.parquet"
    pq.write_table(bad, path)
    before = path.read_bytes()
    proc = run_r2s("report", str(path), "--out", str(tmp_path / "report"))
    assert_one_line_error(proc, 2, contains=message)
    assert not (tmp_path / "report").exists()
    frames = tmp_path / "frames.parquet"
    assert run_r2s("extract", "scenarionet", "data/nuscenes-mini-excerpt/scenarionet", "--out", str(frames),
                   "--categories", "vehicles").returncode == 0
    proc = run_r2s("run", str(frames), "--out", str(path), "--jobs", "1")
    assert proc.returncode == 2 and message in proc.stderr and "Traceback" not in proc.stderr, proc.stderr
    assert path.read_bytes() == before


def test_motion_relations_are_counted_only_where_programs_have_them(real_frames, tmp_path):
    import random
    from dataclasses import replace

    from synth.scene import Scene

    rng = random.Random(8)
    config = SynthConfig(motion=True)
    rows = []
    for scene in [s for s in real_frames if len(s.others) <= 25][:6]:
        moving = Scene(scene.frame_id, tuple(replace(e, speed=rng.choice([0.0, 0.3, rng.uniform(1, 12)]))
                                             for e in scene.entities))
        rows.append(result_row(synthesize(moving, config)))
    out = tmp_path / "report"
    proc = run_r2s("report", str(_write(rows, tmp_path / "programs.parquet")), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    table = _by_name(_table((out / "report.md").read_text(), "Relation usage"))
    lines = [ln for r in rows for ln in r["program"].splitlines()]
    expected = {"stationary": sum(ln.endswith(", stationary") for ln in lines),
                "moving like": sum(", moving like " in ln for ln in lines),
                "relative speed": sum(bool(re.search(r"m/s relative to \w+$", ln)) for ln in lines),
                "absolute speed": sum(ln.endswith(" m/s") for ln in lines)}
    assert {k: int(table[k]["Total"]) for k in expected} == expected
    assert sum(expected.values()) == len(lines) and expected["stationary"] > 0


def test_static_reports_have_no_motion_rows(report):
    table = _by_name(_table((report / "report.md").read_text(), "Relation usage"))
    assert "stationary" not in table and "relative speed" not in table
