"""Untrusted extractor inputs (issue 7): pickles that run code, corrupt or foreign files, and arbitrary bytes
where a frames Parquet should be. Each is refused with exit 2 and one line; nothing is written or executed."""

from __future__ import annotations

import os
import pickle
import shutil
import signal

import numpy as np
import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from extractors.safe_pickle import load_pickle
from frames.rows import FramesError, read_frames
from tests.support.extract import EXCERPT, assert_refused, r2s

SCENARIO = EXCERPT / "scenarionet" / "sd_nuscenes_v1.0-mini_scene-0796.pkl"


class _RunsCode:
    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def test_the_shared_pickles_need_only_numpy_globals(shared_dir):
    for f in sorted((shared_dir / "data" / "nuscenes-mini" / "scenarionet").glob("*.pkl")):
        sd = load_pickle(f)
        assert isinstance(sd["tracks"], dict) and sd["metadata"]["sdc_id"] in sd["tracks"]


def test_malicious_pickle_is_refused_and_never_runs(tmp_path, capsys):
    marker = tmp_path / "pwned"
    db = tmp_path / "db"
    db.mkdir()
    with open(db / "sd_evil.pkl", "wb") as fh:
        pickle.dump({"metadata": {"sdc_id": "ego"}, "tracks": {}, "payload": _RunsCode(marker)}, fh)
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out))
    assert_refused(res, out, "posix.system")
    assert "sd_evil.pkl" in res.stderr
    assert not marker.exists()


@pytest.mark.parametrize("payload", [
    lambda m: (__import__("subprocess").Popen, (["touch", str(m)],)),
    lambda m: (eval, (f"open({str(m)!r}, 'w')",)),
    lambda m: (getattr, (m, "unlink")),
])
def test_other_callables_are_refused(tmp_path, payload):
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return payload(marker)

    path = tmp_path / "evil.pkl"
    path.write_bytes(pickle.dumps([np.arange(3.0), Evil()], protocol=4))
    with pytest.raises(FramesError, match="refused to unpickle"):
        load_pickle(path)
    assert not marker.exists()


def test_numpy_data_in_every_protocol_loads(tmp_path):
    data = {"a": np.arange(6.0).reshape(2, 3), "b": np.float64(1.5), "c": np.int64(3), "s": {1, 2},
            "f": frozenset({"x"}), "z": complex(1, 2), "by": b"\x00\x01"}
    for protocol in (2, 3, 4, 5):
        path = tmp_path / f"p{protocol}.pkl"
        path.write_bytes(pickle.dumps(data, protocol=protocol))
        back = load_pickle(path)
        assert np.array_equal(back["a"], data["a"]) and back["b"] == 1.5 and back["s"] == {1, 2}
        assert back["by"] == b"\x00\x01" and back["z"] == complex(1, 2)


@pytest.mark.parametrize("case", ["truncated", "text", "not-a-scenario", "bad-shape"])
def test_bad_scenarionet_files_exit_2(tmp_path, capsys, case):
    db = tmp_path / "db"
    db.mkdir()
    path = db / SCENARIO.name
    data = SCENARIO.read_bytes()
    expect = {"truncated": "not a readable pickle", "text": "not a pickle file",
              "not-a-scenario": "not a ScenarioNet scenario", "bad-shape": "not 11 steps"}[case]
    if case == "truncated":
        path.write_bytes(data[: len(data) // 3])
    elif case == "text":
        path.write_text("just some text pretending to be a pickle")
    elif case == "not-a-scenario":
        path.write_bytes(pickle.dumps([1, 2, 3]))
    else:
        sd = load_pickle(SCENARIO)
        track = next(t for k, t in sd["tracks"].items() if k != sd["metadata"]["sdc_id"])
        track["state"]["heading"] = track["state"]["heading"][:-3]
        path.write_bytes(pickle.dumps(sd, protocol=4))
    out = tmp_path / "out" / "frames.parquet"
    assert_refused(r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out), "--categories", "all"),
                   out, expect)


def test_database_mapping_may_point_outside_only_to_scenario_files(tmp_path, capsys):
    # merged databases map to ../<db> (issue 13): followed, but only to an existing file that is a scenario
    db = tmp_path / "db"
    shutil.copytree(EXCERPT / "scenarionet", db)
    mapping = {name: "../../etc" for name in load_pickle(db / "dataset_mapping.pkl")}
    (db / "dataset_mapping.pkl").write_bytes(pickle.dumps(mapping))
    out = tmp_path / "out" / "frames.parquet"
    res = r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out))
    assert_refused(res, out, "/../../etc/sd_nuscenes_v1.0-mini_scene-0103.pkl, which does not exist")
    (tmp_path / "elsewhere").mkdir()
    (tmp_path / "elsewhere" / "sd_nuscenes_v1.0-mini_scene-0103.pkl").write_bytes(pickle.dumps({"not": "one"}))
    (db / "dataset_mapping.pkl").write_bytes(
        pickle.dumps({**dict.fromkeys(mapping, ""), "sd_nuscenes_v1.0-mini_scene-0103.pkl": "../elsewhere"}))
    res = r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out))
    assert_refused(res, out, "elsewhere/sd_nuscenes_v1.0-mini_scene-0103.pkl is not a ScenarioNet scenario")
    (db / "dataset_mapping.pkl").write_bytes(pickle.dumps({"sd_nuscenes_v1.0-mini_scene-0103.pkl": 3}))
    res = r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out))
    assert_refused(res, out, "entry 'sd_nuscenes_v1.0-mini_scene-0103.pkl' maps to 3, not a folder")


