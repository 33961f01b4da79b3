"""Hostile ScenarioNet pickles (issue 22): dtypes given object fields through their state, memory bombs of a few
bytes, BUILD on the allow-list's own tokens, and structures that are valid pickles but not scenarios.

Each reproduction runs `r2s extract` as a user does, in a child process under a 2 GB address-space cap, so that a
crash is the child's exit status (a segfault is -11 there, not a dead test run) and its peak memory is measured
(ru_maxrss of a fresh intermediate process's children: Linux keeps a process's peak across fork and exec, so
the child must not descend from this large pytest process directly). The cap turns a bomb that gets past the
bounds into a MemoryError, so each case also checks that the one line names the bound that stopped it."""

from __future__ import annotations

import json
import pickle
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.core.multiarray import _reconstruct

from extractors.base import ExtractError
from extractors.safe_pickle import _GLOBALS, RefusedGlobal, _Token, load_pickle
from tests.support import ROOT
from tests.support.extract import EXCERPT

SCENARIOS = EXCERPT / "scenarionet"
SCENARIO = SCENARIOS / "sd_nuscenes_v1.0-mini_scene-0796.pkl"
CAP_BYTES = 2 * 2**30
SMALL_MB = 500

_RUN = """
import json, resource, subprocess, sys
cap = int(sys.argv[1])
p = subprocess.run(sys.argv[2:], capture_output=True, text=True, timeout=300,
                   preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_AS, (cap, cap)))
peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
print(json.dumps({"returncode": p.returncode, "stdout": p.stdout, "stderr": p.stderr, "peak_mb": peak}))
"""


def r2s_child(*args: str) -> dict:
    """`r2s ARGS` in a child (address space capped): its exit status, output and peak resident memory in MB."""
    cmd = [sys.executable, "-c", _RUN, str(CAP_BYTES), sys.executable, "-m", "pipeline.cli", *args]
    return json.loads(subprocess.run(cmd, capture_output=True, text=True, cwd=ROOT, check=True).stdout)


def assert_refused_small(res: dict, out: Path, contains: str) -> None:
    """Exit 2 with one line naming the problem, nothing written, and the child stayed small."""
    lines = res["stderr"].strip().splitlines()
    assert res["returncode"] == 2, res
    assert len(lines) == 1 and "Traceback" not in res["stderr"], res["stderr"]
    assert contains.lower() in lines[0].lower(), lines[0]
    assert res["peak_mb"] < SMALL_MB, res
    assert not out.exists() or (out.is_dir() and not any(out.iterdir()))


def database_with(tmp_path: Path, name: str, blob: bytes) -> Path:
    """The shipped scenarios (without their index, so that every .pkl is read) plus one more file."""
    db = tmp_path / "db"
    db.mkdir()
    for f in SCENARIOS.glob("sd_*.pkl"):
        shutil.copy(f, db / f.name)
    (db / name).write_bytes(blob)
    return db


def real_scenario() -> dict:
    with open(SCENARIO, "rb") as fh:
        return pickle.load(fh)


def with_heading(value) -> bytes:
    """The shipped scenario, under an id of its own, with one track's state.heading replaced by VALUE (pickled by
    its __reduce__)."""
    sd = real_scenario()
    sd["metadata"]["scenario_id"] = "evil"
    tid = next(t for t in sd["tracks"] if t != sd["metadata"]["sdc_id"])
    sd["tracks"][tid]["state"]["heading"] = value
    return pickle.dumps(sd, protocol=4)


# --- 1. numpy dtypes restored through their state --------------------------------------------------------------

class _Dtype:
    """A dtype as numpy pickles one, np.dtype(spec, False, True) then BUILD with `state`."""

    def __init__(self, spec, state):
        self.spec, self.state = spec, state

    def __reduce__(self):
        return np.dtype, (self.spec, False, True), self.state


