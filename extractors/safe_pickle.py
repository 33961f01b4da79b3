"""Loading ScenarioNet pickles without running code from them, in memory bounded by the file's size.

A pickle is a program for a small stack machine: it can name any importable callable and have it called
(os.system, ...), set the state of any object on its stack (BUILD), and choose memo indices and lengths freely.
ScenarioNet files are plain dicts, lists, strings, numbers and numpy arrays of numbers, so they are read by a
stack machine of our own: pickle's pure-Python Unpickler with every opcode that could do more replaced.

- Names (GLOBAL, STACK_GLOBAL) resolve only to inert tokens of a closed list: numpy's array, scalar and dtype
  reconstructors (measured on the shared nuScenes-mini pickles: numpy.core.multiarray._reconstruct,
  numpy.ndarray, numpy.dtype; the others are what numpy writes for scalars, for protocols 2 and 5, and under
  numpy 2's module names), the builtin containers, `_codecs.encode` (protocol 2 bytes) and the default factories
  of a defaultdict. A token is not callable, has no state and refuses BUILD: nothing a pickle reaches is both
  shared and mutable, so a pickle cannot change what the next one may do.
- REDUCE and NEWOBJ run only a token's own checked constructor. numpy dtypes are plain numbers and bool only
  (kinds b, i, u, f, c): never object, structured, void or string dtypes, whose bytes numpy may take for object
  pointers. An array's or scalar's data must be exactly shape x item size bytes, read from the file.
- BUILD is accepted once, on the two things numpy pickles with a state: a dtype just made, whose state may only
  be numpy's plain one (a byte order), and an array just made by _reconstruct (version 1, a shape, a plain dtype,
  its bytes). Every other BUILD is refused (numpy.dtype's own __setstate__ would take fields, flags and item
  sizes from the pickle: an object field over raw bytes crashed the interpreter).
- Memo indices must be the next free one (what every pickler writes); a length is never more than the bytes
  left; bytearray and bytes are made only from bytes read. Tuples nest at most MAX_TUPLE_DEPTH deep and hold at
  most the file's size in items spelled out (inner tuples counted each time they occur): hashing a tuple recurses
  in C with no depth check (a million nested tuples as a dict key crash the interpreter) and visits every item
  spelled out (64 levels of t = (t, t), a few bytes through the memo, would hash for ever). INST, OBJ, EXT,
  persistent ids and out-of-band buffers, which no ScenarioNet writer uses, are refused.

So whatever the bytes, loading either gives plain data (containers, numbers, strings, numeric arrays, and the
inert tokens) or raises one ExtractError; what it builds is counted as it loads and is at most BUILT_PER_BYTE
bytes per byte of the file plus BUILT_BASE (_SafeUnpickler._spend; docs/cli.md, "Inputs and their bounds").

One constructor needs more care: ScenarioNet's converters (metadrive's ScenarioDescription.update_summaries)
store `collections.defaultdict(int)` in every scenario's metadata.number_summary and so in dataset_summary.pkl.
The factory names resolve to tokens of the closed set DEFAULT_FACTORIES (int, str, ... never become callable
from a pickle), which only the defaultdict constructor accepts.
"""

from __future__ import annotations

import _compat_pickle
import collections
import io
import math
import os
import pickle
import re
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.core import multiarray as _multiarray

from extractors.base import ExtractError
from storage.regular_files import FileTooLarge, read_regular
from synth.errors import InputError

