"""`r2s query` within its bounds (issue 22, items 4, 8, 9): a pattern whose join would blow up is refused before
it runs, with the estimate; too many names are refused; memory and spill are capped; a signal leaves nothing
behind; pattern names that differ only in case are two names. Real processes under a watchdog where a hang or a
blow-up is possible (tests.support.bounded); the estimate is checked against the independent brute force."""

from __future__ import annotations

import itertools
import signal
import subprocess
import sys
import time
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from frames.dataset import FramesDataset
from frames.rows import iter_scenes, read_frames
from pipeline.query import mining
from pipeline.query.sql import estimate_query
from synth.config import SynthConfig
from synth.patterns.one_frame import parse_pattern
from synth.patterns.temporal import is_temporal, parse_temporal
from tests.support import ROOT
from tests.support.bounded import assert_refused, run_bounded
from tests.support.query_bruteforce import brute_matches

KEYFRAMES = str(ROOT / "data" / "nuscenes-mini-keyframes" / "frames.parquet")
ANYWHERE = "on Range(-1000, 1000) @ Range(-1000, 1000), facing Range(0, 360) deg"


def _unrelated(n: int, names: str = "abcdefghijklmnopqrstuvwxyz") -> str:
    return "".join(f"{names[k]} = new Object {ANYWHERE}\n" for k in range(n))


def test_four_unrelated_names_are_refused_with_the_estimate(tmp_path):
    """Before: 11 GB of spill in 90 s. Now: exit 2 within seconds, naming the estimate and the frame."""
    (tmp_path / "four.dsl").write_text(_unrelated(4))
    out = tmp_path / "new" / "matches.parquet"
    result = run_bounded("query", KEYFRAMES, str(tmp_path / "four.dsl"), "--out", str(out), timeout=60,
                         max_rss_mb=1500)
    assert_refused(result, "candidate bindings in frame")
    assert "e+08" in result.stderr  # 141 entities of scene-0061/18: 141^4 = 3.95e8
    assert not (tmp_path / "new").exists()  # the folder it would have made for --out is not left behind


@pytest.mark.parametrize("form", ["events", "temporal"])
def test_unrelated_names_are_refused_for_events_and_in_temporal_steps(form, tmp_path):
    """--events reads the same bindings, a temporal pattern runs each step's join: both are estimated first."""
    text = _unrelated(4) + ("then\n" + _unrelated(4) if form == "temporal" else "")
    (tmp_path / "p.dsl").write_text(text)
    extra = ["--events"] if form == "events" else []
    result = run_bounded("query", KEYFRAMES, str(tmp_path / "p.dsl"), *extra, "--out", str(tmp_path / "m.parquet"),
                         timeout=60, max_rss_mb=1500)
    assert_refused(result, "candidate bindings in frame")
    assert "e+08" in result.stderr
    assert list(tmp_path.iterdir()) == [tmp_path / "p.dsl"]  # no spill folder, no temporary file


def test_many_steps_are_refused_before_the_frames_are_read(tmp_path):
    one = "a = new Car ahead of ego by Range(0, 10), facing Range(0, 360) deg\n"
    (tmp_path / "p.dsl").write_text("then\n".join([one] * (mining.MAX_PATTERN_NAMES + 1)))
    result = run_bounded("query", KEYFRAMES, str(tmp_path / "p.dsl"), "--out", str(tmp_path / "m.parquet"),
                         timeout=30)
    assert_refused(result, f"steps, more than the bound of {mining.MAX_PATTERN_NAMES}")


def test_many_names_are_refused_before_the_frames_are_read(tmp_path):
    (tmp_path / "p.dsl").write_text("".join(f"x{k} = new Car {ANYWHERE}\n" for k in range(300)))
    result = run_bounded("query", KEYFRAMES, str(tmp_path / "p.dsl"), "--out", str(tmp_path / "m.parquet"),
                         timeout=30)
    assert_refused(result, f"more than the bound of {mining.MAX_PATTERN_NAMES}")


def test_a_memory_limit_too_small_is_bad_input(tmp_path):
    result = run_bounded("query", KEYFRAMES, "data/patterns/queue-of-three.dsl", "--memory-limit", "1",
                         "--out", str(tmp_path / "q" / "m.parquet"), timeout=60)
    assert_refused(result, "--memory-limit 1 MB")
    assert not (tmp_path / "q").exists()


