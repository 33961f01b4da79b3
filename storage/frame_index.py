"""Sets of frame ids at dataset scale: 16 bytes a frame instead of a Python string (~70 bytes) in a set.

A frame id is kept as two independent 64-bit SipHash values (pandas' hash_array under two fixed keys), so the
index is exact for any practical purpose (a false match needs a 128-bit collision: ~10^-24 for 10^7 frames)
and the same in every process (no PYTHONHASHSEED). Used where a run must know "which frames" without holding
them: duplicate frame ids in an input, frames already done (resume), rows of frames not in the input.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

_KEYS = ("r2sgen.frame_id1", "r2sgen.frame_id2")  # hash_array wants exactly 16 bytes per key


def frame_hashes(ids: Sequence[str] | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(hi, lo) uint64 arrays, one pair per id."""
    from pandas.util import hash_array  # pandas loads where ids are hashed, not for `r2s extract --help`

    values = np.asarray(ids, dtype=object)
    return (hash_array(values, hash_key=_KEYS[0], categorize=False),
            hash_array(values, hash_key=_KEYS[1], categorize=False))


class FrameIndex:
    """A sorted, immutable set of frame-id hashes with vectorized membership."""

    def __init__(self, hi: np.ndarray, lo: np.ndarray) -> None:
        order = np.lexsort((lo, hi))
        self.hi, self.lo = hi[order], lo[order]

    @classmethod
    def of(cls, parts: Iterable[tuple[np.ndarray, np.ndarray]]) -> FrameIndex:
        parts = list(parts)
        if not parts:
            return cls(np.zeros(0, np.uint64), np.zeros(0, np.uint64))
        return cls(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]))

    def __len__(self) -> int:
        return len(self.hi)

    @property
    def nbytes(self) -> int:
        return self.hi.nbytes + self.lo.nbytes

    def contains(self, hi: np.ndarray, lo: np.ndarray) -> np.ndarray:
        """Boolean mask: which of the (hi, lo) pairs are in the set."""
        if len(self.hi) == 0 or len(hi) == 0:
            return np.zeros(len(hi), dtype=bool)
        left = np.searchsorted(self.hi, hi, side="left")
        right = np.searchsorted(self.hi, hi, side="right")
        found = np.zeros(len(hi), dtype=bool)
        single = right - left == 1
        at = np.minimum(left, len(self.lo) - 1)
        found[single] = self.lo[at[single]] == lo[single]
        for i in np.flatnonzero(right - left > 1):  # equal hi, different ids: a 64-bit collision (very rare)
            found[i] = bool((self.lo[left[i]:right[i]] == lo[i]).any())
        return found

    def duplicated(self) -> tuple[np.ndarray, np.ndarray]:
        """The (hi, lo) pairs that occur more than once (each once)."""
        same = (self.hi[1:] == self.hi[:-1]) & (self.lo[1:] == self.lo[:-1])
        return self.hi[1:][same], self.lo[1:][same]