MAX_PICKLE_BYTES = 2 * 2**30
# The memory a pickle may build, counted as it loads (_SafeUnpickler._spend): BUILT_PER_BYTE bytes per byte of
# the file, plus BUILT_BASE. What is counted bounds what CPython allocates from above: for each opcode what it
# makes by itself (OPCODE_BYTES: an object, the allocator's block and its stack slot; an empty set is 216 bytes,
# a memo entry a table slot and its int key), for each byte read DATA_BYTES_PER_BYTE (a str decoded from UTF-8 takes at most 4 bytes
# a byte), for each item put into a set or dict ITEM_BYTES (its table slot, with the table's growth), and what a
# constructor makes from objects already built (a set or dict of n items, bytes, an array's copied data). Real
# ScenarioNet files count 10 to 20 bytes a byte (whole scenarios), up to about 40 (small files); streams of
# one-byte opcodes that each build an object took 236 bytes a byte before this bound (empty sets), 120 (tuples).
BUILT_PER_BYTE = 64
BUILT_BASE = 256 * 2**20
DATA_BYTES_PER_BYTE = 4
ITEM_BYTES = 144
OBJECT_BYTES = 240  # any object a constructor makes, besides its items or data
OPCODE_BYTES = collections.defaultdict(lambda: 80)  # an object of up to 56 bytes, its allocator block, its slot
OPCODE_BYTES.update({op[0]: 256 for op in (pickle.EMPTY_SET, pickle.FROZENSET)})
# a tuple of tuples is also kept with its depth and size (_SafeUnpickler._tuple): an entry and a 3-tuple
OPCODE_BYTES.update({op[0]: 320 for op in (pickle.TUPLE, pickle.TUPLE1, pickle.TUPLE2, pickle.TUPLE3)})
OPCODE_BYTES.update({op[0]: 160 for op in (pickle.MEMOIZE, pickle.PUT, pickle.BINPUT, pickle.LONG_BINPUT)})
OPCODE_BYTES.update({op[0]: 112 for op in (pickle.BINUNICODE, pickle.SHORT_BINUNICODE, pickle.BINUNICODE8,
                                            pickle.UNICODE, pickle.STRING, pickle.BINSTRING, pickle.SHORT_BINSTRING,
                                            pickle.BINBYTES, pickle.SHORT_BINBYTES, pickle.BINBYTES8,
                                            pickle.BYTEARRAY8)})
MAX_TUPLE_DEPTH = 100
MAX_ARRAY_DIMS = 32
# numpy dtype kinds a ScenarioNet file may hold: bool, signed and unsigned ints, floats, complex
PLAIN_KINDS = "biufc"
# The closed set of default factories a ScenarioNet defaultdict may name.
DEFAULT_FACTORIES = (int, float, str, list, dict, set, tuple)


class RefusedGlobal(InputError, pickle.UnpicklingError):
    """A pickle that asks for something that is not data: a name off the list, a dtype or a state numpy would
    take for more than numbers."""


class _Malformed(InputError, pickle.UnpicklingError):
    """A pickle that breaks the rules every pickler follows (memo order, lengths, nesting)."""


class _TooBig(InputError, pickle.UnpicklingError):
    """A pickle that would build more than its budget (BUILT_PER_BYTE x its size + BUILT_BASE)."""


class _Token:
    """What a pickle gets for a name: an inert, immutable value. It has no __dict__, refuses BUILD (here and in
    any other unpickler) and refuses to be pickled, so no pickle can change it for the ones after it."""

    __slots__ = ("module", "name")

    def __init__(self, module: str, name: str) -> None:
        object.__setattr__(self, "module", module)
        object.__setattr__(self, "name", name)

    def __setattr__(self, key: str, value: Any) -> None:
        raise AttributeError(f"{self} is read-only")

    def __delattr__(self, key: str) -> None:
        raise AttributeError(f"{self} is read-only")

    def __setstate__(self, state: Any) -> None:
        raise RefusedGlobal(f"{self} with state set after construction (BUILD)")

    def __reduce__(self) -> Any:
        raise TypeError(f"{self} is a name read from a pickle, not data to pickle again")

    def __repr__(self) -> str:
        return f"{self.module}.{self.name}"


class _Constructor(_Token):
    """A name a pickle may call (REDUCE; NEWOBJ where `newobj`) if it has a `make`, which checks its arguments
    before building; `build` is the one BUILD the object it makes accepts (numpy dtypes and arrays), else None.
    `factory` is the type a defaultdict gets for this name (`builtins.int` & co.: int, str... themselves never
    become callable from a pickle; `builtins.set` is both a factory and protocol 2's set constructor)."""

    __slots__ = ("make", "build", "newobj", "factory")

    def __init__(self, module: str, name: str, make: Callable[..., Any] | None,
                 build: Callable[[Any, Any], None] | None = None, newobj: bool = False,
                 factory: type | None = None) -> None:
        super().__init__(module, name)
        for key, value in (("make", make), ("build", build), ("newobj", newobj), ("factory", factory)):
            object.__setattr__(self, key, value)