def test_existing_output_survives_a_failed_extraction(tmp_path, capsys):
    out = tmp_path / "frames.parquet"
    out.write_bytes(b"previous result")
    res = r2s(capsys, "extract", "scenarionet", str(tmp_path / "missing"), "--out", str(out))
    assert res.returncode == 2 and "does not exist" in res.stderr
    assert out.read_bytes() == b"previous result"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["frames.parquet"]


@settings(derandomize=True, max_examples=80, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.one_of(
    st.binary(max_size=2048),
    st.binary(max_size=512).map(lambda b: b"PAR1" + b + b"PAR1"),
))
def test_read_frames_fuzz_never_crashes_but_with_frames_error(tmp_path, data):
    path = tmp_path / "fuzz.parquet"
    path.write_bytes(data)
    with pytest.raises(FramesError):
        read_frames(path)


def test_read_frames_fuzz_through_the_cli(tmp_path, capsys):
    rng = np.random.default_rng(7)
    path = tmp_path / "f.parquet"
    for n in (0, 3, 100, 5000):
        path.write_bytes(b"PAR1" + rng.bytes(n) + b"PAR1")
        res = r2s(capsys, "scene", str(path), "scene-0061/0")
        assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1 and res.stdout == ""


def test_unknown_frame_id_suggests_close_ones(tmp_path, capsys):
    out = tmp_path / "frames.parquet"
    assert r2s(capsys, "extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(out)).returncode == 0
    res = r2s(capsys, "scene", str(out), "scene-0103/9")
    assert res.returncode == 2 and "did you mean" in res.stderr and "scene-0103/" in res.stderr
    ok = r2s(capsys, "scene", str(out), "scene-0103/3")
    assert ok.returncode == 0 and '"frame_id": "scene-0103/3"' in ok.stdout


def test_outputs_get_the_permissions_of_a_plain_file(tmp_path):
    import os

    from storage.atomic import write_text_atomic

    old = os.umask(0o022)
    try:
        write_text_atomic(tmp_path / "out.txt", "x")
        (tmp_path / "plain.txt").write_text("x")
    finally:
        os.umask(old)
    assert (tmp_path / "out.txt").stat().st_mode & 0o777 == (tmp_path / "plain.txt").stat().st_mode & 0o777 == 0o644


@pytest.mark.parametrize("change, message", [
    (lambda df: df.assign(entity_id=df["entity_id"].where(df["is_ego"], "car1); import os; (")), "not an identifier"),
    (lambda df: df.assign(entity_id=df["entity_id"].replace({df["entity_id"].iloc[1]: "exec"})), "reserved"),
    (lambda df: df.assign(entity_id=df["entity_id"].replace({df["entity_id"].iloc[1]: "ego"})), "ego row only"),
    (lambda df: df.assign(entity_id=df["entity_id"].replace({df["entity_id"].iloc[2]: df["entity_id"].iloc[1]})),
     "twice"),
])
def test_frames_with_smuggled_or_clashing_ids_are_refused_whole(tmp_path, capsys, change, message):
    from frames.rows import write_frames

    good = tmp_path / "frames.parquet"
    assert r2s(capsys, "extract", "scenarionet", str(EXCERPT / "scenarionet"), "--out", str(good)).returncode == 0
    df = read_frames(good)
    bad = change(df[df["frame_id"] == df["frame_id"].iloc[0]].copy())
    path = tmp_path / "bad.parquet"
    import pyarrow.parquet as pq

    from frames.rows import FRAMES_SCHEMA
    pq.write_table(pa.Table.from_pandas(bad, schema=FRAMES_SCHEMA, preserve_index=False), path)
    with pytest.raises(FramesError, match=message):
        read_frames(path)
    with pytest.raises(FramesError, match=message):
        write_frames(bad, tmp_path / "never.parquet")
    assert not (tmp_path / "never.parquet").exists()
    before = signal.getsignal(signal.SIGTERM)
    res = r2s(capsys, "run", str(path), "--out", str(tmp_path / "programs.parquet"))
    assert res.returncode == 2 and len(res.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "programs.parquet").exists()
    # `r2s run` in this process leaves no SIGTERM handler of its own behind (it used to: a later SIGTERM to the
    # test process became its SystemExit(143) in whatever test ran then).
    assert signal.getsignal(signal.SIGTERM) is before
