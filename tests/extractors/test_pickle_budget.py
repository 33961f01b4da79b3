"""The safe unpickler's memory bound, explicit (issue 22 item 2; docs/cli.md "Inputs and their bounds"): a pickle
builds at most BUILT_PER_BYTE bytes per byte of its file plus BUILT_BASE, counted as it loads. Before, the bound
was only linear: streams of one-byte opcodes took 236 bytes a byte (empty sets), 120 (nested tuples).

The count must bound what CPython really allocates: checked with tracemalloc (every allocation of Python and
numpy, exactly) on streams of each opcode that builds something, on random opcode programs (hypothesis, the
fuzz's own generator) and on the shipped scenarios, which must also stay well inside the budget. The refusal is
checked through `r2s extract` in a capped child process."""

from __future__ import annotations

import pickle
import struct
import tracemalloc

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from extractors import safe_pickle
from extractors.safe_pickle import BUILT_BASE, BUILT_PER_BYTE, _SafeUnpickler, load_pickle
from synth.errors import InputError
from tests.support.bounded import run_bounded
from tests.support.extract import EXCERPT

# Random opcode programs: the opcodes that build, with arguments of the right shape (the fuzz of
# test_fuzz_pickle.py covers the refusals; these mostly load).
_OP = st.one_of(
    st.sampled_from([b"N", b"\x88", b"}", b"]", b")", b"(", b"\x8f", b"\x94", b"0", b"1", b"2", b"a", b"e", b"s",
                     b"u", b"t", b"\x85", b"\x86", b"\x87", b"\x90", b"\x91", b"l", b"d"]),
    st.integers(0, 255).map(lambda n: b"K" + bytes([n])),
    st.integers(-(2**31), 2**31 - 1).map(lambda n: b"J" + struct.pack("<i", n)),
    st.integers(0, 255).map(lambda n: b"h" + bytes([n])),
    st.binary(max_size=16).map(lambda b: b"C" + bytes([len(b)]) + b),
    st.text(max_size=6).map(lambda t: b"\x8c" + bytes([len(t.encode())]) + t.encode()),
    st.sampled_from([b"\x8c\x08builtins\x8c\x03set\x93", b"\x8c\x08builtins\x8c\tfrozenset\x93",
                     b"\x8c\x08builtins\x8c\tbytearray\x93"]),
    st.just(b"R"),
)

# Streams of one opcode (with what it needs) that each build something, the worst per byte of each kind.
STREAMS = {
    "empty sets": b"\x8f",
    "marks": b"(",
    "empty lists": b"]",
    "empty dicts": b"}",
    "memo entries": b"N\x94",
    "nested tuples": b"N" + b"\x85" * 60 + b"0",
    "pairs": b"NN\x86",
    "ints": b"J\x01\x02\x03\x04",
    "floats": b"G" + struct.pack(">d", 1.5),
    "short strings": b"\x8c\x02ab",
    "wide strings": b"\x8c\x05a\xf0\x9f\x98\x80",  # one character beyond the BMP: 4 bytes a character
    "short bytes": b"C\x02ab",
    "dict items": b"}" + b"(" + b"".join(b"J" + struct.pack("<i", i) + b"N" for i in range(50)) + b"u",
    "set items": b"\x8f(" + b"".join(b"J" + struct.pack("<i", i) for i in range(50)) + b"\x90",
    "frozensets": b"(" + b"".join(b"J" + struct.pack("<i", i) for i in range(20)) + b"\x91",
    "sets from a memo list": b"](" + b"".join(b"J" + struct.pack("<i", i) for i in range(200)) + b"e\x94"
                             + b"\x8c\x08builtins\x8c\x03set\x93\x94" + b"h\x01h\x00\x85R0" * 2000,
}


def _traced(data: bytes) -> tuple[int, int]:
    """(bytes counted, peak bytes allocated) while loading data."""
    unpickler = _SafeUnpickler(data)
    tracemalloc.start()
    try:
        unpickler.load()
    except Exception:  # noqa: BLE001 - refused or malformed (load_pickle makes every one an InputError)
        pass
    finally:
        _, peak = tracemalloc.get_traced_memory()
        tracemalloc.stop()
    return unpickler.spent, peak


@pytest.mark.parametrize("kind", STREAMS)
def test_what_is_counted_bounds_what_is_allocated(kind):
    body = STREAMS[kind]
    data = b"\x80\x04" + body * max(1, 100_000 // len(body)) + b"N."
    spent, peak = _traced(data)
    assert peak <= spent, (kind, peak, spent)  # (the count never goes down: what is freed stays counted)


@settings(max_examples=150, deadline=None, derandomize=True, database=None, suppress_health_check=list(HealthCheck))
@given(st.sampled_from([2, 4]), st.lists(_OP, max_size=40), st.integers(1, 200))
def test_random_opcode_programs_allocate_no_more_than_counted(protocol, ops, repeat):
    spent, peak = _traced(b"\x80" + bytes([protocol]) + b"".join(ops) * repeat + b".")
    assert peak <= spent + 4096, (peak, spent)  # + the exception a refused program raises


def test_real_scenarios_stay_well_inside_the_budget():
    files = sorted((EXCERPT / "scenarionet").glob("*.pkl"))
    assert files
    for f in files:
        data = f.read_bytes()
        spent, peak = _traced(data)
        assert peak <= spent <= BUILT_PER_BYTE * len(data) / 1.5, (f.name, spent / len(data))
        assert load_pickle(f) is not None


def test_a_pickle_over_its_budget_is_refused_with_the_bound(tmp_path, monkeypatch):
    monkeypatch.setattr(safe_pickle, "BUILT_BASE", 2**20)
    path = tmp_path / "sets.pkl"
    path.write_bytes(b"\x80\x04" + b"\x8f" * 50_000 + b".")
    with pytest.raises(InputError, match=r"refused to unpickle: it would build more than 4 MB \(64 bytes a byte"):
        load_pickle(path)


def test_extract_refuses_an_empty_set_bomb_within_its_budget(tmp_path):
    """Before: 236 bytes a byte (a 2 GiB file: 470 GB). Now refused at the budget, one line, exit 2."""
    size = (BUILT_BASE // 256) * 3 // 2  # 1.5 x what the base alone allows at 256 bytes an empty set
    db = tmp_path / "db"
    db.mkdir()
    (db / "sd_bomb.pkl").write_bytes(b"\x80\x04" + b"\x8f" * size + b".")
    out = tmp_path / "frames"
    budget_mb = (BUILT_PER_BYTE * size + BUILT_BASE) / 2**20
    result = run_bounded("extract", "scenarionet", str(db), "--out", str(out), timeout=300,
                         max_rss_mb=budget_mb + 400)  # the budget, the interpreter and the file's bytes
    assert result.killed is None and result.returncode == 2, (result.killed, result.peak_rss_mb, result.stderr)
    (line,) = result.stderr.strip().splitlines()
    assert f"it would build more than {budget_mb:.0f} MB" in line and "sd_bomb.pkl" in line
    assert not out.exists()


def test_pickle_of_plain_data_still_loads():
    data = {"a": [1.5, 2.5], "b": {"c": (1, 2)}}
    assert _SafeUnpickler(pickle.dumps(data, protocol=4)).load() == data