class _Array:
    """An array as numpy pickles one, _reconstruct(ndarray, (0,), b'b') then BUILD (1, shape, dtype, F, data)."""

    def __init__(self, shape, dtype, data):
        self.shape, self.dtype, self.data = shape, dtype, data

    def __reduce__(self):
        return _reconstruct, (np.ndarray, (0,), b"b"), (1, self.shape, self.dtype, False, self.data)


OBJECT_FIELD = (3, "|", None, ("a",), {"a": (np.dtype("O"), 0)}, 8, 1, 0)  # flags 0: numpy copies raw bytes
STEPS = 11  # the shipped scene-0796 excerpt


NOT_PLAIN = [
    # a void dtype given an object field: the array's bytes become object pointers (segfault on reading)
    (_Array((STEPS,), _Dtype("V8", OBJECT_FIELD), b"\x41" * 8 * STEPS), "numpy.dtype 'V8'"),
    # a float dtype given the same fields by its state (the field's object dtype is refused first), or plain
    # fields, or an item size
    (_Array((STEPS,), _Dtype("f8", OBJECT_FIELD), b"\x41" * 8 * STEPS), "numpy.dtype 'O8'"),
    (_Array((STEPS,), _Dtype("f8", (3, "|", None, ("a",), {"a": (np.dtype("f8"), 0)}, 8, 1, 0)), b"\0" * 8 * STEPS),
     "numpy.dtype with a state other than a byte order (BUILD)"),
    (_Array((STEPS,), _Dtype("f8", (3, "<", None, None, None, 4096, 8, 0)), b"\0" * 8 * STEPS),
     "numpy.dtype with a state other than a byte order (BUILD)"),
    # an object array (numpy's own pickle: a list of objects)
    (np.array([float(i) for i in range(STEPS)], dtype=object), "numpy.dtype 'O8'"),
    # a structured array of numbers, and strings
    (np.zeros(STEPS, dtype=[("x", "f8")]), "numpy.dtype 'V8'"),
    (np.array(["1.5"] * STEPS), "numpy.dtype 'U3'"),
]


# every case with one reader; the ones made by hand (the crashes on main) also with two worker processes
@pytest.mark.parametrize("heading, refused, jobs", [(*case, "1") for case in NOT_PLAIN]
                         + [(*case, "2") for case in NOT_PLAIN if isinstance(case[0], _Array)])
def test_dtypes_other_than_plain_numbers_are_refused_without_a_crash(tmp_path, heading, refused, jobs):
    db = database_with(tmp_path, "sd_evil.pkl", with_heading(heading))
    out = tmp_path / "frames"
    res = r2s_child("extract", "scenarionet", str(db), "--out", str(out), "--jobs", jobs, "--categories", "all")
    assert_refused_small(res, out, f"refused to unpickle: it references {refused}")
    assert "sd_evil.pkl" in res["stderr"]


def test_array_data_must_match_its_shape(tmp_path):
    path = tmp_path / "a.pkl"
    for shape, data in (((4,), b"\x00" * 24), ((2, 2), b"\x00" * 40), ((3,), "text"), ((-1,), b"")):
        path.write_bytes(pickle.dumps(_Array(shape, np.dtype("f8"), data), protocol=4))
        with pytest.raises(ExtractError, match="not a readable pickle"):
            load_pickle(path)
    path.write_bytes(pickle.dumps(_Array((2, 2), np.dtype(">f8"), np.arange(4.0).astype(">f8").tobytes()), 4))
    back, plain = load_pickle(path), pickle.loads(path.read_bytes())
    assert back.dtype == plain.dtype and back.tolist() == plain.tolist() == [[0.0, 1.0], [2.0, 3.0]]


