"""Programs over a window: one minimum-cost program for several consecutive frames of one scene (issue 25).

The search is the paper's (Alg. 1 over Alg. 4), on the window's relation table: a relation of target e with
reference r holds for the window iff it holds in every frame of the window where e is present, with r present in
each of those frames too (the per-frame tables intersected, part by part). An entity present in only part of the
window is declared once and describes the frames it is in: a frame's program is the window program's statements
of the entities present in that frame (frame_program), which is why a reference must be present wherever its
target is (its statement would otherwise name an entity the frame lacks). Each frame's statements are written by
Alg. 4 on that frame with the window's choice of reference and relation, and the window's clause of an entity is
its part's merge of its frames' clauses (Part.merged: by default their widening, Clause.widened, Ranges the hull
of the frames' Ranges so they cover every frame's measure; the lane part's fallback is decided on the entity's
place in every frame, and the search weighs it so, Part.window_fallback_cost). Every frame's program is certified
on its frame. docs/dsl.md, "Programs over a window".

How windows tile a scene's frames (tile) is here too: it is arithmetic on timestamps, values in and out.
"""

from __future__ import annotations

import math
from bisect import bisect_left
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from synth.config import ConfigError, SynthConfig, as_config
from synth.driver import Frame, Oracles, drive
from synth.dsl import Program, Statement, parse_program
from synth.oracle import RelationOracle, make_oracle
from synth.parts import parts_for
from synth.result import SynthResult
from synth.road.roadmap import RoadMap
from synth.robust import robust_note
from synth.scene import Entity, Scene, SceneError, as_scene
from synth.scenic.emit import render_scenic
from synth.semantics import check
from synth.statement import choose_references, write_statements
from synth.tables import NONE, RelationTable
from synth.version import __version__
from synth.window.road import window_road

if TYPE_CHECKING:
    from synth.semantics import CheckResult

class WindowError(SceneError):
    """A clip that is not frames of one scene: no frame, a frame id twice, an id of two types. One line."""


@dataclass(frozen=True)
class WindowResult(SynthResult):
    """The program synthesized for a window of frames: a SynthResult (its frame_id the window's first frame, its
    status the window search's, n_entities every entity present in some frame, certified: every frame's program
    certified on its frame) and the frames it covers (`frame_ids`, in order). `frame_program(scene)` is what it
    says of one of them."""

    frame_ids: tuple[str, ...]

    @property
    def first_frame(self) -> str:
        return self.frame_ids[0]

    @property
    def last_frame(self) -> str:
        return self.frame_ids[-1]

    def frame_program(self, scene: Scene) -> Program:
        return frame_program(self.program, scene)

    def json_more(self) -> dict:
        """The `r2s synth --format json` document of a clip is the single-frame document (frame_id: the first
        frame) with the window's first and last frame and its number of frames before the stats."""
        return {"first_frame": self.first_frame, "last_frame": self.last_frame, "frames": len(self.frame_ids)}


def frame_program(program: Program, scene: Scene) -> Program:
    """The window program's statements of the entities present in `scene`, in the program's order: what the
    window program says of that frame (checked with r2s check's semantics as any program is)."""
    present = {e.id for e in scene.others}
    return Program(tuple(st for st in program.statements if st.id in present))


def check_window(program: Program | str, scenes: Sequence[Scene | Mapping[str, Any]],
                 config: SynthConfig | Mapping[str, Any] | None = None) -> tuple[CheckResult, ...]:
    """r2s check's verdict on every frame of a window: `check(frame_program(program, scene), scene)` per frame."""
    if isinstance(program, str):
        program = parse_program(program)
    config = as_config(config)
    return tuple(check(frame_program(program, s), s, config) for s in map(as_scene, scenes))