def _what(obj: Any) -> str:
    """A short name for an object of a pickle, never its repr (which may be huge or nested without end)."""
    if isinstance(obj, _Token):
        return repr(obj)
    if isinstance(obj, _DefaultDict):
        return "collections.defaultdict"
    return f"{type(obj).__module__}.{type(obj).__qualname__}".removeprefix("builtins.")


# --- numpy: plain numeric dtypes, and arrays and scalars of them -----------------------------------------------

_DTYPE_SPEC = re.compile(r"[biufc?]\d{0,2}")


def _plain_dtype(d: Any) -> np.dtype:
    if not isinstance(d, np.dtype):
        raise _Malformed(f"a {_what(d)} where a numpy dtype belongs")
    if d.kind not in PLAIN_KINDS or d.fields is not None or d.subdtype is not None or d.hasobject or d.flags:
        raise RefusedGlobal(f"numpy.dtype {d.str!r} (only plain numbers and bool may be unpickled)")
    return d


def _make_dtype(spec: Any, align: Any = False, copy: Any = False) -> np.dtype:
    """np.dtype(spec, align, copy) as numpy pickles one ('f8', False, True), for plain numbers only. Always a
    new dtype (copy): its BUILD sets the byte order of this dtype, never of numpy's shared float64."""
    if type(spec) is not str or not _DTYPE_SPEC.fullmatch(spec) or type(align) is not bool or type(copy) is not bool:
        shown = repr(spec) if type(spec) is str and len(spec) < 40 else _what(spec)
        raise RefusedGlobal(f"numpy.dtype {shown} (only plain numbers and bool may be unpickled)")
    return _plain_dtype(np.dtype(spec, False, True))


_DTYPE_STATE_TYPES = (int, str, type(None), type(None), type(None), int, int, int)


def _build_dtype(d: np.dtype, state: Any) -> None:
    """numpy's state of a plain dtype: (3, byte order, None, None, None, -1, -1, 0). Fields, names, a subarray,
    an item size or flags would let the pickle give the dtype object pointers."""
    if (type(state) is not tuple or len(state) != 8 or tuple(map(type, state)) != _DTYPE_STATE_TYPES
            or state[0] != 3 or state[1] not in ("<", ">", "|", "=") or state[5:] != (-1, -1, 0)):
        raise RefusedGlobal("numpy.dtype with a state other than a byte order (BUILD)")
    d.__setstate__(state)


def _shape(shape: Any) -> tuple[int, ...]:
    if type(shape) is not tuple or len(shape) > MAX_ARRAY_DIMS or any(type(n) is not int or n < 0 for n in shape):
        raise _Malformed(f"an array shape that is not a tuple of at most {MAX_ARRAY_DIMS} sizes")
    return shape


def _check_data(data: Any, shape: tuple[int, ...], dtype: np.dtype) -> None:
    if type(data) not in (bytes, bytearray):
        raise _Malformed(f"array data of type {_what(data)}, not bytes")
    if len(data) != math.prod(shape) * dtype.itemsize:
        raise _Malformed(f"array of shape {shape} and {dtype.itemsize}-byte items holds {len(data)} bytes")


def _reconstruct(subtype: Any, shape: Any, typecode: Any) -> np.ndarray:
    """numpy.core.multiarray._reconstruct(ndarray, (0,), b'b'): the empty array numpy's BUILD then fills."""
    if subtype is not _NDARRAY or type(shape) is not tuple or shape != (0,) or type(typecode) is not bytes \
            or typecode != b"b":
        raise _Malformed(f"numpy _reconstruct of {_what(subtype)} other than numpy's own (ndarray, (0,), b'b')")
    return np.empty(0, dtype=np.int8)


