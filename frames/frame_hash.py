"""The content hash of a frame: what a stored program was computed from (docs/cli.md, "When a stored program is
reused").

`r2s run` keeps a frame's program across runs only while the frame's rows are the same; the hash of the rows is
written beside the program (the programs column `frame_hash`) and compared on resume. It covers what synthesis
reads of a frame, and nothing else:

- the columns HASHED_COLUMNS, in that order; an optional column a file lacks hashes as nulls, so a file with a
  `speed` column of nulls and one without it hash alike;
- the rows in the order they are stored: synthesis declares entities in row order and its program can depend
  on it (reordering a frame's rows recomputes it), so the canonical order is the stored one;
- every float as the IEEE-754 binary64 bit pattern of its value (float32 columns widened exactly, -0.0 and 0.0
  apart), a null or NaN as the canonical quiet NaN (synthesis reads both as "not given"); every string as the
  first 8 bytes of its BLAKE2b digest (UTF-8), a null as the same NaN pattern;
- how Parquet stores them does not count: encodings, dictionaries, row groups, compression, file names.

The hash is two 64-bit lanes (32 hex digits). A row is a chain of SplitMix64 finalizers over its values, salted
with its position in the frame; a frame is the sum of its rows (mod 2^64) and its row count, finalized per lane.
The sum lets a frame continue from one row group into the next (streaming), and vectorizes over a row group: the
work is a few dozen numpy operations per row, no Python per row or per frame. It is a checksum against stale
results, not a cryptographic commitment: whoever writes the frames file also chooses what is synthesized.

With a road (`r2s run --lanes`, whose workers read each frame with its road columns and the map it names:
`Coverage.with_road`), a frame is also what it reads of its road, and the chain goes on over ROAD_HASHED_COLUMNS
after HASHED_COLUMNS: the frame's world (synth.world: the ego row's source, scene, frame_index, map_x, map_y,
map_heading), the lane facts, and the map each row names *by its content*. There a bool is 0 or 1, an integer is
hashed as the binary64 bits of its value, a list (`lanes`) is the finalizer of (the sum of its elements' words,
each mixed with its position) xor mix(its length xor the second seed), and a row's `map_id` is the first 8 bytes of
BLAKE2b over the id (UTF-8), a zero byte and the map's content digest (frames.maps.map_digests: 16 bytes over
the map's rows as stored beside the frames; nothing when the maps hold no such map). Moving a lane, a lane fact, or
the map a frame names recomputes the frame; a map no frame names does not count.
"""

from __future__ import annotations

import hashlib
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from frames.schema import FramesError
from storage.frame_index import FrameIndex, frame_hashes

HASHED_COLUMNS = ("entity_id", "type", "x", "y", "heading", "length", "width", "speed", "pos_sigma",
                  "heading_sigma", "speed_sigma")
# What synthesis reads of a frame besides, with its road (synth.world's pose and names, the lane facts, the map).
ROAD_HASHED_COLUMNS = ("source", "scene", "frame_index", "map_id", "map_x", "map_y", "map_heading", "lanes", "lane",
                       "in_intersection", "on_crosswalk", "off_road")
HASH_CHARS = 32  # two 64-bit lanes in hex

_NULL = np.uint64(0x7FF8000000000000)  # the canonical quiet NaN's bits: a null, a NaN, an absent column
_SEEDS = (np.uint64(0x72327367656E2E66), np.uint64(0x6672616D652E6831))  # "r2sgen.f", "frame.h1"
_M1, _M2 = np.uint64(0xBF58476D1CE4E5B9), np.uint64(0x94D049BB133111EB)


