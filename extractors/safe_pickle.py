"""Loading ScenarioNet pickles without running code from them.

A pickle can name any importable callable and have it called (os.system, subprocess.Popen, ...). ScenarioNet
files are plain dicts, lists, strings, numbers and numpy arrays, which reference only the globals below
(measured on the shared nuScenes-mini pickles: numpy.core.multiarray._reconstruct, numpy.ndarray,
numpy.dtype; the others are what numpy writes for scalars, for pickle protocols 2 and 5, and under numpy 2's
module names). Anything else is refused before it is imported.

One callable needs more care: ScenarioNet's converters (metadrive's ScenarioDescription.update_summaries) store
`collections.defaultdict(int)` in every scenario's metadata.number_summary and so in dataset_summary.pkl. A
defaultdict's default factory is itself a global that pickle hands to the constructor (REDUCE), and pickle's
BUILD could set it afterwards. So the factory names resolve to inert tokens, not to the types (int, str, ...
never become callable from a pickle), the defaultdict constructor accepts only a token of the closed set
DEFAULT_FACTORIES, and what it builds refuses BUILD.
"""

from __future__ import annotations

import _compat_pickle
import codecs
import collections
import io
import os
import pickle
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.core import multiarray as _multiarray
from numpy.core import numeric as _numeric

from extractors.base import ExtractError
from storage.regular_files import FileTooLarge, read_regular
from synth.errors import InputError

ALLOWED_GLOBALS: dict[tuple[str, str], Any] = {
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("collections", "OrderedDict"): collections.OrderedDict,
    # protocol 2 writes bytes as _codecs.encode(text, "latin1")
    ("_codecs", "encode"): codecs.encode,
}
# numpy 1 and numpy 2 module names of the array / scalar reconstructors
for _core in ("numpy.core", "numpy._core"):
    ALLOWED_GLOBALS[(f"{_core}.multiarray", "_reconstruct")] = _multiarray._reconstruct
    ALLOWED_GLOBALS[(f"{_core}.multiarray", "scalar")] = _multiarray.scalar
    ALLOWED_GLOBALS[(f"{_core}.numeric", "_frombuffer")] = _numeric._frombuffer
# builtin containers, under Python 3 and (protocol < 3) Python 2 module names
for _mod in ("builtins", "__builtin__"):
    for _t in (set, frozenset, complex, bytearray):
        ALLOWED_GLOBALS[(_mod, _t.__name__)] = _t

MAX_PICKLE_BYTES = 2 * 2**30

# The closed set of default factories a ScenarioNet defaultdict may name.
DEFAULT_FACTORIES = (int, float, str, list, dict, set, tuple)


class RefusedGlobal(InputError, pickle.UnpicklingError):
    pass


@dataclass(frozen=True)
class _FactoryName:
    """What a pickle gets for `builtins.int` & co.: not callable, only accepted as a defaultdict's factory."""

    factory: type


def _python2_name(t: type) -> tuple[str, str]:
    # protocol < 3 writes Python 2 names (int as __builtin__.long, str as __builtin__.unicode)
    return _compat_pickle.REVERSE_NAME_MAPPING.get(("builtins", t.__name__), ("__builtin__", t.__name__))


FACTORY_NAMES: dict[tuple[str, str], _FactoryName] = {}
for _t in DEFAULT_FACTORIES:
    FACTORY_NAMES[("builtins", _t.__name__)] = FACTORY_NAMES[_python2_name(_t)] = _FactoryName(_t)


class _DefaultDict(collections.defaultdict):
    """A defaultdict as unpickled. BUILD would set default_factory to whatever object the pickle put on the stack
    after the constructor checked it, so any BUILD is refused; it pickles again as a plain defaultdict."""

    __slots__ = ()

    def __setstate__(self, state: Any) -> None:
        raise RefusedGlobal("collections.defaultdict with state set after construction (BUILD)")

    def __reduce__(self) -> tuple:
        args = () if self.default_factory is None else (self.default_factory,)
        return collections.defaultdict, args, None, None, iter(self.items())


def _defaultdict(*args: Any) -> _DefaultDict:
    """collections.defaultdict(factory[, items]) with factory None or one of DEFAULT_FACTORIES (as its token)."""
    factory, rest = (args[0], args[1:]) if args else (None, ())
    if isinstance(factory, _FactoryName):
        factory = factory.factory
    elif factory is not None and not any(factory is t for t in DEFAULT_FACTORIES):
        qualname = getattr(factory, "__qualname__", None)
        what = f"{getattr(factory, '__module__', '?')}.{qualname}" if qualname else f"a {type(factory).__name__} object"
        raise RefusedGlobal(f"collections.defaultdict with default factory {what}")
    return _DefaultDict(factory, *rest)


class _RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        if (module, name) == ("collections", "defaultdict"):
            return _defaultdict
        try:
            return ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            pass
        try:
            return FACTORY_NAMES[(module, name)]
        except KeyError:
            raise RefusedGlobal(f"{module}.{name}") from None


def load_pickle(path: str | os.PathLike, max_bytes: int = MAX_PICKLE_BYTES) -> Any:
    """Unpickle a data file through the allow-list; every failure is one ExtractError naming the file."""
    try:  # a regular file only (never a FIFO or /dev/zero), read at most max_bytes + 1 bytes
        data = read_regular(path, max_bytes)
    except FileTooLarge:
        raise ExtractError(f"{path} is larger than the {max_bytes / 2**20:.0f} MB limit") from None
    except OSError as exc:
        raise ExtractError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not data.startswith(b"\x80"):
        raise ExtractError(f"{path} is not a pickle file (it does not start with a pickle protocol header)")
    try:
        return _RestrictedUnpickler(io.BytesIO(data)).load()
    except RefusedGlobal as exc:
        raise ExtractError(
            f"{path}: refused to unpickle: it references {exc}, which is not data a ScenarioNet file may hold"
        ) from None
    except RecursionError:
        raise ExtractError(f"{path}: pickle is nested too deeply") from None
    except MemoryError:
        raise ExtractError(f"{path}: pickle needs more memory than is available") from None
    except Exception as exc:  # corrupt or truncated data raises almost anything from inside pickle / numpy
        raise ExtractError(f"{path} is not a readable pickle ({type(exc).__name__}: {str(exc)[:100]})") from None
