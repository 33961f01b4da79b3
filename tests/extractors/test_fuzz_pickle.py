"""Fuzzing the safe unpickler's opcode stream (issue 22): random opcode programs, the shipped ScenarioNet pickles
mutated, and pickles of random plain data. Every input must load to plain data or raise the project's InputError:
never another exception, never a crash, never more than a little memory or a few seconds.

The examples run in a child process (the test below starts it), so that a crash is the child's exit status and
not the end of the test run; the child caps its own address space (a bomb that gets past the bounds becomes a
MemoryError, which the fuzz reports) and each example has an alarm (a CPU bomb fails instead of hanging).
Derandomized and bounded (max_examples), so CI runs the same few seconds of cases every time."""

from __future__ import annotations

import collections
import io
import pickle
import resource
import signal
import struct
import subprocess
import sys

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.support import ROOT
from tests.support.extract import EXCERPT
from tests.support.mutate import EDITS, mutated

SEEDS = [EXCERPT / "scenarionet" / name for name in
         ("dataset_mapping.pkl", "dataset_summary.pkl", "sd_nuscenes_v1.0-mini_scene-0796.pkl")]
HEADROOM = 2**30  # address space the child may add to what it holds after its imports
ALARM_S = 20
PEAK_MB = 500
REFUSED = object()


def test_the_unpickler_fuzz_finds_nothing_in_a_child_process():
    proc = subprocess.run([sys.executable, "-c", "from tests.extractors.test_fuzz_pickle import main; main()"],
                          capture_output=True, text=True, cwd=ROOT, timeout=600)
    assert proc.returncode == 0, (proc.returncode, proc.stdout[-3000:], proc.stderr[-3000:])
    assert "fuzzed" in proc.stdout


# --- what the child runs -----------------------------------------------------------------------------------------

def main() -> None:
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    with open("/proc/self/statm") as fh:
        vm = int(fh.read().split()[0]) * resource.getpagesize()
    resource.setrlimit(resource.RLIMIT_AS, (vm + HEADROOM, hard))
    counts = collections.Counter()
    for name, fuzz in (("opcode programs", fuzz_opcode_programs), ("mutated real pickles", fuzz_mutated_pickles),
                       ("plain data", fuzz_plain_data)):
        fuzz(counts)
        print(f"fuzzed {name}", flush=True)
    with open("/proc/self/status") as fh:  # VmHWM: this process's own peak (ru_maxrss keeps its parent's)
        peak = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM")) / 1024
    print(dict(counts), f"peak {peak:.0f} MB")
    assert peak < PEAK_MB, peak


def _on_alarm(signum, frame):
    raise TimeoutError(f"an example ran more than {ALARM_S} s")


def load_or_refuse(data: bytes, counts: collections.Counter):
    """load_pickle on data: plain data, or one InputError of one line that is not about memory."""
    import tempfile

    from extractors.safe_pickle import load_pickle
    from synth.errors import InputError

    with tempfile.NamedTemporaryFile(suffix=".pkl") as fh:
        fh.write(data)
        fh.flush()
        signal.signal(signal.SIGALRM, _on_alarm)
        signal.alarm(ALARM_S)
        try:
            value = load_pickle(fh.name)
        except InputError as exc:
            message = str(exc)
            assert "\n" not in message and "more memory" not in message, message
            counts["refused"] += 1
            return REFUSED
        finally:
            signal.alarm(0)
    assert_plain(value)
    counts["loaded"] += 1
    return value


def assert_plain(value) -> None:
    """Only containers, numbers, strings, numpy arrays / scalars / dtypes of plain numbers, and the inert tokens."""
    from extractors.safe_pickle import PLAIN_KINDS, _Token

    atoms = (type(None), bool, int, float, complex, str, bytes, bytearray, _Token)
    seen, todo = set(), [value]
    while todo:
        v = todo.pop()
        if id(v) in seen:
            continue
        seen.add(id(v))
        if isinstance(v, (list, tuple, set, frozenset)):
            todo.extend(v)
        elif isinstance(v, dict):  # dict, OrderedDict, defaultdict
            assert type(v) is dict or type(v).__module__ in ("collections", "extractors.safe_pickle"), type(v)
            todo.extend(v.keys())
            todo.extend(v.values())
        elif isinstance(v, (np.ndarray, np.generic, np.dtype)):
            d = v if isinstance(v, np.dtype) else v.dtype
            assert d.kind in PLAIN_KINDS and not d.hasobject and d.fields is None, d
        else:
            assert isinstance(v, atoms), type(v)


# opcode programs: opcodes with arguments of the right shape, values chosen to hit the bounds
def _u(n: int, fmt: str) -> bytes:
    return struct.pack(fmt, n)


_NAMES = [("numpy", "dtype"), ("numpy", "ndarray"), ("numpy.core.multiarray", "_reconstruct"),
          ("numpy.core.multiarray", "scalar"), ("numpy.core.numeric", "_frombuffer"), ("_codecs", "encode"),
          ("collections", "OrderedDict"), ("collections", "defaultdict"), ("__builtin__", "long"),
          ("builtins", "set"), ("builtins", "bytearray"), ("builtins", "complex"), ("os", "system"),
          ("builtins", "eval"), ("numpy", "frombuffer")]
