"""`r2s run --window W`: one program per window of consecutive frames of a scene (synth.window.program), in the batch
stage's workers, parts, resume and progress.

The coordinator reads four short columns of every frame (frame_id, scene, frame_index, timestamp_us) once, after
the check, and keeps per frame its place (file, first row, rows), its scene and timestamp and its rows' hash
(frames.frame_hash, from the checking pass): ~100 bytes a frame, never a frame's rows. It orders each scene's
frames by frame_index, cuts them into windows (synth.window.program.tile) and hands windows to the workers
(pipeline.batch.window_task), which read their frames' rows themselves. A window's row is keyed by its first frame
(frame_id) and records the hash of all its frames' rows (frame_hash), so a resumed run
keeps a window's program only for the same frames with the same rows, and the config hash covers the window
options: another W is another configuration.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

import numpy as np
import pyarrow as pa

from pipeline.errors import UserError
from synth.config import SynthConfig
from synth.window.program import tile

PLACE_COLUMNS = ("frame_id", "scene", "frame_index", "timestamp_us")
# The most frames all windows together may hold, a frame counted once in each window it is in (windows that
# overlap, --stride shorter than --window, hold a frame many times). The plan costs the coordinator about 110
# bytes and 3 us a frame of a window (bench: 5e6 took 13 s and 540 MB), and the workers one synthesis each.
MAX_WINDOW_FRAMES = 4_000_000
MAX_WINDOW_S = 3600.0


@dataclass(frozen=True)
class WindowSpec:
    """How windows tile a scene (docs/dsl.md, "Programs over a window"), in seconds: their length, the time
    between two windows' starts (None: the length, consecutive windows), the longest gap between consecutive
    frames that a window may span (None: any)."""

    window_s: float
    stride_s: float | None = None
    max_gap_s: float | None = None

    name: ClassVar[str] = "window"  # the option that asks for these units (--window), and the unit in messages

    def check(self) -> None:
        """Refuse values no run can use (UserError: one line), before anything is read."""
        for name, value in ((f"--{self.name}", self.window_s), ("--stride", self.stride_s),
                            ("--max-gap", self.max_gap_s)):
            if value is not None and not (math.isfinite(value) and value > 0):
                raise UserError(f"{name} must be a positive number of seconds, got {value}")
        # --max-gap too: a gap past the window changes nothing, and seconds far past it overflow microseconds.
        if max(self.window_s, self.stride_s or 0, self.max_gap_s or 0) > MAX_WINDOW_S:
            raise UserError(f"--{self.name}, --stride and --max-gap are at most {MAX_WINDOW_S:g} s")

    def us(self, seconds: float | None) -> int | None:
        return None if seconds is None else max(1, round(seconds * 1e6))

    def tile(self, timestamps_us) -> list[tuple[int, int]]:
        return tile(timestamps_us, self.us(self.window_s), self.us(self.stride_s), self.us(self.max_gap_s))

    @property
    def text(self) -> str:
        return f"{self.name}={self.window_s!r} stride={self.stride_s!r} max_gap={self.max_gap_s!r}"

    def unit_hash(self, unit: WindowUnit, frame_ids, lane0: np.ndarray, lane1: np.ndarray) -> str:
        """A unit's frame_hash (what its row is computed from): window_hash."""
        return window_hash(unit, frame_ids, lane0, lane1)

    def config_hash(self, config: SynthConfig) -> str:
        """The config_hash of a window row: the configuration's and the window options' (16 hex digits, as
        SynthConfig.hash)."""
        return hashlib.sha256(f"{config.hash} {self.text}".encode()).hexdigest()[:16]


class FramePlace(NamedTuple):
    part: int  # index into the dataset's parts
    frame_id: str
    start: int  # first row in its file
    rows: int


class WindowUnit(NamedTuple):
    """One window to compute: `label` names it in log lines (its first and last frame), `frames` its frames in
    order, with their timestamps."""

    label: str
    scene: str
    frames: tuple[FramePlace, ...]
    first_timestamp_us: int
    last_timestamp_us: int
    timestamps_us: tuple[int, ...] = ()  # every frame's (a clip's durations depend on them: its hash covers them)


def window_hash(unit: WindowUnit, frame_ids, lane0: np.ndarray, lane1: np.ndarray) -> str:
    """What a window's row is computed from: its scene and first and last timestamps (the row records them), its
    frames (ids, in order) with their rows' hashes (frames.frame_hash); 32 hex digits, as a frame's hash. (The
    window options are in the config hash.)"""
    h = hashlib.blake2b(digest_size=16)
    h.update(f"{unit.scene}\0{unit.first_timestamp_us}\0{unit.last_timestamp_us}".encode())
    for fid, a, b in zip(frame_ids, lane0, lane1):
        h.update(b"\0" + str(fid).encode() + b"\0" + int(a).to_bytes(8, "little") + int(b).to_bytes(8, "little"))
    return h.hexdigest()