def _build_array(a: np.ndarray, state: Any) -> None:
    """ndarray.__setstate__((1, shape, dtype, is_fortran, data)) once, on an array _reconstruct just made."""
    if type(state) is not tuple or len(state) != 5 or type(state[0]) is not int or state[0] != 1:
        raise _Malformed("numpy array state other than (1, shape, dtype, fortran, data)")
    _, shape, dtype, fortran, data = state
    shape, dtype = _shape(shape), _plain_dtype(dtype)
    if type(fortran) is not bool:
        raise _Malformed(f"a numpy array order flag of type {_what(fortran)}")
    _check_data(data, shape, dtype)
    a.__setstate__((1, shape, dtype, fortran, data))


def _frombuffer(buf: Any, dtype: Any, shape: Any, order: Any) -> np.ndarray:
    """numpy.core.numeric._frombuffer (protocol 5, buffer in band): frombuffer(buf, dtype).reshape(shape)."""
    dtype, shape = _plain_dtype(dtype), _shape(shape)
    if type(order) is not str or order not in ("C", "F"):
        raise _Malformed("a numpy array order other than C or F")
    _check_data(buf, shape, dtype)
    return np.frombuffer(buf, dtype=dtype).reshape(shape, order=order)


def _scalar(dtype: Any, data: Any) -> Any:
    """numpy.core.multiarray.scalar(dtype, bytes): a numpy scalar of a plain dtype from exactly its bytes."""
    dtype = _plain_dtype(dtype)
    _check_data(data, (), dtype)
    return _multiarray.scalar(dtype, data)


# --- builtin containers ----------------------------------------------------------------------------------------

def _one_of(what: str, args: tuple, *types: type) -> tuple:
    """args for a builtin constructor: none, or one value of the given types."""
    if len(args) > 1 or (args and type(args[0]) not in types):
        raise _Malformed(f"{what}() of {', '.join(_what(a) for a in args[:3])}")
    return args


def _set(*args: Any) -> set:
    return set(*_one_of("set", args, list, tuple, set, frozenset))


def _frozenset(*args: Any) -> frozenset:
    return frozenset(*_one_of("frozenset", args, list, tuple, set, frozenset))


def _bytes(*args: Any) -> bytes:
    return bytes(*_one_of("bytes", args, bytes, bytearray))  # never bytes(n): n zero bytes from 2 bytes of pickle


def _bytearray(*args: Any) -> bytearray:
    if len(args) == 2 and type(args[0]) is str and type(args[1]) is str and args[1] in ("latin-1", "latin1"):
        return bytearray(args[0].encode("latin-1"))
    return bytearray(*_one_of("bytearray", args, bytes, bytearray))  # never bytearray(n), as bytes


def _complex(*args: Any) -> complex:
    if len(args) > 2 or any(type(a) not in (int, float) for a in args):
        raise _Malformed(f"complex() of {', '.join(_what(a) for a in args[:3])}")
    return complex(*args)


def _encode(text: Any, encoding: Any = "utf-8") -> bytes:
    """_codecs.encode(text, 'latin1'): how protocol 2 writes bytes. No other codec (hex, zlib... would let a
    pickle double a string's size per call)."""
    if type(text) is not str or type(encoding) is not str or encoding not in ("latin1", "latin-1"):
        raise RefusedGlobal(f"_codecs.encode with codec {encoding[:40]!r}" if type(encoding) is str
                            else "_codecs.encode of something other than text")
    return text.encode("latin-1")


def _ordered_dict(*args: Any) -> collections.OrderedDict:
    return collections.OrderedDict(*_one_of("collections.OrderedDict", args, list, tuple, dict))


class _DefaultDict(collections.defaultdict):
    """A defaultdict as unpickled; it pickles again as a plain defaultdict."""

    __slots__ = ()

    def __setstate__(self, state: Any) -> None:
        raise RefusedGlobal("collections.defaultdict with state set after construction (BUILD)")

    def __reduce__(self) -> tuple:
        args = () if self.default_factory is None else (self.default_factory,)
        return collections.defaultdict, args, None, None, iter(self.items())