def test_the_spill_is_capped(tmp_path, monkeypatch):
    """A query that must spill more than the cap fails with one bad-input line and leaves no spill folder."""
    from pipeline.errors import UserError

    monkeypatch.setattr(mining, "SPILL_LIMIT_MB", 1)
    out = tmp_path / "m.parquet"
    with pytest.raises(UserError, match="spilled to disk"):  # every pair of two names, all bindings, sorted
        mining.query_frames(KEYFRAMES, parse_pattern(_unrelated(2)), out, all_bindings=True, memory_limit_mb=20,
                            threads=1, log=lambda s: None)
    assert list(tmp_path.iterdir()) == []


def test_a_query_without_memory_limit_runs_under_the_default(tmp_path, monkeypatch):
    """Without --memory-limit the session is bounded by the default (DuckDB's own, 80% of RAM, let queue-of-three
    at 10^6 frames reach 4.7 GB): a default too small to run in is named in the refusal."""
    from pipeline.errors import UserError

    assert mining.default_memory_limit_mb() <= mining.DEFAULT_MEMORY_LIMIT_MB
    monkeypatch.setattr(mining, "DEFAULT_MEMORY_LIMIT_MB", 1)
    out = tmp_path / "m.parquet"
    with pytest.raises(UserError, match="the default memory limit of 1 MB"):
        mining.query_frames(KEYFRAMES, parse_pattern(_unrelated(2)), out, all_bindings=True, threads=1,
                            log=lambda s: None)
    assert list(tmp_path.iterdir()) == []


def _running_query(tmp_path: Path, sig: signal.Signals):
    """Start a query that runs for seconds (every pair of two unrelated names, all bindings: 6e5 rows), wait
    until it has made its temporary output, then send `sig`."""
    (tmp_path / "two.dsl").write_text(_unrelated(2))
    new = tmp_path / "made" / "here"
    cmd = [sys.executable, "-m", "pipeline.cli", "query", KEYFRAMES, str(tmp_path / "two.dsl"), "--all",
           "--out", str(new / "m.parquet")]
    # SIGINT as a terminal sends it (a child of a background job would inherit SIG_IGN).
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while not (new.is_dir() and any(p.name.endswith(".tmp") for p in new.iterdir())):
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.02)
    proc.send_signal(sig)
    try:
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    return proc.returncode, out, err