def clip_entities(scenes: Sequence[Scene]) -> tuple[tuple[str, ...], dict[str, list[int]]]:
    """The entities of a clip to declare, in order of first appearance (scene order within a frame), and the
    frames (indices) each is present in. Refuses what is not frames of one scene."""
    if not scenes:
        raise WindowError("a window needs at least one frame")
    _check_one_scene_in_order(scenes)
    seen_frames: set[str] = set()
    types: dict[str, tuple[str, str]] = {}
    frames: dict[str, list[int]] = {}
    for k, scene in enumerate(scenes):
        if scene.frame_id in seen_frames:
            raise WindowError(f"frame {scene.frame_id!r} is in the window twice")
        seen_frames.add(scene.frame_id)
        for e in scene.others:
            first = types.setdefault(e.id, (e.type, scene.frame_id))
            if first[0] != e.type:
                raise WindowError(f"entity {e.id!r} is a {first[0]} in frame {first[1]!r} and a {e.type} in frame "
                                  f"{scene.frame_id!r}: a window needs one id per object (stable ids, docs/formats.md)")
            frames.setdefault(e.id, []).append(k)
    return tuple(frames), frames


def _check_one_scene_in_order(scenes: Sequence[Scene]) -> None:
    """Where scene JSON says it (its `world`: source, scene, frame_index), the frames are of one scene and in time
    order: two frames naming different scenes (or sources), or a frame whose index is not above the index of the
    frame before it that gives one, are refused. Frames that do not say are taken as given."""
    named: dict[str, tuple[str, str]] = {}  # "source" / "scene": (the first frame that names one, its name)
    last: tuple[str, int] | None = None  # the last frame that gives its index, and that index
    for scene in scenes:
        world = scene.world
        if world is None:
            continue
        for key in ("source", "scene"):
            name = getattr(world, key)
            if name is None:
                continue
            first = named.setdefault(key, (scene.frame_id, name))
            if first[1] != name:
                raise WindowError(f"frame {scene.frame_id!r} is of {key} {name!r} and frame {first[0]!r} of {key} "
                                  f"{first[1]!r} (their world): a clip is frames of one scene")
        if world.frame_index is not None:
            if last is not None and world.frame_index <= last[1]:
                raise WindowError(f"frame {scene.frame_id!r} (frame_index {world.frame_index}) comes after frame "
                                  f"{last[0]!r} (frame_index {last[1]}): give a clip's frames in time order")
            last = (scene.frame_id, world.frame_index)


def window_table(oracles: Sequence[Any], ids: tuple[str, ...]):
    """The window's relation table (ids: ego, then the clip's entities): per part, a relation holds between r and
    e iff it holds in every frame where e is present, r present in each (RelationOracle.holds, relation by
    relation); where several hold, the first a reference is asked in (Part.codes_from), as the oracles record."""
    n = len(ids)
    where = {i: k for k, i in enumerate(ids)}
    codes = {}
    for k, part in enumerate(oracles[0].parts):
        holds = {c: np.ones((n, n), dtype=bool) for c in range(len(part.relations))}
        for oracle in oracles:
            at = np.array([where[i] for i in oracle.ids])
            cells = oracle.table[part.name]
            # The cells where a relation other than the recorded one may hold too (RelationOracle.holds): ego's
            # row where a refless code is recorded; for a part whose relations are not disjoint, every witness.
            if part.disjoint:
                asked = [(0, int(e)) for e in np.flatnonzero(np.isin(cells[0], list(part.refless)))]
            else:
                asked = [(int(r), int(e)) for r, e in np.argwhere(cells != NONE)]
            for c, window in holds.items():
                frame = np.zeros((n, len(at)), dtype=bool)  # references absent from the frame: never
                frame[at, :] = cells == c
                for r, e in asked:
                    frame[at[r], e] = oracle.holds(k, c, r, e)
                window[:, at[1:]] &= frame[:, 1:]
        table = np.full((n, n), NONE, dtype=np.int8)
        for c in reversed(part.codes_from(True)):
            table[holds[c]] = c
        table[1:][np.isin(table[1:], list(part.refless))] = NONE  # refless codes live in ego's row only
        table[:, 0] = NONE
        np.fill_diagonal(table, NONE)
        codes[part.name] = table
    return RelationTable(ids, codes)