def _mix(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finalizer (a bijection of uint64), on a fresh array."""
    x = x ^ (x >> np.uint64(30))
    x *= _M1
    x ^= x >> np.uint64(27)
    x *= _M2
    x ^= x >> np.uint64(31)
    return x


def _mix_into(h: np.ndarray, values: np.ndarray, scratch: np.ndarray) -> None:
    """h = _mix(h ^ values), in place (one link of a row's chain: no temporary array per operation)."""
    np.bitwise_xor(h, values, out=h)
    for shift, factor in ((30, _M1), (27, _M2), (31, None)):
        np.right_shift(h, np.uint64(shift), out=scratch)
        np.bitwise_xor(h, scratch, out=h)
        if factor is not None:
            np.multiply(h, factor, out=h)


@dataclass(frozen=True)
class Coverage:
    """What a frame's hash covers: its columns, in order, and with a road each map's content digest by map id
    (frames.maps.map_digests; a map id the maps lack is absent or None)."""

    columns: tuple[str, ...] = HASHED_COLUMNS
    maps: Mapping[str, bytes | None] | None = field(default=None, hash=False)

    @classmethod
    def with_road(cls, maps: Mapping[str, bytes | None]) -> Coverage:
        return cls(HASHED_COLUMNS + ROAD_HASHED_COLUMNS, maps)

    def map_word(self, map_id: str) -> bytes:
        return map_id.encode("utf-8") + b"\0" + (self.maps.get(map_id) or b"")


PLAIN = Coverage()


def _word(text: bytes) -> int:
    return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "little")


def _string_values(arr: pa.Array, encode=lambda s: s.encode("utf-8")) -> np.ndarray:
    """8 bytes of BLAKE2b per distinct string (dictionary-encoded: the work is per distinct value); `encode`: the
    bytes hashed for a string."""
    if not pa.types.is_dictionary(arr.type):
        arr = pc.dictionary_encode(arr)
    words = np.array([_word(encode(s)) for s in arr.dictionary.to_pylist()] + [int(_NULL)], dtype=np.uint64)
    codes = arr.indices.fill_null(len(words) - 1).to_numpy(zero_copy_only=False).astype(np.int64)
    return words[codes]


def _float_values(arr: pa.Array) -> np.ndarray:
    values = np.asarray(arr.to_numpy(zero_copy_only=False), dtype=np.float64)  # nulls come as NaN
    bits = values.view(np.uint64).copy()
    bits[np.isnan(values)] = _NULL
    return bits


def _bool_values(arr: pa.Array) -> np.ndarray:
    values = pc.fill_null(arr.cast(pa.uint8()), 0).to_numpy(zero_copy_only=False).astype(np.uint64)
    values[np.asarray(arr.is_null())] = _NULL
    return values


def _list_values(arr: pa.Array) -> np.ndarray:
    """Per list: mix(sum of mix(word of element k ^ mix(k + 1)) ^ mix(length ^ seed 1)); a null list is null.
    Vectorized over all elements at once (running sums: a list's sum is the difference of two); the mixes of
    positions and lengths looked up in tables as long as the longest list."""
    lengths = pc.fill_null(pc.list_value_length(arr), 0).to_numpy(zero_copy_only=False).astype(np.int64)
    ends = np.cumsum(lengths)
    counts = np.arange(int(lengths.max()) + 1 if len(lengths) else 1, dtype=np.uint64)
    position = np.arange(int(ends[-1]) if len(ends) else 0, dtype=np.int64) - np.repeat(ends - lengths, lengths)
    salted = _mix(_values(arr.flatten()) ^ _mix(counts + np.uint64(1))[position])
    running = np.concatenate((np.zeros(1, np.uint64), np.cumsum(salted, dtype=np.uint64)))  # wraps mod 2^64
    values = _mix((running[ends] - running[ends - lengths]) ^ _mix(counts ^ _SEEDS[1])[lengths])
    values[np.asarray(arr.is_null())] = _NULL
    return values


def _values(arr: pa.Array, encode=None) -> np.ndarray:
    """The 64-bit word of each value of a column, by its type (a road column's type is the file's own)."""
    kind = arr.type.value_type if pa.types.is_dictionary(arr.type) else arr.type
    if pa.types.is_string(kind) or pa.types.is_large_string(kind):
        return _string_values(arr) if encode is None else _string_values(arr, encode)
    if pa.types.is_boolean(kind):
        return _bool_values(arr)
    if pa.types.is_list(kind) or pa.types.is_large_list(kind):
        return _list_values(arr)
    if pa.types.is_integer(kind) or pa.types.is_floating(kind):
        return _float_values(arr)
    raise FramesError(f"a column holds values of type {kind}, which no frames column has")


def row_chain(table: pa.Table, coverage: Coverage = PLAIN) -> np.ndarray:
    """The position-free hash of each row: the chain of its values over coverage.columns."""
    h = np.full(table.num_rows, _SEEDS[0], dtype=np.uint64)
    scratch = np.empty_like(h)
    for name in coverage.columns:
        if name not in table.column_names:
            values = np.full(table.num_rows, _NULL, dtype=np.uint64)
        else:
            column = table.column(name)
            arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
            try:
                values = _values(arr, coverage.map_word if name == "map_id" and coverage.maps is not None else None)
            except FramesError as exc:
                raise FramesError(f"column {name}: {exc}") from None
        _mix_into(h, values, scratch)
    return h


class RowBytes:
    """The rows of a table as bytes, column by column, to digest any run of its rows (the content digest of a map:
    frames.maps.map_digests): a column is its name and type, then its pieces, the bytes of each row's values in
    each piece: validity, list lengths, then the values (numbers as 8 bytes, strings as their lengths and UTF-8
    bytes), however the table stores them (slices, chunks, dictionaries). Built once for a table; digesting rows
    a to b is a few buffer slices a column, so a file of many maps is digested map by map without a pass each."""

    def __init__(self, table: pa.Table) -> None:
        self.columns = []
        for name in table.column_names:
            column = table.column(name)
            pieces: list[tuple[np.ndarray, np.ndarray]] = []
            _pieces(column.combine_chunks(), np.arange(table.num_rows + 1, dtype=np.int64), pieces)
            self.columns.append((f"\0{name}:{column.type}".encode(), pieces))

    def digest(self, h, a: int, b: int) -> None:
        """Feed a hashlib object rows a to b (not included)."""
        for head, pieces in self.columns:
            h.update(head)
            for data, bounds in pieces:
                h.update(data[bounds[a]: bounds[b]])


def _pieces(arr: pa.Array, rows: np.ndarray, out: list) -> None:
    """Append (data, bounds) for each piece of a column: row i of the table is data[bounds[rows[i]]:
    bounds[rows[i + 1]]]; `rows`: where each row of the table starts among this array's items."""
    if pa.types.is_dictionary(arr.type):
        arr = arr.dictionary.take(arr.indices)
    out.append((np.asarray(arr.is_valid(), dtype=np.uint8), rows))
    kind = arr.type
    if pa.types.is_list(kind) or pa.types.is_large_list(kind):
        lengths = pc.fill_null(pc.list_value_length(arr), 0).to_numpy(zero_copy_only=False).astype(np.int64)
        out.append((lengths, rows))
        _pieces(arr.flatten(), np.concatenate(([0], np.cumsum(lengths)))[rows], out)
    elif pa.types.is_string(kind) or pa.types.is_large_string(kind):
        text = pc.fill_null(arr, "")
        if len(text) == 0:
            out.append((np.zeros(0, np.int64), rows))
            out.append((np.zeros(0, np.uint8), np.zeros_like(rows)))
            return
        offsets = np.frombuffer(text.buffers()[1], np.int64 if pa.types.is_large_string(kind) else np.int32)
        offsets = offsets[text.offset: text.offset + len(text) + 1].astype(np.int64)
        out.append((np.diff(offsets), rows))
        data = text.buffers()[2]
        out.append((np.frombuffer(data, np.uint8) if data is not None else np.zeros(0, np.uint8), offsets[rows]))
    elif pa.types.is_boolean(kind) or pa.types.is_integer(kind) or pa.types.is_floating(kind):
        values = pc.fill_null(arr, False if pa.types.is_boolean(kind) else 0).to_numpy(zero_copy_only=False)
        out.append((np.asarray(values, dtype=np.float64 if pa.types.is_floating(kind) else np.int64), rows))
    else:
        raise FramesError(f"a column holds values of type {kind}, which no map column has")


def _row_lanes(chain: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    salted = chain ^ _mix(positions.astype(np.uint64) + np.uint64(1))
    return _mix(salted ^ _SEEDS[0]), _mix(salted ^ _SEEDS[1])


def _finish(sum0: np.ndarray, sum1: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = rows.astype(np.uint64)
    return _mix(sum0 ^ _mix(n ^ _SEEDS[0])), _mix(sum1 ^ _mix(n ^ _SEEDS[1]))


def frame_hashes_of(table: pa.Table, starts: np.ndarray, coverage: Coverage = PLAIN) -> tuple[np.ndarray, np.ndarray]:
    """(lane0, lane1) of each frame of a table of whole frames; frame i is rows starts[i] .. starts[i+1]."""
    n = table.num_rows
    if len(starts) == 0:
        return np.zeros(0, np.uint64), np.zeros(0, np.uint64)
    lengths = np.diff(np.append(starts, n))
    positions = np.arange(n, dtype=np.int64) - np.repeat(starts, lengths)
    lane0, lane1 = _row_lanes(row_chain(table, coverage), positions)
    return _finish(np.add.reduceat(lane0, starts), np.add.reduceat(lane1, starts), lengths)


def to_hex(lane0: np.ndarray, lane1: np.ndarray) -> list[str]:
    return [f"{int(a):016x}{int(b):016x}" for a, b in zip(lane0, lane1)]


def from_hex(column: pa.ChunkedArray | pa.Array) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(lane0, lane1, valid) of a column of stored hashes; a null or malformed value is not valid (its frame is
    recomputed). Vectorized: the digits are read as bytes, never one Python int per row."""
    arr = column.combine_chunks() if isinstance(column, pa.ChunkedArray) else column
    n = len(arr)
    if n == 0:
        return np.zeros(0, np.uint64), np.zeros(0, np.uint64), np.zeros(0, bool)
    arr = arr.cast(pa.binary())
    valid = np.asarray(pc.fill_null(pc.equal(pc.binary_length(arr), HASH_CHARS), False).to_numpy(
        zero_copy_only=False), dtype=bool)
    text = pc.if_else(pa.array(valid), arr, pa.scalar(b"0" * HASH_CHARS, pa.binary()))
    offsets = np.frombuffer(text.buffers()[1], dtype=np.int32)[text.offset: text.offset + n + 1]
    raw = np.frombuffer(text.buffers()[2], dtype=np.uint8)[offsets[0]: offsets[-1]].reshape(n, HASH_CHARS)
    digit = raw.astype(np.int64) - 48
    letter = (raw | 0x20).astype(np.int64) - 87
    nibbles = np.where((raw >= 48) & (raw <= 57), digit, np.where((letter >= 10) & (letter <= 15), letter, -1))
    valid &= (nibbles >= 0).all(axis=1)
    nibbles = np.where(nibbles < 0, 0, nibbles).astype(np.uint64)
    shifts = (np.uint64(4) * np.arange(15, -1, -1, dtype=np.uint64))
    lane0 = np.bitwise_or.reduce(nibbles[:, :16] << shifts, axis=1)
    lane1 = np.bitwise_or.reduce(nibbles[:, 16:] << shifts, axis=1)
    return lane0, lane1, valid


class FrameHasher:
    """frame_hashes_of for a stream of tables (row groups) of one part after another, where a frame may continue
    from one table into the next. `keys()`: each frame's hash folded into its frame id's (storage.frame_index),
    as a FrameIndex: "this frame with these rows"."""

    def __init__(self, keep_lanes: bool = False, coverage: Coverage = PLAIN) -> None:
        self.coverage = coverage
        self.columns = coverage.columns  # what the tables fed must hold (those a file has; the rest hash as null)
        self._keys: list[tuple[np.ndarray, np.ndarray]] = []
        self._open: tuple[str, np.uint64, np.uint64, int] | None = None  # (id, sum0, sum1, rows so far)
        # With keep_lanes, each frame's hash itself too (32 bytes a frame), for hashes over several frames
        # (r2s run --window): lanes() looks them up by frame id.
        self._lanes: list[tuple[np.ndarray, ...]] | None = [] if keep_lanes else None

    def feed(self, table: pa.Table, starts: np.ndarray, ids: np.ndarray) -> None:
        """A table and its frames (first row and id of each run of equal frame ids)."""
        n = table.num_rows
        if n == 0:
            return
        lengths = np.diff(np.append(starts, n))
        positions = np.arange(n, dtype=np.int64) - np.repeat(starts, lengths)
        continues = self._open is not None and ids[0] == self._open[0]
        if continues:
            positions[: lengths[0]] += self._open[3]
        lane0, lane1 = _row_lanes(row_chain(table, self.coverage), positions)
        sum0, sum1 = np.add.reduceat(lane0, starts), np.add.reduceat(lane1, starts)
        ids, lengths = np.asarray(ids, dtype=object), lengths.astype(np.int64)
        if continues:
            _, s0, s1, rows = self._open
            sum0[:1] += s0  # array arithmetic: wraps mod 2^64 (a scalar sum would warn)
            sum1[:1] += s1
            lengths[0] += rows
        elif self._open is not None:
            self.end_part()
        self._emit(ids[:-1], sum0[:-1], sum1[:-1], lengths[:-1])
        self._open = (str(ids[-1]), sum0[-1], sum1[-1], int(lengths[-1]))

    def end_part(self) -> None:
        if self._open is not None:
            fid, s0, s1, rows = self._open
            self._open = None
            self._emit(np.array([fid], dtype=object), np.array([s0], np.uint64), np.array([s1], np.uint64),
                       np.array([rows], np.int64))

    def _emit(self, ids, sum0, sum1, lengths) -> None:
        if len(ids):
            id_hi, id_lo = frame_hashes(ids)
            lane0, lane1 = _finish(sum0, sum1, lengths)
            self._keys.append(frame_keys(id_hi, id_lo, lane0, lane1))
            if self._lanes is not None:
                self._lanes.append((id_hi, id_lo, lane0, lane1))

    def lanes(self, ids) -> tuple[np.ndarray, np.ndarray]:
        """The hash (lane0, lane1) of each of these frames (ids as fed; a FrameHasher(keep_lanes=True))."""
        self.end_part()
        hi, lo, lane0, lane1 = (np.concatenate(a) for a in zip(*self._lanes))
        order = np.lexsort((lo, hi))
        hi, lo, lane0, lane1 = hi[order], lo[order], lane0[order], lane1[order]
        want_hi, want_lo = frame_hashes(ids)
        at = np.searchsorted(hi, want_hi)  # frame ids are unique in a checked dataset; hi alone almost always
        for i in np.flatnonzero(lo[np.minimum(at, len(lo) - 1)] != want_lo):  # a 64-bit collision of hi: step on
            at[i] += int(np.flatnonzero(lo[at[i]:] == want_lo[i])[0])
        return lane0[at], lane1[at]

    def keys(self) -> FrameIndex:
        self.end_part()
        return FrameIndex.of(self._keys)


def frame_keys(id_hi: np.ndarray, id_lo: np.ndarray, lane0: np.ndarray, lane1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A frame id (its storage.frame_index.frame_hashes) and its rows' hash as one key of a FrameIndex."""
    return id_hi ^ lane0, id_lo ^ lane1