@pytest.mark.parametrize("sig,code,word", [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")])
def test_a_signal_leaves_nothing_behind(sig, code, word, tmp_path):
    """Before: SIGTERM left the spill folder and the .tmp beside --out; Ctrl-C printed "internal error"."""
    returncode, out, err = _running_query(tmp_path, sig)
    assert returncode == code, err
    assert err.strip().splitlines() == [f"r2s query: {word}"], err
    assert not (tmp_path / "made").exists()  # spill, temporary output and the folders it made: all gone


def test_names_that_differ_in_case_are_two_names(tmp_path):
    """DuckDB's struct field names ignore case; the pattern's do not (before: an internal error)."""
    text = ("a = new Car on Range(-50, 50) @ Range(-50, 50), facing Range(0, 360) deg\n"
            "A = new Car ahead of a by Range(0, 20), facing Range(0, 360) deg\n")
    (tmp_path / "p.dsl").write_text(text)
    out = tmp_path / "m.parquet"
    result = run_bounded("query", KEYFRAMES, str(tmp_path / "p.dsl"), "--all", "--out", str(out), timeout=120)
    assert result.returncode == 0, result.stderr
    table = pq.read_table(out)
    assert table.schema.field("binding").type.names == ["a", "A"]
    got = {}
    for row in table.to_pylist():
        got.setdefault(row["frame_id"], []).append((row["binding"]["a"], row["binding"]["A"]))
    pattern = parse_pattern(text)
    want = {s.frame_id: b for s in iter_scenes(read_frames(KEYFRAMES)) if (b := brute_matches(pattern, s))}
    assert {f: sorted(b) for f, b in got.items()} == {f: sorted(b) for f, b in want.items()}
    assert want  # the pattern does match somewhere


def test_case_distinct_names_in_temporal_patterns_and_events(tmp_path):
    """Temporal steps and events key tracks by name too: `a` / `A` give what `x` / `y` give, under their names."""
    text = ("a = new Car ahead of ego by Range(0, 40), facing Range(0, 360) deg\n"
            "A = new Object left of a by Range(0, 20), facing Range(0, 360) deg\nthen\n"
            "A = new Object ahead of ego by Range(0, 60), facing Range(0, 360) deg\n"
            "a = new Car on Range(-60, 60) @ Range(-60, 60) relative to ego, facing Range(0, 360) deg\n")
    renamed = text.replace("A = ", "y = ").replace("a = ", "x = ").replace("of a ", "of x ")
    got = {}
    for label, pattern in (("case", text), ("plain", renamed)):
        for extra in ([], ["--events"]):
            (tmp_path / "p.dsl").write_text(pattern)
            out = tmp_path / f"{label}{len(extra)}.parquet"
            result = run_bounded("query", KEYFRAMES, str(tmp_path / "p.dsl"), *extra, "--out", str(out), timeout=120)
            assert result.returncode == 0, result.stderr
            got[label, len(extra)] = pq.read_table(out)
    for events in (0, 1):
        case, plain = got["case", events], got["plain", events]
        assert case.schema.field("binding").type.names == ["a", "A"]
        assert plain.num_rows > 0
        for column in ("binding", "tracks") if events else ("binding",):
            assert [(r["a"], r["A"]) for r in case.column(column).to_pylist()] == \
                   [(r["x"], r["y"]) for r in plain.column(column).to_pylist()]


ONE_FRAME = [
    *(t for p in sorted((ROOT / "data" / "patterns").glob("*.dsl")) if not is_temporal(t := p.read_text())),
    f"a = new Pedestrian {ANYWHERE}\nb = new Barrier {ANYWHERE}\n",  # unrelated: the product is exact
    "p = new Pedestrian ahead of ego by Range(0, 40), facing Range(0, 360) deg\n"
    "v = new Vehicle right of p by Range(0, 15), facing Range(0, 360) deg\n"
    "w = new Object left of v by Range(0, 10), facing Range(0, 360) deg\n",
]


def _per_frame(con, sql: str) -> dict[str, list[float]]:
    got: dict[str, list[float]] = {}
    for fid, p in con.execute(sql).fetchall():
        got.setdefault(fid, []).append(p)
    return got


@pytest.fixture(scope="module")
def keyframes():
    return list(iter_scenes(read_frames(KEYFRAMES)))


@pytest.fixture
def session(tmp_path):
    ds = FramesDataset.open(KEYFRAMES)
    con = mining._open([p.path for p in ds.parts], False, 1, None, str(tmp_path))
    yield con
    con.close()


@pytest.mark.parametrize("k", range(len(ONE_FRAME)))
def test_the_estimate_bounds_every_frames_bindings_from_above(k, keyframes, session):
    """Both estimates (per-type products, and with pairwise fan-outs) are at least the number of bindings the
    brute force finds in each frame: refusing on them never refuses a query on a false premise of size."""
    pattern = parse_pattern(ONE_FRAME[k])
    counts = {s.frame_id: len(brute_matches(pattern, s)) for s in keyframes}
    plain = _per_frame(session, estimate_query(pattern, SynthConfig(), False, per_frame=True))
    tight = _per_frame(session, estimate_query(pattern, SynthConfig(), True, per_frame=True))
    assert set(plain) == set(tight) == set(counts)
    for fid, n in counts.items():
        assert n <= tight[fid][0] <= plain[fid][0], (fid, n, tight[fid], plain[fid])
    assert sum(counts.values()) > 0
    if "Barrier" in ONE_FRAME[k] and "Pedestrian" in ONE_FRAME[k] and " of " not in ONE_FRAME[k]:
        assert counts == {f: p[0] for f, p in plain.items()}  # unrelated names of two types: the product is exact
    _assert_bound_is_above(pattern, session.execute(estimate_query(pattern, SynthConfig(), False)).fetchall()[0])


def _assert_bound_is_above(pattern, estimate) -> None:
    """mining.estimate_bound, which lets a query skip the estimate, is at least the estimate (without fan-outs,
    the larger): skipping it never lets through a pattern the estimate refuses."""
    dataset = FramesDataset.open(KEYFRAMES)
    bound = mining.estimate_bound(pattern, dataset.check().largest, sum(p.rows for p in dataset.parts))
    worst, _, _, total = estimate
    assert bound is None or (worst <= bound[0] and total <= bound[1]), (bound, worst, total)


# Every shipped temporal pattern, and one whose variables are in two of three steps each (its candidates are a
# join of the steps' track tuples, bounded by the step that binds the fewest).
TEMPORAL = [
    *(t for p in sorted((ROOT / "data" / "patterns").glob("*.dsl")) if is_temporal(t := p.read_text())),
    "a = new Car ahead of ego by Range(0, 40), facing Range(0, 360) deg\n"
    "b = new Object left of a by Range(0, 20), facing Range(0, 360) deg\nthen\n"
    "b = new Object ahead of ego by Range(0, 60), facing Range(0, 360) deg\n"
    "c = new Pedestrian on Range(-30, 30) @ Range(-30, 30) relative to ego, facing Range(0, 360) deg\nthen\n"
    "c = new Pedestrian on Range(-30, 30) @ Range(-30, 30) relative to ego, facing Range(0, 360) deg\n"
    "a = new Car right of c by Range(0, 40), facing Range(0, 360) deg\n",
]


def _brute_candidates(pattern, scenes_by_name: dict) -> int:
    """The candidate bindings of candidates_sql by definition: per scene, the injective bindings of the variables
    to tracks such that every step binds its variables' tracks in some frame of the scene (behaviours aside)."""
    total = 0
    for frames in scenes_by_name.values():
        per_step = []
        for step in pattern.steps:
            tuples = set()
            for scene, tracks in frames:
                for b in brute_matches(step.pattern, scene):
                    tuples.add(tuple(tracks[e] for e in b))
            per_step.append((step.names, tuples))
        names = pattern.names
        options = {n: {t[ns.index(n)] for ns, ts in per_step if n in ns for t in ts} for n in names}
        for combo in itertools.product(*(sorted(options[n]) for n in names)):
            if len(set(combo)) == len(combo) and all(
                    tuple(combo[names.index(n)] for n in ns) in ts for ns, ts in per_step):
                total += 1
    return total


@pytest.mark.parametrize("k", range(len(TEMPORAL)))
def test_the_temporal_estimate_bounds_each_steps_bindings_and_the_candidates(k, keyframes, session):
    """A temporal pattern's steps run one by one: per frame, each step's estimate is at least the step's bindings
    (brute force); over all, the estimate is at least every step's bindings plus the candidate bindings of the
    whole pattern (brute force over the scenes' track tuples)."""
    from pipeline.query.temporal import estimate_query as temporal_estimate

    pattern = parse_temporal(TEMPORAL[k])
    rows = read_frames(KEYFRAMES)
    tracks = {f: dict(zip(g.entity_id, g.track_id)) for f, g in rows.groupby("frame_id", sort=False)}
    by_scene: dict = {}
    for s in keyframes:
        by_scene.setdefault(rows.loc[rows.frame_id == s.frame_id, "scene"].iloc[0], []).append((s, tracks[s.frame_id]))
    steps = [{s.frame_id: len(brute_matches(step.pattern, s)) for s in keyframes} for step in pattern.steps]
    for fanout in (False, True):
        sql = temporal_estimate(pattern, SynthConfig(), fanout, per_frame=True)
        est = {(fid, k): p for fid, k, p in session.execute(sql).fetchall()}
        assert set(est) == {(fid, k) for k in range(len(steps)) for fid in steps[0]}
        for (fid, k), p in est.items():
            assert steps[k][fid] <= p, (fid, k)
        worst, _, _, total = session.execute(temporal_estimate(pattern, SynthConfig(), fanout)).fetchall()[0]
        assert worst == max(est.values())
        need = sum(sum(step.values()) for step in steps) + _brute_candidates(pattern, by_scene)
        assert need <= total, (need, total)
        if not fanout:
            _assert_bound_is_above(pattern, (worst, None, None, total))
    assert sum(sum(step.values()) for step in steps) > 0 or pattern.uses_motion  # keyframes carry no speed