def _defaultdict(*args: Any) -> _DefaultDict:
    """collections.defaultdict(factory[, items]) with factory None or one of DEFAULT_FACTORIES (as its token)."""
    factory, rest = (args[0], args[1:]) if args else (None, ())
    if type(factory) is _Constructor and factory.factory is not None:
        factory = factory.factory
    elif factory is not None:
        raise RefusedGlobal(f"collections.defaultdict with default factory {_what(factory)}")
    return _DefaultDict(factory, *_one_of("collections.defaultdict", rest, list, tuple, dict))


_NDARRAY = _Token("numpy", "ndarray")
_GLOBALS: dict[tuple[str, str], _Token] = {
    ("numpy", "ndarray"): _NDARRAY,
    ("numpy", "dtype"): _Constructor("numpy", "dtype", _make_dtype, build=_build_dtype),
    ("collections", "OrderedDict"): _Constructor("collections", "OrderedDict", _ordered_dict),
    ("collections", "defaultdict"): _Constructor("collections", "defaultdict", _defaultdict),
    ("_codecs", "encode"): _Constructor("_codecs", "encode", _encode),
}
# numpy 1 and numpy 2 module names of the array / scalar reconstructors
for _core in ("numpy.core", "numpy._core"):
    _GLOBALS[(f"{_core}.multiarray", "_reconstruct")] = _Constructor(
        f"{_core}.multiarray", "_reconstruct", _reconstruct, build=_build_array)
    _GLOBALS[(f"{_core}.multiarray", "scalar")] = _Constructor(f"{_core}.multiarray", "scalar", _scalar)
    _GLOBALS[(f"{_core}.numeric", "_frombuffer")] = _Constructor(f"{_core}.numeric", "_frombuffer", _frombuffer)
# builtin containers, under Python 3 and (protocol < 3) Python 2 module names; complex is written with NEWOBJ
for _mod in ("builtins", "__builtin__"):
    for _name, _make in (("set", _set), ("frozenset", _frozenset), ("bytes", _bytes), ("bytearray", _bytearray),
                         ("complex", _complex)):
        _GLOBALS[(_mod, _name)] = _Constructor(_mod, _name, _make, newobj=_name == "complex")


def _python2_name(t: type) -> tuple[str, str]:
    # protocol < 3 writes Python 2 names (int as __builtin__.long, str as __builtin__.unicode)
    return _compat_pickle.REVERSE_NAME_MAPPING.get(("builtins", t.__name__), ("__builtin__", t.__name__))


for _t in DEFAULT_FACTORIES:
    for _key in (("builtins", _t.__name__), _python2_name(_t)):
        _make = _GLOBALS[_key].make if _key in _GLOBALS else None
        _GLOBALS[_key] = _Constructor(*_key, _make, factory=_t)


# --- the stack machine -----------------------------------------------------------------------------------------

class _Opcodes(dict):
    def __missing__(self, key: int) -> Any:
        raise _Malformed(f"unknown opcode {bytes([key])!r}")


_P = pickle._Unpickler  # the stdlib's pure-Python unpickler: every opcode overridable, nothing run in C
_OPS = _Opcodes(_P.dispatch)
_CONTAINERS = {"list": (list,), "dict": (dict, collections.OrderedDict, _DefaultDict), "set": (set,)}


def _op(code: bytes) -> Callable:
    def register(f: Callable) -> Callable:
        _OPS[code[0]] = f
        return f
    return register