_SIZES = st.sampled_from([0, 1, 2, 3, 8, 255, 2**16, 2**31 - 1, 2**32 - 1, 0x10000000])
_TEXT = st.sampled_from(["f8", "O8", "V8", "b1", "i4", "latin1", "hex", "x", "", "U3", "<", "|"])
_OP = st.one_of(
    st.sampled_from([b"N", b"\x88", b"\x89", b"}", b"]", b")", b"(", b"\x8f", b"\x94", b"0", b"1", b"2", b"a",
                     b"e", b"s", b"u", b"t", b"\x85", b"\x86", b"\x87", b"R", b"b", b"\x81", b"\x92", b"\x93",
                     b"\x90", b"\x91", b"l", b"d", b"\x97", b"\x98", b"Q", b"o", b"."]),
    st.integers(0, 255).map(lambda n: b"K" + bytes([n])),
    st.integers(-(2**31), 2**31 - 1).map(lambda n: b"J" + _u(n, "<i")),
    st.floats(allow_nan=True).map(lambda f: b"G" + struct.pack(">d", f)),
    _SIZES.map(lambda n: b"r" + _u(n, "<I")), _SIZES.map(lambda n: b"j" + _u(n, "<I")),
    st.integers(0, 255).map(lambda n: b"q" + bytes([n])), st.integers(0, 255).map(lambda n: b"h" + bytes([n])),
    _SIZES.map(lambda n: f"p{n}\n".encode()), _SIZES.map(lambda n: f"g{n}\n".encode()),
    _SIZES.map(lambda n: b"\x96" + _u(n, "<Q")), _SIZES.map(lambda n: b"\x8e" + _u(n, "<Q")),
    _SIZES.map(lambda n: b"\x8d" + _u(n, "<Q")), _SIZES.map(lambda n: b"\x95" + _u(n, "<Q")),
    _SIZES.map(lambda n: b"\x8a\x05" + _u(n, "<Q")[:5]),
    st.binary(max_size=16).map(lambda b: b"C" + bytes([len(b)]) + b),
    st.binary(max_size=24).map(lambda b: b"B" + _u(len(b), "<I") + b),
    _TEXT.map(lambda s: b"\x8c" + bytes([len(s)]) + s.encode()),
    st.sampled_from(_NAMES).map(lambda m: f"c{m[0]}\n{m[1]}\n".encode()),
    st.sampled_from(_NAMES).map(lambda m: b"\x8c" + bytes([len(m[0])]) + m[0].encode() + b"\x8c"
                                + bytes([len(m[1])]) + m[1].encode() + b"\x93"),
)


def fuzz_opcode_programs(counts: collections.Counter) -> None:
    @settings(derandomize=True, max_examples=600, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.sampled_from([2, 3, 4, 5]), st.lists(_OP, max_size=40))
    def run(protocol, ops):
        load_or_refuse(b"\x80" + bytes([protocol]) + b"".join(ops) + b".", counts)
    run()


def fuzz_mutated_pickles(counts: collections.Counter) -> None:
    seeds = [p.read_bytes() for p in SEEDS]

    @settings(derandomize=True, max_examples=300, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(st.sampled_from(range(len(seeds))), EDITS)
    def run(seed, edits):
        load_or_refuse(mutated(seeds[seed], edits), counts)
    run()


_ARRAYS = st.builds(
    lambda kind, shape, fortran: (np.asfortranarray if fortran else np.ascontiguousarray)(
        np.arange(int(np.prod(shape))).reshape(shape).astype(kind)),
    st.sampled_from(["?", "i1", "u2", ">i4", "<i8", "f2", "f4", ">f8", "c16"]),
    st.lists(st.integers(0, 3), max_size=3).map(tuple), st.booleans())
_PLAIN = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(), st.floats(allow_nan=False), st.text(max_size=8),
              st.binary(max_size=8), st.complex_numbers(allow_nan=False), _ARRAYS,
              st.sampled_from([np.float32(1.5), np.int64(-3), np.bool_(True)])),
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.tuples(inner, inner),
        st.dictionaries(st.text(max_size=4), inner, max_size=4),
        st.dictionaries(st.text(max_size=4), inner, max_size=3).map(
            lambda d: collections.defaultdict(int, d)),
        st.dictionaries(st.text(max_size=4), inner, max_size=3).map(collections.OrderedDict),
        st.frozensets(st.integers(), max_size=3), st.sets(st.text(max_size=3), max_size=3)),
    max_leaves=12)


def _same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return (isinstance(b, np.ndarray) and a.dtype == b.dtype and a.shape == b.shape
                and a.flags.f_contiguous == b.flags.f_contiguous and np.array_equal(a, b))
    if isinstance(a, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, dict):
        return (isinstance(b, dict) and list(a) == list(b) and all(_same(a[k], b[k]) for k in a)
                and getattr(a, "default_factory", None) is getattr(b, "default_factory", None))
    return type(a) is type(b) and (a == b or (a != a and b != b))


def fuzz_plain_data(counts: collections.Counter) -> None:
    @settings(derandomize=True, max_examples=300, deadline=None, database=None,
              suppress_health_check=list(HealthCheck))
    @given(_PLAIN, st.sampled_from([2, 3, 4, 5]))
    def run(value, protocol):
        data = pickle.dumps(value, protocol=protocol)
        back = load_or_refuse(data, counts)
        assert back is not REFUSED, "plain data was refused"
        assert _same(pickle.load(io.BytesIO(data)), back)  # what the stdlib's unpickler gives
    run()