def check_window_config(config: SynthConfig) -> None:
    """What a window cannot be synthesized with: one line, before any work (r2s run checks it up front)."""
    if config.strategy == "monolithic":
        raise ConfigError("strategy 'monolithic' encodes one frame; a window is searched on its relation table "
                          "(any other strategy)")


@dataclass(frozen=True)
class Window:
    """A window of frames of one scene, as the driver (synth.driver) synthesizes it: its frames, the clip's
    entities and the frames each is present in, and what the window's oracle and Scenic text stand on."""

    kind: ClassVar[str] = "window"
    scenes: tuple[Scene, ...]
    ids: tuple[str, ...]  # the clip's entities, in order of first appearance (clip_entities)
    present: dict[str, list[int]] = field(hash=False)  # each entity's frames (indices)
    # The scene the window's oracle and Scenic text stand on: ego's first frame, each entity where first seen (in
    # the ego frame of that frame, where its relations to ego were measured); the text's road is the window's.
    shown: Scene
    road: RoadMap | None  # the window's road (synth.window.road): every frame's, in the first frame's ego frame

    @classmethod
    def of(cls, scenes: Sequence[Scene], config: SynthConfig) -> Window:
        """The window of `scenes`, refused (one line) before any work if it is not frames of one scene
        (WindowError), if the config cannot search a window, if a frame lacks what the config asks (as a Frame's),
        or if the frames' roads cannot be brought together."""
        check_window_config(config)
        ids, present = clip_entities(scenes)
        for scene in scenes:
            Frame.of(scene, config)
        road = window_road(scenes)
        first = {e.id: e for scene in reversed(scenes) for e in scene.others}
        shown = Scene(scenes[0].frame_id, (scenes[0].ego,) + tuple(first[i] for i in ids), scenes[0].road,
                      scenes[0].world)
        return cls(tuple(scenes), ids, present, shown, road)

    @property
    def all_ids(self) -> tuple[str, ...]:
        """The window oracle's ids: ego, then the clip's entities."""
        return (self.shown.ego.id,) + self.ids

    @cached_property
    def poses(self) -> dict[str, tuple[Entity, ...]]:
        """Each entity's poses in the frames it is in: what a part's window fallback is decided on."""
        by_id = [scene.by_id() for scene in self.scenes]
        return {i: tuple(by_id[k][i] for k in self.present[i]) for i in self.ids}

    def oracles(self, config: SynthConfig) -> Oracles:
        """Each frame's oracle with its full table, and the window's oracle on their intersection."""
        frames = tuple(make_oracle(scene, config) for scene in self.scenes)
        for oracle in frames:
            oracle.full_table()
        window = RelationOracle(self.shown, config, self.all_ids, window_table(frames, self.all_ids),
                                parts=parts_for(config), poses=self.poses)
        return Oracles(window, frames)

    def program(self, oracles: Oracles, order: tuple[int, ...], config: SynthConfig) -> Program:
        """Each frame's statements by Alg. 4 with the window's choice of reference and relation, each entity's
        clause its part's merge of its frames' clauses."""
        all_ids, window = self.all_ids, oracles.search
        # Alg. 4's nearest reference, measured in the frame where the target is first seen (where every reference
        # that witnesses it for the window is too).
        places = [{e.id: (e.x, e.y) for e in scene.entities} for scene in self.scenes]
        seen = {i: self.present[i][0] for i in self.ids}

        def distance(r: int, i: int) -> float:
            at = places[seen[all_ids[i]]]
            (rx, ry), (x, y) = at[all_ids[r]], at[all_ids[i]]
            return math.hypot(rx - x, ry - y)

        choices = dict(zip(order, choose_references(window, order, distance)))
        written: dict[str, dict[str, list]] = {}  # per entity, per part: the clause of each frame it is in
        for oracle in oracles.frames:
            at = {i: k for k, i in enumerate(oracle.ids)}  # window id -> the frame oracle's index
            mine = [i for i in order if all_ids[i] in at]
            rows = [tuple((at[all_ids[r]], c) for r, c in choices[i]) for i in mine]
            for st in write_statements(oracle, tuple(at[all_ids[i]] for i in mine), rows, config):
                for part, clause in st.parts:
                    written.setdefault(st.id, {}).setdefault(part, []).append(clause)
        by_name, poses, types = {p.name: p for p in window.parts}, self.poses, self.shown.by_id()
        return Program(tuple(
            Statement(i, types[i].type, parts=tuple((part, by_name[part].merged(frames, poses[i], config))
                                                    for part, frames in written[i].items()))
            for i in (all_ids[j] for j in order)))

    def frame_program(self, program: Program, scene: Scene) -> Program:
        return frame_program(program, scene)

    def where(self, scene: Scene) -> str:
        return f"frame {scene.frame_id}: "

    def scenic(self, program: Program, status: str, config: SynthConfig) -> str:
        first, last = self.scenes[0], self.scenes[-1]
        header = (f"frames {first.frame_id} to {last.frame_id} ({len(self.scenes)} frames): cost {program.cost} "
                  f"({status}), r2sgen {__version__}" + robust_note(self.scenes, config))
        # On the window's road, so that a lane clause of an entity first seen later names a region of the text.
        shown = self.shown
        return render_scenic(program, shown if self.road is shown.road else replace(shown, road=self.road), config,
                             header=header)

    def result(self, **fields: Any) -> WindowResult:
        return WindowResult(frame_id=self.scenes[0].frame_id, n_entities=len(self.ids),
                            frame_ids=tuple(s.frame_id for s in self.scenes), **fields)


