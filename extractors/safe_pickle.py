"""Loading ScenarioNet pickles without running code from them.

A pickle can name any importable callable and have it called (os.system, subprocess.Popen, ...). ScenarioNet
files are plain dicts, lists, strings, numbers and numpy arrays, which reference only the globals below
(measured on the shared nuScenes-mini pickles: numpy.core.multiarray._reconstruct, numpy.ndarray,
numpy.dtype; the others are what numpy writes for scalars, for pickle protocols 2 and 5, and under numpy 2's
module names). Anything else is refused before it is imported.
"""

from __future__ import annotations

import io
import os
import pickle
from typing import Any

import numpy as np

from extractors.base import ExtractError

_NUMPY_CORE = {
    "multiarray._reconstruct": ("numpy.core.multiarray", "_reconstruct"),
    "multiarray.scalar": ("numpy.core.multiarray", "scalar"),
    "numeric._frombuffer": ("numpy.core.numeric", "_frombuffer"),
}

ALLOWED_GLOBALS: dict[tuple[str, str], Any] = {
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("builtins", "set"): set,
    ("builtins", "frozenset"): frozenset,
    ("builtins", "complex"): complex,
    ("builtins", "bytearray"): bytearray,
    ("collections", "OrderedDict"): __import__("collections").OrderedDict,
    # protocol 2 writes bytes as _codecs.encode(text, "latin1")
    ("_codecs", "encode"): __import__("codecs").encode,
}
for _short, (_mod, _name) in _NUMPY_CORE.items():
    _obj = getattr(__import__(_mod, fromlist=[_name]), _name)
    _sub, _attr = _short.split(".")
    ALLOWED_GLOBALS[(f"numpy.core.{_sub}", _attr)] = _obj
    ALLOWED_GLOBALS[(f"numpy._core.{_sub}", _attr)] = _obj  # as numpy 2 names them

# numpy dtypes may be pickled by class (numpy.dtypes.Float64DType) under numpy 2.
for _cls in ("Float64DType", "Float32DType", "Int64DType", "Int32DType", "BoolDType", "StrDType", "ObjectDType"):
    if hasattr(np, "dtypes") and hasattr(np.dtypes, _cls):
        ALLOWED_GLOBALS[("numpy.dtypes", _cls)] = getattr(np.dtypes, _cls)

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