@pytest.mark.parametrize("protocol", [2, 3, 4, 5])
def test_plain_arrays_and_scalars_of_every_kind_load_as_numpy_gives_them(tmp_path, protocol):
    data = {k: np.arange(6).astype(k).reshape(2, 3) for k in ("?", "i1", "u2", ">i4", "i8", "f2", "f4", ">f8", "c16")}
    data["fortran"] = np.asfortranarray(np.arange(6.0).reshape(2, 3))
    data["empty"] = np.zeros((0, 3))
    data["scalars"] = [np.float32(1.5), np.int64(-3), np.bool_(True), np.complex64(1j)]
    path = tmp_path / "p.pkl"
    path.write_bytes(pickle.dumps(data, protocol=protocol))
    back, plain = load_pickle(path), pickle.loads(path.read_bytes())  # numpy's own unpickling is the reference
    for k, v in data.items():
        if isinstance(v, np.ndarray):
            got, want = back[k], plain[k]
            assert (got.dtype, got.shape, got.flags.f_contiguous) == (want.dtype, want.shape, want.flags.f_contiguous)
            assert np.array_equal(got, v), k
    assert back["scalars"] == data["scalars"] and [type(s) for s in back["scalars"]] == [type(s) for s in data["scalars"]]
    # numpy's shared dtypes keep their byte order whatever a pickle's dtypes were given
    assert np.dtype("f8").byteorder == "=" and np.dtype("i4").byteorder == "="


# --- 2. memory bombs of a few bytes ----------------------------------------------------------------------------

def _shared_state_scenario(tracks: int, steps: int) -> bytes:
    """A scenario whose tracks all hold the same state dict (one copy in the file, `tracks` references)."""
    state = {"position": np.zeros((steps, 3)), "heading": np.zeros(steps), "velocity": np.zeros((steps, 2)),
             "valid": np.ones(steps), "length": np.full(steps, 4.0), "width": np.full(steps, 2.0)}
    track = {"type": "VEHICLE", "state": state, "metadata": {"type": "VEHICLE"}}
    sd = {"id": "shared", "length": steps, "metadata": {"scenario_id": "shared", "sdc_id": "0", "dataset": "waymo"},
          "tracks": {str(i): track for i in range(tracks)}}
    return pickle.dumps(sd, protocol=4)


@pytest.mark.parametrize("blob, refused", [
    # LONG_BINPUT 0x10000000: the C unpickler sizes its memo to twice that (4.2 GB)
    (b"\x80\x02Nr\x00\x00\x00\x10.", "memo index 268435456 out of order"),
    (b"\x80\x02Np268435456\n.", "memo index 268435456 out of order"),
    # bytearray(3 GiB), 30 bytes: 3.2 GB of zeros
    (b"\x80\x02c__builtin__\nbytearray\n\x8a\x05\x00\x00\x00\xc0\x00\x85R.", "bytearray() of int"),
    (b"\x80\x03cbuiltins\nbytes\n\x8a\x05\x00\x00\x00\xc0\x00\x85R.", "bytes() of int"),
    # BYTEARRAY8 / BINBYTES8 / BINUNICODE8 announcing 3 GiB
    (b"\x80\x05\x96\x00\x00\x00\xc0\x00\x00\x00\x00.", "a length of 3221225472 bytes"),
    (b"\x80\x05\x8e\x00\x00\x00\xc0\x00\x00\x00\x00.", "a length of 3221225472 bytes"),
    (b"\x80\x05\x8d\x00\x00\x00\xc0\x00\x00\x00\x00.", "a length of 3221225472 bytes"),
    # an 8 MB scenario whose 600 tracks share one state of 100,000 steps: 2.25 GB once stacked
    (_shared_state_scenario(600, 100_000), "600 tracks x 100000 steps is more than a file of its size holds"),
])
def test_memory_bombs_are_refused_in_little_memory(tmp_path, blob, refused):
    db = tmp_path / "db"
    db.mkdir()
    (db / "sd_bomb.pkl").write_bytes(blob)
    out = tmp_path / "frames.parquet"
    res = r2s_child("extract", "scenarionet", str(db), "--out", str(out), "--categories", "all")
    assert_refused_small(res, out, refused)


