"""Byte mutations of real files for the fuzz tests: a hypothesis strategy of edits and the function applying them."""

from __future__ import annotations

from hypothesis import strategies as st

# (kind, where in the file as a fraction, span as a fraction of max_span, bytes to flip or insert)
EDITS = st.lists(st.tuples(st.sampled_from(["flip", "insert", "delete", "duplicate", "truncate"]),
                           st.floats(0, 1), st.floats(0, 1), st.binary(min_size=1, max_size=8)),
                 min_size=1, max_size=4)


def mutated(original: bytes, edits: list, max_span: int = 64) -> bytes:
    """original with the edits applied in order: bits flipped, bytes inserted, a span deleted or repeated, the
    end cut off."""
    data = bytearray(original)
    for kind, where, span, blob in edits:
        i, n = int(where * len(data)), max(1, int(span * max_span))
        if kind == "flip":
            data[i:i + len(blob)] = bytes(a ^ b for a, b in zip(data[i:i + len(blob)], blob))
        elif kind == "insert":
            data[i:i] = blob
        elif kind == "delete":
            del data[i:i + n]
        elif kind == "duplicate":
            data[i:i] = data[i:i + n]
        else:
            del data[i:]
    return bytes(data)
