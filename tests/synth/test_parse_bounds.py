"""The DSL's parsers within their bounds (issue 35, items 6, 7 and 15): a line is at most MAX_LINE characters, a
program at most MAX_STATEMENTS statements, a pattern at most MAX_NAMES names and MAX_STEPS steps, a name shows each behaviour once a step, a duration is at most
MAX_DURATION_S; each is refused at the line that passes it, as one line and exit 2, before the rest is parsed.
Tokens are read in time linear in the line. Real `r2s` processes on real files, under the watchdog
(tests.support.bounded): before, these ran for minutes, ran out of memory or exited 1."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from synth.dsl import MAX_STATEMENTS
from synth.patterns.one_frame import MAX_NAMES
from synth.patterns.temporal import MAX_DURATION_S, MAX_STEPS, parse_temporal
from synth.syntax import MAX_LINE
from tests.support import ROOT
from tests.support.bounded import assert_refused, run_bounded

KEYFRAMES = str(ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet")
AV2 = str(ROOT / "data" / "argoverse2-log-excerpt" / "frames.parquet")  # with speeds: behaviours are read
FRAME = "scene-0061/0"


@pytest.fixture(scope="module")
def scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scene") / "S.json"
    result = run_bounded("scene", KEYFRAMES, FRAME, "--out", str(path), timeout=60)
    assert result.returncode == 0, result.stderr
    return path


def _query(tmp_path: Path, text: str, frames: str = KEYFRAMES, timeout: float = 30):
    (tmp_path / "p.dsl").write_text(text)
    result = run_bounded("query", frames, str(tmp_path / "p.dsl"), "--out", str(tmp_path / "m.parquet"),
                         timeout=timeout, max_rss_mb=1000)
    return result


def test_a_program_of_one_huge_line_is_refused_at_once(scene, tmp_path):
    """Before: `r2s check` of 1.5e6 tokens on one line ran past 60 s (each token copied the rest of the line)."""
    (tmp_path / "P.dsl").write_text("x " * 1_500_000)
    result = run_bounded("check", str(scene), str(tmp_path / "P.dsl"), timeout=20, max_rss_mb=600)
    assert_refused(result, f"line 1: 3000000 characters, more than the {MAX_LINE} a line may have")
    assert result.seconds < 10, result.seconds


def test_a_line_of_max_line_characters_is_read(scene, tmp_path):
    """The bound is MAX_LINE itself: a program whose line has exactly that many characters is checked."""
    program = run_bounded("synth", str(scene), timeout=120)
    assert program.returncode == 0, program.stderr
    first, *rest = program.stdout.splitlines()
    padded = first + " " * (MAX_LINE - len(first) - 2) + "#."
    assert len(padded) == MAX_LINE
    (tmp_path / "P.dsl").write_text("\n".join([padded, *rest]) + "\n")
    ok = run_bounded("check", str(scene), str(tmp_path / "P.dsl"), timeout=60)
    assert ok.returncode == 0 and ok.stdout.startswith("ok:"), ok.stderr
    (tmp_path / "P.dsl").write_text("\n".join([padded + " ", *rest]) + "\n")
    assert_refused(run_bounded("check", str(scene), str(tmp_path / "P.dsl"), timeout=60),
                   f"line 1: {MAX_LINE + 1} characters")


def test_a_program_of_too_many_statements_is_refused_at_the_bound(scene, tmp_path):
    """200,000 statements took about 20 s to parse (64 MB of them, 100 s); now the parse stops at
    the first statement past MAX_STATEMENTS. At the bound, the program is checked (exit 3: every statement names
    no entity of the scene)."""
    def statements(n: int) -> str:
        return "".join(f"c{k} = new Car ahead of ego by Range(0, 1), facing toward ego\n" for k in range(n))

    (tmp_path / "P.dsl").write_text(statements(200_000))
    result = run_bounded("check", str(scene), str(tmp_path / "P.dsl"), timeout=30, max_rss_mb=800)
    assert_refused(result, f"line {MAX_STATEMENTS + 1}: statement {MAX_STATEMENTS + 1:,}, more than the bound of "
                           f"{MAX_STATEMENTS:,}")
    (tmp_path / "P.dsl").write_text(statements(MAX_STATEMENTS))
    result = run_bounded("check", str(scene), str(tmp_path / "P.dsl"), timeout=60)
    assert result.returncode == 3 and result.killed is None, result.stderr[-300:]
    assert result.stdout.count(": extra: declared but not an entity of the scene") == MAX_STATEMENTS


def test_tokens_are_read_in_linear_time():
    """The tokenizer without the line bound (the Python API's Line): 400,000 tokens in well under the watchdog's
    10 s (about 1 s now; the copy of the rest of the line per token took minutes)."""
    code = ("from synth.syntax import Line\n"
            "ln = Line('x ' * 400_000, 1)\n"
            "assert len(ln.toks) == 400_000 and ln.toks[-1].col == 799_999\n")
    result = run_bounded(command=[sys.executable, "-c", code], timeout=10, max_rss_mb=800)
    assert result.killed is None and result.returncode == 0, (result.killed, result.stderr[-400:])


@pytest.mark.parametrize("shape, text, says", [
    # Before: 20,000 steps ran past 100 s (each step's text was rebuilt from line 1).
    ("200,000 steps", "then\n".join(["c = new Car\n"] * 200_000),
     f"line {2 * MAX_STEPS}: the pattern has {MAX_STEPS + 1} or more steps, more than the bound of {MAX_STEPS}"),
    ("200,000 names", "".join(f"c{k} = new Car\n" for k in range(200_000)),
     f"line {MAX_NAMES + 1}: the pattern declares {MAX_NAMES + 1} or more names, more than the bound of {MAX_NAMES}"),
    ("200,000 clauses on a line", "c = new Car" + ", stationary" * 200_000 + "\n", "more than the 10000 a line"),
])
def test_huge_patterns_are_refused_at_the_line_that_passes_the_bound(tmp_path, shape, text, says):
    result = _query(tmp_path, text, timeout=20)
    assert_refused(result, says)
    assert result.seconds < 10, (shape, result.seconds)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.dsl"]


def test_names_over_all_steps_are_bounded(tmp_path):
    """Each step within the bound, the steps together past it: refused at the line of the first name too many."""
    half = MAX_NAMES // 2 + 1
    steps = [[f"a{k} = new Car" for k in range(half)], [f"a{k} = new Car" for k in range(half)],
             [f"a{k} = new Car" for k in range(half, 2 * half)], [f"a{k} = new Car" for k in range(half, 2 * half)]]
    text = "then\n".join("".join(f"{s}\n" for s in step) for step in steps)
    first_too_many = text.splitlines().index(f"a{MAX_NAMES} = new Car") + 1
    assert_refused(_query(tmp_path, text), f"line {first_too_many}: the pattern declares {MAX_NAMES + 1} or more")


@pytest.mark.parametrize("times", [2, 50, 1_000])
def test_a_behaviour_said_twice_is_refused(tmp_path, times):
    """Before: 1,000 times was a BinderException (exit 1), 10,000 ran 48 s and out of memory."""
    text = "c = new Car, ahead of ego by Range(0, 50)" + ", braking" * times + "\nthen\nc = new Car\n"
    assert_refused(_query(tmp_path, text, frames=AV2), "line 1: c is 'braking' twice in one step")


def test_every_behaviour_once_is_read(tmp_path):
    """Each behaviour once, for a name and for ego: a pattern, not a refusal (the bound is repetition)."""
    every = "braking, accelerating, stopping, turning left, turning right, changing lanes"
    text = f"c = new Car, ahead of ego by Range(0, 50), {every}\nego {every}\nthen\nc = new Car\n"
    step = parse_temporal(text).steps[0]
    assert len(step.behaviours) == 12 and len(set(step.behaviours)) == 12
    result = _query(tmp_path, text, frames=AV2, timeout=60)
    assert result.returncode == 0 and result.killed is None, result.stderr


@pytest.mark.parametrize("text", ["c = new Car\nfor at least 1e308 s\n", "c = new Car\nthen within 1e308 s\nc = new Car\n",
                                  f"c = new Car\nfor at least {MAX_DURATION_S * 1.000001!r} s\n"])
def test_a_duration_past_the_bound_is_refused(tmp_path, text):
    """Before: 1e308 s was an OverflowError (exit 1)."""
    assert_refused(_query(tmp_path, text, frames=AV2), f"a duration is a number of seconds from 0 to {MAX_DURATION_S:g}")


def test_a_duration_at_the_bound_is_read():
    pattern = parse_temporal(f"c = new Car\nthen within {MAX_DURATION_S:g} s\nc = new Car\nfor at least "
                             f"{MAX_DURATION_S:g} s\n")
    assert pattern.steps[1].within_us == pattern.steps[1].for_at_least_us == round(MAX_DURATION_S * 1e6)