class _SafeUnpickler(_P):
    dispatch = _OPS

    def __init__(self, data: bytes) -> None:
        super().__init__(io.BytesIO(data))
        self._data = io.BytesIO(data)
        self._size = len(data)
        self._pending: dict[int, tuple[Any, Callable[[Any, Any], None]]] = {}  # id -> (object, its one BUILD)
        self._deep: dict[int, tuple[int, int, tuple]] = {}  # id -> (depth, size, tuple) of tuples of tuples
        self.budget = BUILT_PER_BYTE * len(data) + BUILT_BASE
        self.spent = 0

    def _spend(self, n: int) -> None:
        self.spent += n
        if self.spent > self.budget:
            raise _TooBig(f"it would build more than {self.budget / 2**20:.0f} MB ({BUILT_PER_BYTE} bytes a byte of "
                          f"its {self._size:,} bytes, plus {BUILT_BASE / 2**20:.0f} MB)")

    def _read(self, n: int = -1) -> bytes:
        data = self._data.read(n)
        self._spend(DATA_BYTES_PER_BYTE * len(data))
        return data

    def _readline(self) -> bytes:
        data = self._data.readline()
        self._spend(DATA_BYTES_PER_BYTE * len(data))
        return data

    def _made(self, obj: Any) -> Any:
        """Count what a constructor made from objects already built (their own bytes were counted as read)."""
        if isinstance(obj, np.ndarray):
            self._spend(OBJECT_BYTES + obj.nbytes)
        elif isinstance(obj, (bytes, bytearray)):
            self._spend(OBJECT_BYTES + len(obj))
        elif isinstance(obj, (set, frozenset, dict)):
            self._spend(OBJECT_BYTES + ITEM_BYTES * len(obj))
        else:
            self._spend(OBJECT_BYTES)
        return obj

    def load(self) -> Any:
        """pickle's loop, reading the bytes directly: frames only group the opcodes that follow them in the same
        bytes (FRAME below checks its length and goes on), and a read cut short by the end of the data is found
        by the next opcode's read (no STOP, EOFError) or by _bytes_of."""
        self.read, self.readline = self._read, self._readline  # every byte read is counted (_spend)
        self.metastack, self.stack = [], []
        self.append = self.stack.append
        self.proto = 0
        read, dispatch, spend, cost = self.read, self.dispatch, self._spend, OPCODE_BYTES
        try:
            while True:
                key = read(1)
                if not key:
                    raise EOFError
                spend(cost[key[0]])
                dispatch[key[0]](self)
        except pickle._Stop as stop:  # what the stdlib's STOP raises
            return stop.value

    def find_class(self, module: str, name: str) -> Any:
        try:
            return _GLOBALS[(module, name)]
        except (KeyError, TypeError):
            raise RefusedGlobal(f"{module}.{name}"[:200]) from None

    def persistent_load(self, pid: Any) -> Any:
        raise _Malformed("persistent ids are not ScenarioNet data")

    def _call(self, func: Any, args: Any, how: str) -> Any:
        if type(func) is not _Constructor or func.make is None:
            raise _Malformed(f"{how} of {_what(func)}, which is not a constructor a pickle may call")
        if type(args) is not tuple:
            raise _Malformed(f"{how} arguments of type {_what(args)}, not a tuple")
        made = self._made(func.make(*args))
        if func.build is not None:
            self._pending[id(made)] = (made, func.build)
        return made

    def _tuple(self, items: list | tuple) -> tuple:
        """A tuple, with its depth and its size spelled out (items, counting those of inner tuples every time
        they occur): what hashing it costs, in C stack and in time. A tuple of tuples is kept in _deep (alive,
        so that its id stays its own); a flat one's depth is 1 and its size its length."""
        deep, depth, size = self._deep, 0, len(items)
        for x in items:
            if type(x) is tuple and x:
                d, n, _ = deep[id(x)] if id(x) in deep else (1, len(x), None)
                depth, size = max(depth, d), size + n
        t = tuple(items)
        if depth:
            if depth >= MAX_TUPLE_DEPTH:
                raise _Malformed(f"tuples nested more than {MAX_TUPLE_DEPTH} deep")
            if size > self._size:  # only a tuple shared through the memo is larger spelled out than its file
                raise _Malformed(f"a tuple of {size} items spelled out, more than its file's {self._size} bytes")
            deep[id(t)] = (depth + 1, size, t)
        return t

    def _into(self, kind: str) -> Any:
        target = self.stack[-1]
        if type(target) not in _CONTAINERS[kind]:
            raise _Malformed(f"items added to a {_what(target)}, not a {kind}")
        return target

    def _put(self, i: int) -> None:
        if not 0 <= i <= len(self.memo):  # a pickler's memo index is always the next free one (or one it reuses)
            raise _Malformed(f"memo index {i} out of order (memo holds {len(self.memo)})")
        self.memo[i] = self.stack[-1]

    def _bytes_of(self, n: int) -> bytes:
        if n > self._size:
            raise _Malformed(f"a length of {n} bytes in a pickle of {self._size}")
        data = self.read(n)
        if len(data) != n:
            raise _Malformed("pickle data was truncated")
        return data

    @_op(pickle.REDUCE)
    def load_reduce(self) -> None:
        args = self.stack.pop()
        self.stack[-1] = self._call(self.stack[-1], args, "REDUCE")

    @_op(pickle.NEWOBJ)
    def load_newobj(self) -> None:
        args, cls = self.stack.pop(), self.stack.pop()
        if type(cls) is not _Constructor or not cls.newobj or cls.make is None:
            raise _Malformed(f"NEWOBJ of {_what(cls)}")
        self.append(self._call(cls, args, "NEWOBJ"))

    @_op(pickle.NEWOBJ_EX)
    def load_newobj_ex(self) -> None:
        kwargs = self.stack.pop()
        if type(kwargs) is not dict or kwargs:
            raise _Malformed("NEWOBJ_EX with keyword arguments")
        self.load_newobj()

    @_op(pickle.BUILD)
    def load_build(self) -> None:
        state = self.stack.pop()
        inst = self.stack[-1]
        pending = self._pending.pop(id(inst), None)
        if pending is None or pending[0] is not inst:
            raise RefusedGlobal(f"{_what(inst)} with state set after construction (BUILD)")
        pending[1](inst, state)
        self._made(inst)  # an array's BUILD copies its data

    @_op(pickle.INST)
    def load_inst(self) -> None:
        raise _Malformed("INST (a protocol 0 class instance) is not ScenarioNet data")

    @_op(pickle.OBJ)
    def load_obj(self) -> None:
        raise _Malformed("OBJ (a protocol 1 class instance) is not ScenarioNet data")

    @_op(pickle.NEXT_BUFFER)
    def load_next_buffer(self) -> None:
        raise _Malformed("out-of-band buffers are not ScenarioNet data")

    @_op(pickle.READONLY_BUFFER)
    def load_readonly_buffer(self) -> None:
        raise _Malformed("out-of-band buffers are not ScenarioNet data")

    @_op(pickle.TUPLE)
    def load_tuple(self) -> None:
        items = self.pop_mark()  # before self.append: pop_mark rebinds it to the outer stack
        self.append(self._tuple(items))

    def _tuple_of_top(self, n: int) -> None:
        if len(self.stack) < n:
            raise _Malformed(f"a tuple of {n} items from a stack of {len(self.stack)}")
        self.stack[-n:] = [self._tuple(self.stack[-n:])]

    @_op(pickle.TUPLE1)
    def load_tuple1(self) -> None:
        self._tuple_of_top(1)

    @_op(pickle.TUPLE2)
    def load_tuple2(self) -> None:
        self._tuple_of_top(2)

    @_op(pickle.TUPLE3)
    def load_tuple3(self) -> None:
        self._tuple_of_top(3)

    def get_extension(self, code: int) -> None:
        raise _Malformed("extension codes (EXT1, EXT2, EXT4) are not ScenarioNet data")

    @_op(pickle.APPEND)
    def load_append(self) -> None:
        value = self.stack.pop()
        self._into("list").append(value)

    @_op(pickle.APPENDS)
    def load_appends(self) -> None:
        items = self.pop_mark()
        self._into("list").extend(items)

    @_op(pickle.SETITEM)
    def load_setitem(self) -> None:
        value, key = self.stack.pop(), self.stack.pop()
        target = self._into("dict")
        self._spend(ITEM_BYTES)
        target[key] = value

    @_op(pickle.SETITEMS)
    def load_setitems(self) -> None:
        items = self.pop_mark()
        target = self._into("dict")
        if len(items) % 2:
            raise _Malformed("SETITEMS with an odd number of items")
        self._spend(ITEM_BYTES * (len(items) // 2))
        for i in range(0, len(items), 2):
            target[items[i]] = items[i + 1]

    @_op(pickle.ADDITEMS)
    def load_additems(self) -> None:
        items = self.pop_mark()
        target = self._into("set")
        self._spend(ITEM_BYTES * len(items))
        target.update(items)

    @_op(pickle.DICT)
    def load_dict(self) -> None:
        items = self.pop_mark()
        if len(items) % 2:
            raise _Malformed("DICT with an odd number of items")
        self._spend(ITEM_BYTES * (len(items) // 2))
        self.append({items[i]: items[i + 1] for i in range(0, len(items), 2)})

    @_op(pickle.FROZENSET)
    def load_frozenset(self) -> None:
        items = self.pop_mark()
        self._spend(ITEM_BYTES * len(items))
        self.append(frozenset(items))

    @_op(pickle.PUT)
    def load_put(self) -> None:
        self._put(int(self.readline()[:-1]))

    @_op(pickle.BINPUT)
    def load_binput(self) -> None:
        self._put(self.read(1)[0])

    @_op(pickle.LONG_BINPUT)
    def load_long_binput(self) -> None:
        self._put(int.from_bytes(self.read(4), "little"))

    @_op(pickle.BYTEARRAY8)
    def load_bytearray8(self) -> None:
        self.append(bytearray(self._bytes_of(int.from_bytes(self.read(8), "little"))))

    @_op(pickle.BINBYTES8)
    def load_binbytes8(self) -> None:
        self.append(self._bytes_of(int.from_bytes(self.read(8), "little")))

    @_op(pickle.BINUNICODE8)
    def load_binunicode8(self) -> None:
        self.append(str(self._bytes_of(int.from_bytes(self.read(8), "little")), "utf-8", "surrogatepass"))

    @_op(pickle.BINBYTES)
    def load_binbytes(self) -> None:
        self.append(self._bytes_of(int.from_bytes(self.read(4), "little")))

    @_op(pickle.FRAME)
    def load_frame(self) -> None:
        n = int.from_bytes(self._bytes_of(8), "little")
        if n > self._size - self._data.tell():
            raise _Malformed(f"a frame of {n} bytes past the end of the pickle")

    @_op(pickle.BINUNICODE)
    def load_binunicode(self) -> None:
        self.append(str(self._bytes_of(int.from_bytes(self.read(4), "little")), "utf-8", "surrogatepass"))


def load_pickle(path: str | os.PathLike, max_bytes: int = MAX_PICKLE_BYTES) -> Any:
    """Unpickle a data file through the stack machine above; every failure is one ExtractError naming the file."""
    try:  # a regular file only (never a FIFO or /dev/zero), read at most max_bytes + 1 bytes; no more than its
        # size + 1 either, since read(n) reserves n bytes up front (2 GiB of address space for every pickle)
        size = os.stat(path).st_size
        data = read_regular(path, min(size, max_bytes))
    except FileTooLarge:
        why = f"larger than the {max_bytes / 2**20:.0f} MB limit" if size > max_bytes else "growing while it is read"
        raise ExtractError(f"{path} is {why}") from None
    except OSError as exc:
        raise ExtractError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not data.startswith(b"\x80"):
        raise ExtractError(f"{path} is not a pickle file (it does not start with a pickle protocol header)")
    try:
        return _SafeUnpickler(data).load()
    except RefusedGlobal as exc:
        raise ExtractError(
            f"{path}: refused to unpickle: it references {exc}, which is not data a ScenarioNet file may hold"
        ) from None
    except RecursionError:
        raise ExtractError(f"{path}: pickle is nested too deeply") from None
    except MemoryError:
        raise ExtractError(f"{path}: pickle needs more memory than is available") from None
    except _Malformed as exc:
        raise ExtractError(f"{path} is not a readable pickle ({_one_line(exc, 200)})") from None
    except _TooBig as exc:
        raise ExtractError(f"{path}: refused to unpickle: {exc}") from None
    except Exception as exc:  # corrupt or truncated data raises almost anything from inside pickle / numpy
        raise ExtractError(f"{path} is not a readable pickle ({type(exc).__name__}: {_one_line(exc, 100)})") from None


def _one_line(exc: BaseException, limit: int) -> str:
    return " ".join(str(exc).split())[:limit]
