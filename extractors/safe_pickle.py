"""Loading ScenarioNet pickles without running code from them.

A pickle can name any importable callable and have it called (os.system, subprocess.Popen, ...). ScenarioNet
files are plain dicts, lists, strings, numbers and numpy arrays, which reference only the globals below
(measured on the shared nuScenes-mini pickles: numpy.core.multiarray._reconstruct, numpy.ndarray,
numpy.dtype; the others are what numpy writes for scalars, for pickle protocols 2 and 5, and under numpy 2's
module names). Anything else is refused before it is imported.
"""

from __future__ import annotations

import codecs
import collections
import io
import os
import pickle
from typing import Any

import numpy as np
from numpy.core import multiarray as _multiarray
from numpy.core import numeric as _numeric

from extractors.base import ExtractError

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


class RefusedGlobal(pickle.UnpicklingError):
    pass


class _RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str) -> Any:
        try:
            return ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise RefusedGlobal(f"{module}.{name}") from None


def load_pickle(path: str | os.PathLike, max_bytes: int = MAX_PICKLE_BYTES) -> Any:
    """Unpickle a data file through the allow-list; every failure is one ExtractError naming the file."""
    try:
        size = os.path.getsize(path)
        if size > max_bytes:
            raise ExtractError(f"{path} is {size / 2**20:.0f} MB, larger than the {max_bytes / 2**20:.0f} MB limit")
        with open(path, "rb") as fh:
            data = fh.read()
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