def test_tuples_nested_deeper_than_a_hash_can_follow_are_refused(tmp_path):
    # hashing a tuple recurses in C without a depth check: a million nested tuples as a dict key crash Python
    blob = b"\x80\x02}" + b")" + b"\x85" * 1_000_000 + b"Ns."
    db = tmp_path / "db"
    db.mkdir()
    (db / "sd_deep.pkl").write_bytes(blob)
    out = tmp_path / "frames.parquet"
    res = r2s_child("extract", "scenarionet", str(db), "--out", str(out))
    assert_refused_small(res, out, "tuples nested more than 100 deep")


# --- 3. the allow-list cannot be changed from inside a pickle --------------------------------------------------

_TWO_LOADS = """
import sys
from extractors.base import ExtractError
from extractors.safe_pickle import load_pickle
try:
    load_pickle(sys.argv[1])
    print("loaded")
except ExtractError as exc:
    print("refused:", exc)
d = load_pickle(sys.argv[2])["counts"]
print(d.default_factory.__name__)
"""


@pytest.mark.parametrize("state", [
    b"}X\x07\x00\x00\x00factoryccollections\nOrderedDict\ns",  # {"factory": OrderedDict}: the token's __dict__
    b"N}X\x07\x00\x00\x00factoryccollections\nOrderedDict\ns\x86",  # (None, {"factory": ...}): setattr
])
def test_build_on_a_factory_token_is_refused_and_changes_nothing(tmp_path, state):
    # BUILD on the shared `builtins.int` token (written as __builtin__.long) would make every later
    # defaultdict(int) of the process a defaultdict(OrderedDict): a callable the closed set never allowed
    evil, good = tmp_path / "evil.pkl", tmp_path / "good.pkl"
    evil.write_bytes(b"\x80\x02c__builtin__\nlong\n" + state + b"b.")
    import collections
    good.write_bytes(pickle.dumps({"counts": collections.defaultdict(int, {"a": 1})}, protocol=2))
    out = subprocess.run([sys.executable, "-c", _TWO_LOADS, str(evil), str(good)], capture_output=True, text=True,
                         cwd=ROOT, check=True).stdout.splitlines()
    assert out[0].startswith("refused:") and "__builtin__.long with state set after construction (BUILD)" in out[0]
    assert out[1] == "int"


@pytest.mark.parametrize("key", sorted(_GLOBALS))
def test_every_name_a_pickle_can_reach_is_immutable_and_refuses_state(key):
    token = _GLOBALS[key]
    before = {slot: getattr(token, slot) for cls in type(token).__mro__ for slot in getattr(cls, "__slots__", ())}
    with pytest.raises(RefusedGlobal):
        token.__setstate__({"factory": dict})
    for slot in [*before, "__dict__", "anything"]:
        with pytest.raises(AttributeError):
            setattr(token, slot, dict)
    assert not hasattr(token, "__dict__") and isinstance(token, _Token)
    assert {slot: getattr(token, slot) for slot in before} == before
    # and not through the stdlib's own unpickler either (a BUILD there calls __setstate__)
    with pytest.raises(RefusedGlobal):
        pickle._Unpickler.dispatch[pickle.BUILD[0]](_FakeStack(token, {"factory": dict}))
    assert {slot: getattr(token, slot) for slot in before} == before


class _FakeStack:
    def __init__(self, inst, state):
        self.stack = [inst, state]


# --- 4. valid pickles that are not scenarios: one line and exit 2, never an internal error ---------------------

def _nested_lists(depth: int) -> bytes:
    """A list nested `depth` deep as protocol 2 opcodes (MARK x depth, [], LIST x depth): pickle.dumps itself
    recurses and cannot write it."""
    return b"(" * depth + b"]" + b"l" * depth