def frame_places(dataset) -> Iterator[tuple[FramePlace, str, int, int | None]]:
    """(place, scene, frame_index, timestamp_us) of every frame of a checked dataset, in file order, reading only
    the columns PLACE_COLUMNS (a frame continued from one row group into the next is one frame)."""
    for k, part in enumerate(dataset.parts):
        offset = 0
        pending = None  # the last frame of the previous row group: it may go on in this one
        for table in dataset.row_groups(part, PLACE_COLUMNS):
            n = table.num_rows
            if n == 0:
                continue
            ids = table.column("frame_id").combine_chunks()
            codes = ids.indices.to_numpy(zero_copy_only=False) if pa.types.is_dictionary(ids.type) else \
                np.unique(ids.to_numpy(zero_copy_only=False), return_inverse=True)[1]
            starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
            heads = table.take(pa.array(starts)).to_pylist()
            lengths = np.diff(np.r_[starts, n])
            for head, start, rows in zip(heads, starts, lengths):
                if pending is not None and start == 0 and head["frame_id"] == pending[0].frame_id:
                    place = pending[0]
                    pending = (place._replace(rows=place.rows + int(rows)),) + pending[1:]
                    continue
                if pending is not None:
                    yield pending
                pending = (FramePlace(k, head["frame_id"], offset + int(start), int(rows)), head["scene"],
                           head["frame_index"], head["timestamp_us"])
            offset += n
        if pending is not None:
            yield pending


def plan_windows(dataset, hasher, spec: WindowSpec) -> tuple[list[WindowUnit], list[str]]:
    """The windows of every scene (scenes in name order, windows in time order) and the hash each is expected to
    have. A frame without a scene or a timestamp, or two frames of a scene at one timestamp or out of order,
    refuses the run (UserError)."""
    scenes: dict[str, list[tuple[int, int, int, FramePlace]]] = {}
    for n, (place, scene, index, stamp) in enumerate(frame_places(dataset)):
        if scene is None:
            raise UserError(f"{dataset.source}: frame {place.frame_id!r} has no scene; --{spec.name} cuts scenes")
        if stamp is None:
            raise UserError(f"{dataset.source}: frame {place.frame_id!r} has no timestamp_us; --{spec.name} needs "
                            "the frames' timestamps")
        scenes.setdefault(scene, []).append((-1 if index is None else index, n, stamp, place))
    tiles = {}
    for scene in sorted(scenes):
        frames = scenes[scene] = sorted(scenes[scene])  # by frame_index, then file order
        stamps = [f[2] for f in frames]
        bad = next((i for i in range(1, len(stamps)) if stamps[i] <= stamps[i - 1]), None)
        if bad is not None:
            a, b = frames[bad - 1][3].frame_id, frames[bad][3].frame_id
            raise UserError(f"{dataset.source}: scene {scene!r}: frame {b!r} is not later than {a!r} "
                            f"(timestamps {stamps[bad - 1]}, {stamps[bad]}); --{spec.name} needs increasing timestamps")
        tiles[scene] = spec.tile(stamps)
    # Counted on the (first, last) pairs, before a window's frames are gathered.
    total = sum(last - first + 1 for pairs in tiles.values() for first, last in pairs)
    if total > MAX_WINDOW_FRAMES:
        frames_in = sum(map(len, scenes.values()))
        raise UserError(f"{dataset.source}: the {spec.name}s would hold {total:,} frames in all "
                        f"({total / frames_in:,.0f} per frame of the input), more than the bound of "
                        f"{MAX_WINDOW_FRAMES:,}: give a longer --stride or a shorter --{spec.name} (docs/cli.md, "
                        "Inputs and their bounds)")
    units: list[WindowUnit] = []
    for scene, pairs in tiles.items():
        frames = scenes[scene]
        stamps = [f[2] for f in frames]
        for first, last in pairs:
            places = tuple(f[3] for f in frames[first:last + 1])
            units.append(WindowUnit(f"{places[0].frame_id}..{places[-1].frame_id}", scene, places, stamps[first],
                                    stamps[last], tuple(stamps[first:last + 1])))
    ids = [p.frame_id for unit in units for p in unit.frames]
    lane0, lane1 = hasher.lanes(ids) if ids else (np.zeros(0, np.uint64), np.zeros(0, np.uint64))
    hashes, at = [], 0
    for unit in units:
        k = len(unit.frames)
        hashes.append(spec.unit_hash(unit, ids[at:at + k], lane0[at:at + k], lane1[at:at + k]))
        at += k
    return units, hashes