def synthesize_window(scenes: Sequence[Scene | Mapping[str, Any]],
                      config: SynthConfig | Mapping[str, Any] | None = None) -> WindowResult:
    """A minimum-cost program whose every clause holds in every frame of the window (docs/dsl.md, "Programs over
    a window"). `scenes`: the window's frames of one scene, in time order, with stable ids (Scenes or decoded
    scene JSON). `config` as synthesize takes it. Bad input raises SceneError / WindowError / ConfigError (one
    line); a frame program the solver cannot certify raises CertificationError. Deterministic."""
    scenes = [as_scene(s) for s in scenes]
    config = as_config(config)
    return drive(Window.of(scenes, config), config)


def tile(timestamps_us: Sequence[int], window_us: int, stride_us: int | None = None,
         max_gap_us: int | None = None) -> list[tuple[int, int]]:
    """The windows of one scene's frames (timestamps in microseconds, in order, strictly increasing), as
    (first, last) frame indices, inclusive. A gap of more than `max_gap_us` between consecutive frames cuts the
    scene into segments that no window spans; in a segment, a window starts at its first frame and holds the
    frames less than `window_us` after its start; the next starts at the first frame at least `stride_us` after
    that start (default: the window, so windows are consecutive and do not overlap), until the segment ends."""
    if window_us <= 0 or (stride_us is not None and stride_us <= 0) or (max_gap_us is not None and max_gap_us < 0):
        raise ValueError("window, stride and gap must be positive durations")
    stride = window_us if stride_us is None else stride_us
    # Each window's last frame and the next window's first are found by bisection in the segment (timestamps
    # increase): O(n log n) for n frames, however long the windows or short the stride (a frame-by-frame walk
    # was O(n * frames a window), 4e8 steps for 20,000 frames and one window over them all).
    out: list[tuple[int, int]] = []
    n, start = len(timestamps_us), 0
    while start < n:
        end = start  # the segment: start .. end
        while end + 1 < n and (max_gap_us is None or timestamps_us[end + 1] - timestamps_us[end] <= max_gap_us):
            end += 1
        first = start
        while first <= end:
            at = timestamps_us[first]
            out.append((first, bisect_left(timestamps_us, at + window_us, first, end + 1) - 1))
            first = bisect_left(timestamps_us, at + stride, first + 1, end + 1)
        start = end + 1
    return out