def _spliced(sd: dict, where: tuple, blob: bytes) -> bytes:
    """sd pickled (protocol 2, no frames) with the value at `where` replaced by the opcodes `blob`."""
    target = sd
    for key in where[:-1]:
        target = target[key]
    target[where[-1]] = "SPLICE"
    data = pickle.dumps(sd, protocol=2)
    mark = b"X\x06\x00\x00\x00SPLICE"
    assert data.count(mark) == 1
    return data.replace(mark, blob)


SHARED_TUPLES = b")" + b"2\x86" * 64  # t = (); 64 x t = (t, t) (DUP, TUPLE2): 2**64 leaves to hash or print


def _first_track(sd: dict) -> str:
    return next(t for t in sd["tracks"] if t != sd["metadata"]["sdc_id"])


def _case(name: str) -> bytes:
    sd = real_scenario()
    tid, steps = _first_track(sd), int(sd["length"])
    state = sd["tracks"][tid]["state"]
    if name == "ndarray":
        return pickle.dumps(np.arange(3.0), protocol=4)
    if name == "heading-strings":
        state["heading"] = ["1.5"] * steps
    elif name == "heading-huge-int":
        state["heading"] = [10**400] * steps
    elif name == "heading-huge-scalar":
        state["heading"] = 10**400
    elif name == "position-ragged":
        state["position"] = [[1.0, 2.0], [3.0]] * steps
    elif name == "nested-scenario-id":
        return _spliced(sd, ("metadata", "scenario_id"), _nested_lists(100_000))
    elif name == "shared-scenario-id":
        return _spliced(sd, ("metadata", "scenario_id"), SHARED_TUPLES)
    elif name == "shared-track-id":
        sd["tracks"]["SPLICE"] = sd["tracks"].pop(tid)
        data = pickle.dumps(sd, protocol=2)
        return data.replace(b"X\x06\x00\x00\x00SPLICE", SHARED_TUPLES)
    elif name == "length-inf":
        sd["length"] = float("inf")
    elif name == "track-metadata-array":
        sd["tracks"][tid]["metadata"] = np.arange(3.0)
    elif name == "tracks-list":
        sd["tracks"] = list(sd["tracks"].values())
    elif name == "metadata-list":
        sd["metadata"] = [sd["metadata"]]
    return pickle.dumps(sd, protocol=4)


@pytest.mark.parametrize("name, message", [
    ("ndarray", "is not a ScenarioNet scenario (it holds a numpy.ndarray, not a dict)"),
    ("heading-strings", "state.heading is a list that is not an array of numbers"),
    ("heading-huge-int", "state.heading is a list that is not an array of numbers"),
    ("heading-huge-scalar", "state.heading is an int that is not an array of numbers"),
    ("position-ragged", "state.position is a list that is not an array of numbers"),
    ("nested-scenario-id", "metadata.scenario_id is a list, not a scenario name"),
    ("shared-scenario-id", "items spelled out, more than its file's"),
    ("shared-track-id", "items spelled out, more than its file's"),
    ("length-inf", "scenario length is a float, not a number of steps"),
    ("track-metadata-array", "is not a ScenarioNet track"),
    ("tracks-list", "tracks is a list, not a dict of tracks"),
    ("metadata-list", "is not a ScenarioNet scenario (missing 'metadata')"),
])
def test_scenarios_that_are_not_scenarionet_data_exit_2(tmp_path, name, message):
    db = tmp_path / "db"
    db.mkdir()
    (db / "sd_odd.pkl").write_bytes(_case(name))
    out = tmp_path / "frames.parquet"
    res = r2s_child("extract", "scenarionet", str(db), "--out", str(out), "--categories", "all")
    assert_refused_small(res, out, message)


@pytest.mark.parametrize("index, message", [
    (np.arange(4.0), "dataset_mapping.pkl is not a ScenarioNet index (it holds a numpy.ndarray, not a dict)"),
    ({"SPLICE": ""}, "items spelled out, more than its file's"),
    ({"sd_nuscenes_v1.0-mini_scene-0103.pkl": "SPLICE"}, "maps to a tuple, not a folder"),
    ({"sd_nuscenes_v1.0-mini_scene-0103.pkl": [[[]]] * 3}, "maps to a list, not a folder"),
    ({3: ""}, "entry 3 is not the file name of a scenario"),
])
def test_odd_database_indexes_exit_2(tmp_path, index, message):
    db = tmp_path / "db"
    shutil.copytree(SCENARIOS, db)
    data = pickle.dumps(index, protocol=2)
    if message.startswith("maps to a tuple"):  # a small tuple: a value is not hashed
        data = data.replace(b"X\x06\x00\x00\x00SPLICE", b")" + b"2\x86" * 3)
    (db / "dataset_mapping.pkl").write_bytes(data.replace(b"X\x06\x00\x00\x00SPLICE", SHARED_TUPLES))
    out = tmp_path / "frames.parquet"
    res = r2s_child("extract", "scenarionet", str(db), "--out", str(out))
    assert_refused_small(res, out, message)


def test_odd_timestamps_leave_the_timestamp_empty(tmp_path, capsys):
    from tests.support.extract import r2s

    sd = real_scenario()
    sd["metadata"]["ts"] = [10**400] * int(sd["length"])
    db = tmp_path / "db"
    db.mkdir()
    (db / "sd.pkl").write_bytes(pickle.dumps(sd, protocol=4))
    out = tmp_path / "frames.parquet"
    assert r2s(capsys, "extract", "scenarionet", str(db), "--out", str(out)).returncode == 0
    import pandas as pd
    assert pd.read_parquet(out)["timestamp_us"].isna().all()


# any value anywhere a scenario is read from: the reading path gives frames or one ExtractError
_ODD = st.one_of(
    st.none(), st.booleans(), st.integers(-3, 3), st.sampled_from([10**400, -(10**400), 2**63, float("nan"),
                                                                  float("inf"), -0.0, 1e308, "", "x", b"x"]),
    st.text(max_size=3), st.lists(st.integers(0, 2), max_size=3), st.dictionaries(st.text(max_size=2), st.none()),
    st.tuples(st.integers()), st.builds(lambda n, k: np.zeros((n,) * k), st.integers(0, 12), st.integers(0, 3)),
    st.builds(lambda k: np.ones(STEPS, dtype=k), st.sampled_from(["?", "i1", "u8", "f2", "c16"])),
    st.sampled_from([np.float32(2.0), np.int64(-1), np.bool_(False), complex(1, 1)]))


def _places(sd: dict) -> list[tuple]:
    """Every key path of a scenario down to the state arrays (the map features are not read)."""
    tid = _first_track(sd)
    places = [(k,) for k in sd] + [("metadata", k) for k in sd["metadata"]]
    places += [("tracks", tid, k) for k in sd["tracks"][tid]] + [("tracks", tid, "metadata", "type")]
    places += [("tracks", tid, "state", k) for k in sd["tracks"][tid]["state"]]
    places += [("tracks", sd["metadata"]["sdc_id"], "state", k) for k in ("position", "valid", "length")]
    return places


@settings(derandomize=True, max_examples=300, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 10**6), _ODD), min_size=1, max_size=3))
def test_odd_values_anywhere_in_a_scenario_give_frames_or_one_extract_error(changes):
    from extractors.base import ExtractOptions
    from extractors.categories import ALL
    from extractors.scenarionet import scenario_frames

    sd = real_scenario()
    places = _places(sd)
    for i, value in changes:
        where = places[i % len(places)]
        target = sd
        for key in where[:-1]:
            target = target[key] if isinstance(target, dict) and key in target else None
        if isinstance(target, dict):
            target[where[-1]] = value
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a warning is one more line on stderr
            frames = list(scenario_frames(SCENARIO, sd, ExtractOptions(categories=ALL)))
    except ExtractError as exc:
        assert "\n" not in str(exc)
    else:
        assert all(isinstance(r["x"], float) for f in frames for r in f)
