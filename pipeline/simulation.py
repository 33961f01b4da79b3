"""`r2s simulate PROGRAM.json A.json B.json ... --n K --seed S --out DIR` (its Python API `pipeline.simulate`):
K simulated variants of a clip program, as frames, each re-checked by r2sgen's own checker (docs/cli.md,
docs/scenic.md "Simulated variants").

The clip program's variant scenario (synth.behaviour.variants) is compiled once on the clip's road as OpenDRIVE
(what `r2s export FIRST.json --to opendrive` writes, in a scratch folder); variant k is Scenic's scene drawn with
the seed derived from S and k (so it does not depend on K), simulated headless in the Newtonian simulator for the
clip's length under `--time-limit`, and its states at the recording's frame times written as frames rows: one
scene per variant, the recorded timestamps, world poses and speeds, lane facts on the clip's road (its map is
written beside the frames). The rows are read back as `r2s scene` reads them and checked against the clip program
(synth.behaviour.check); a variant Scenic rejects, that runs past the time limit or that the checker refuses is
not written, and summary.json says which and why. DIR is replaced whole, and only when at least one variant
is written (else SamplingError, exit 4, nothing written).
"""

from __future__ import annotations

import json
import math
import os
import random
import signal
import sys
import tempfile
import threading
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from frames.maps import FrameRoads, maps_dir, maps_writer
from frames.rows import to_table
from frames.scene import EgoPlace, FrameColumns, frame_to_scene
from frames.schema import MAPS_DIR
from frames.writer import frames_writer
from pipeline.cli.inputs import read_scene, read_text_file
from pipeline.errors import UserError
from pipeline.export.opendrive import export_road, header_frame
from pipeline.outputs import staged_directory
from synth.behaviour.check import check_clip, segment_holds
from synth.behaviour.program import ClipProgram, parse_clip_program
from synth.behaviour.track import Clip, read_clip
from synth.behaviour.variant_lanes import LaneWatch, world_states
from synth.behaviour.variants import Simulated, variant_scenic
from synth.config import SynthConfig, as_config
from synth.driver import StageTimer
from synth.errors import InternalError, SamplingError
from synth.geometry import normalize
from synth.road.lane_facts import RoadIndex
from synth.scene import Scene
from synth.syntax import DslError
from synth.version import __version__
from synth.window.road import window_road
from synth.world import WorldPose, road_in_world

FRAMES_FILE = "part-000000.parquet"
SUMMARY_FILE = "summary.json"
MAX_VARIANTS = 10_000
ATTEMPTS = 5  # simulations per variant: Scenic draws another scene when one breaks a requirement
OUTCOMES = ("written", "rejected by Scenic", "timed out", "rejected by the checker")


def _owns(entry: os.DirEntry) -> bool:
    """What r2s simulate writes in DIR: its frames part, its summary and its maps folder."""
    if entry.name == MAPS_DIR:
        return entry.is_dir(follow_symlinks=False)
    return entry.is_file(follow_symlinks=False) and entry.name in (FRAMES_FILE, SUMMARY_FILE)


@dataclass(frozen=True)
class Variant:
    """One simulation: its index, the seed its scene was drawn with, its scene name, outcome and why."""

    index: int
    seed: int
    scene: str
    outcome: str
    reason: str = ""
    attempts: int = 1  # simulations drawn (up to ATTEMPTS: one more each time a requirement failed)

    def to_json_dict(self) -> dict:
        return {"variant": self.index, "seed": self.seed, "scene": self.scene, "outcome": self.outcome,
                "attempts": self.attempts, **({"reason": self.reason} if self.reason else {})}


@dataclass(frozen=True)
class SimulateResult:
    """What r2s simulate did: every variant's outcome, the entities it simulated and those it could not (first
    seen after the clip's first frame), and the seconds of each stage (StageTimer: road, compile, simulate, check,
    write). Counts by outcome, and the summary written as DIR/summary.json (without the seconds: the same seed
    writes the same bytes)."""

    asked: int
    seed: int
    variants: tuple[Variant, ...]
    simulated: tuple[str, ...]
    not_simulated: tuple[str, ...]
    frames: int
    seconds: Mapping[str, float] = field(compare=False)

    def count(self, outcome: str) -> int:
        return sum(v.outcome == outcome for v in self.variants)

    @property
    def written(self) -> int:
        return self.count("written")

    def line(self) -> str:
        return (f"{self.asked} asked, {self.count('rejected by Scenic')} rejected by Scenic, "
                f"{self.count('timed out')} timed out, {self.count('rejected by the checker')} rejected by the checker, "
                f"{self.written} written")

    def to_json_dict(self) -> dict:
        return {"asked": self.asked, "seed": self.seed, "written": self.written,
                "rejected_by_scenic": self.count("rejected by Scenic"), "timed_out": self.count("timed out"),
                "rejected_by_checker": self.count("rejected by the checker"), "frames_per_variant": self.frames,
                "simulated": list(self.simulated), "not_simulated": list(self.not_simulated),
                "variants": [v.to_json_dict() for v in self.variants], "version": __version__}


class NoVariantWritten(SamplingError):
    """Every variant rejected (exit 4, nothing written); `result` says how."""

    def __init__(self, result: SimulateResult) -> None:
        super().__init__(f"no variant written: {result.line()}")
        self.result = result


class _TimedOut(InternalError):
    """The alarm of --time-limit inside one simulation, caught around it (an internal error only if it escaped)."""


def variant_seed(seed: int, k: int) -> int:
    """The seed of variant k's scene: from S and k alone (numpy's SeedSequence), so variant k is the same for any K."""
    return int(np.random.SeedSequence([seed, k]).generate_state(1)[0])


def read_program_json(text: str, where: str) -> tuple[ClipProgram, dict[str, list[int]], dict]:
    """The clip program, its boundaries and the document of `r2s synth ... --behaviours --format json`; anything
    else one line (UserError)."""
    how = "r2s synth A.json B.json ... --behaviours --format json writes one"
    try:
        doc = json.loads(text)
    except ValueError:
        raise UserError(f"{where} is not JSON: give a behaviour program as {how}") from None
    if not (isinstance(doc, dict) and isinstance(doc.get("program"), str) and isinstance(doc.get("boundaries"), dict)
            and isinstance(doc.get("frames"), int)):
        raise UserError(f"{where} is not a behaviour program (no 'program', 'boundaries' and 'frames'): {how}")
    try:
        program = parse_clip_program(doc["program"])
    except DslError as exc:
        raise UserError(f"{where}: {exc}") from None
    bounds = doc["boundaries"]
    if not all(isinstance(v, list) and all(type(b) is int for b in v) for v in bounds.values()):
        raise UserError(f"{where}: 'boundaries' must map each entity to its boundary samples (integers): {how}")
    return program, bounds, doc


def _boundaries(program: ClipProgram, bounds: Mapping[str, list[int]], clip: Clip, config: SynthConfig,
                where: str) -> list[tuple[int, ...]]:
    """Each track's boundary samples, checked: each segment holds on the recording between its two (so the
    recorded parameters the variants start from are the program's)."""
    out = []
    for track in clip.tracks:
        behaviour, b = program.behaviour(track.id), bounds.get(track.id)
        if behaviour is None or b is None:
            raise UserError(f"{where} has no behaviour or boundaries for {track.id!r}, an entity of the clip: "
                            "give the frames the program was synthesized from")
        m = max(len(behaviour.segments), 1)
        ok = (len(b) == m + 1 and b[0] == 0 and b[-1] == track.n - 1 and all(x < y for x, y in zip(b, b[1:]))
              or track.n == 1 and b == [0, 0])
        if ok and not behaviour.parked:
            ok = all(segment_holds(s, track, x, y, config) for s, x, y in zip(behaviour.segments, b, b[1:]))
        if not ok:
            raise UserError(f"{where}: the boundaries {b} of {track.id!r} do not fit its {track.n} samples and "
                            f"{m} segments: give the frames the program was synthesized from, unedited boundaries")
        out.append(tuple(b))
    return out


def simulate(program: str | os.PathLike, scenes: Sequence[str | os.PathLike], out: str | os.PathLike, *, n: int = 1,
             seed: int = 0, time_limit: float | None = None, config: SynthConfig | Mapping[str, Any] | None = None,
             report: Callable[[Variant, int], None] | None = None) -> SimulateResult:
    """K = n simulated variants of the clip program in the JSON file `program` on the clip's scene JSON files
    `scenes` (those it was synthesized from), written to the folder `out` (module docstring). `report(variant, n)`
    is called after each simulation. Bad input raises a UserError (one line, nothing written); no variant
    written, NoVariantWritten (a SamplingError) with the result."""
    config = as_config(config)
    if not 1 <= n <= MAX_VARIANTS:
        raise UserError(f"--n must be from 1 to {MAX_VARIANTS:,}, got {n}")
    if time_limit is not None and not (math.isfinite(time_limit) and time_limit > 0):
        raise UserError(f"--time-limit must be a positive number of seconds, got {time_limit}")
    if time_limit is not None and threading.current_thread() is not threading.main_thread():
        raise UserError("a time limit per simulation is an alarm signal, which only the main thread receives: call "
                        "simulate with time_limit from the main thread, or without it")
    if not 0 <= seed < 2**32:
        raise UserError(f"--seed must be from 0 to 2^32 - 1, got {seed}")
    if len(scenes) < 2:
        raise UserError("give the clip's frames: two or more scene JSON files, in time order (those of r2s synth "
                        "--behaviours)")
    where = str(program)
    clip_program, bounds, doc = read_program_json(read_text_file(where, "program"), where)
    recorded = [read_scene(str(p)) for p in scenes]
    clip, boundaries = check_program(clip_program, bounds, doc, recorded, config, where)
    base = clip.scenes[0].world.scene or clip.scenes[0].frame_id.rsplit("/", 1)[0]
    with staged_directory(out, _owns, "r2s simulate's frames, maps and summary") as stage:
        (stage / MAPS_DIR).mkdir()

        def road_maps(world_road) -> Path:  # the clip's road is the map of its variants, written beside them
            with maps_writer(stage / MAPS_DIR / FRAMES_FILE) as maps:
                maps.add(world_road)
            return maps_dir(stage)

        # each written variant's rows go to the file as it passes (K up to MAX_VARIANTS clips must not sit in
        # memory); with none written the staged folder is dropped whole
        with frames_writer(stage / FRAMES_FILE) as w:
            result = simulate_clip(clip_program, clip, boundaries, str(scenes[0]), base, road_maps, n, seed,
                                   time_limit, config, report, w.write_frame)
        if not result.written:
            raise NoVariantWritten(result)
        (stage / SUMMARY_FILE).write_text(json.dumps(result.to_json_dict(), indent=1) + "\n", encoding="utf-8")
    return result


def check_program(clip_program: ClipProgram, bounds: Mapping[str, list[int]], doc: Mapping, recorded: list[Scene],
                  config: SynthConfig, where: str) -> tuple[Clip, list[tuple[int, ...]]]:
    """The clip of the recorded frames and each track's boundaries, once the program is checked to be theirs (its
    frames, the checker, its boundaries) and the first frame to have a road and a world pose; else a UserError."""
    clip = read_clip(recorded)
    if [s.frame_id for s in (recorded[0], recorded[-1])] != [doc.get("first_frame"), doc.get("last_frame")] \
            or len(recorded) != doc["frames"]:
        raise UserError(f"{where} is the program of frames {doc.get('first_frame')!r} to {doc.get('last_frame')!r} "
                        f"({doc['frames']}), not of the {len(recorded)} frames given ({recorded[0].frame_id!r} to "
                        f"{recorded[-1].frame_id!r})")
    if not check_clip(clip_program, clip, config).ok:
        raise UserError(f"{where} does not contain the clip its frames make (r2s check says why): give the frames "
                        "it was synthesized from, and the --config, --motion, --lanes it was synthesized with")
    boundaries = _boundaries(clip_program, bounds, clip, config, where)
    if recorded[0].road is None or recorded[0].world is None:
        raise UserError(f"the clip's first frame {recorded[0].frame_id!r} has no road or no world pose: a simulation "
                        "runs on the recorded road (extract a source with maps)")
    return clip, boundaries


def simulate_clip(clip_program: ClipProgram, clip: Clip, boundaries: list[tuple[int, ...]], first_scene: str,
                  base: str, road_maps: Callable[[Any], Path], n: int, seed: int, time_limit: float | None,
                  config: SynthConfig, report: Callable[[Variant, int], None] | None,
                  write: Callable[[list[dict]], None]) -> SimulateResult:
    """K = n variants of a checked clip (check_program), scenes `{base}-simNNN`: the road of `first_scene` (the
    clip's first frame as scene JSON) as OpenDRIVE, each written variant's frames passed to `write`. `road_maps(road)`
    says where the maps of the written rows are (each variant is read back from them): given the clip's road in the
    world, it writes it as the variants' map, or names maps that hold the recording's."""
    timer = StageTimer()
    first = clip.scenes[0]
    with tempfile.TemporaryDirectory(prefix="r2s-simulate-") as scratch:
        with timer.stage("road"):
            xodr = str(Path(scratch) / "road.xodr")
            export_road(first_scene, None, xodr)
        sim = variant_scenic(f"variants of {first.frame_id} to {clip.scenes[-1].frame_id}",
                             [clip_program.behaviour(t.id) for t in clip.tracks], boundaries, clip, xodr, config,
                             (header_frame(xodr) or (0.0, 0.0))[:2])
        world_road = road_in_world(first.world, window_road(clip.scenes))
        index = RoadIndex(world_road)  # the lane facts Scenic's lane rules and the written rows both read
        watch = LaneWatch(index, clip.graph, sim.offset, sim.frame_steps, sim.lane_rules)
        with timer.stage("compile"):
            scenario = _compile(sim.text, {"r2s_lanes": watch})
        kept = ClipProgram(clip_program.program, tuple(clip_program.behaviour(i) for i in sim.placed))
        with timer.stage("write"):
            maps = road_maps(world_road)
        variants = _variants(scenario, watch, sim, clip, kept, index, maps, base, n, seed, time_limit, config, timer,
                             report, write)
    return SimulateResult(n, seed, tuple(variants), sim.placed, tuple(t.id for t in clip.tracks if not t.from_start),
                          len(clip.scenes), dict(timer.seconds))


def _compile(text: str, params: Mapping[str, Any] | None = None):
    """The scenario; `params` its global parameters (a variant scenario's r2s_lanes: its LaneWatch)."""
    import scenic

    return scenic.scenarioFromString(text, params=dict(params or {}), mode2D=True)


def _variants(scenario, watch: LaneWatch, sim: Simulated, clip: Clip, kept: ClipProgram, index: RoadIndex,
              maps: Path, base: str, n: int, seed: int, time_limit: float | None, config: SynthConfig,
              timer: StageTimer, report, write: Callable[[list[dict]], None]) -> list[Variant]:
    """Simulate, write as rows and check each variant in turn, each frame of a variant the checker accepts passed to
    `write`; every Variant. `watch`: the scenario's lane rules (its r2s_lanes), which say the last one broken."""
    from scenic.core.distributions import RejectionException

    roads = FrameRoads(maps)
    simulator = scenario.getSimulator()
    variants = []
    for k in range(n):
        name, s = f"{base}-sim{k:03d}", variant_seed(seed, k)
        random.seed(s)
        np.random.seed(s)
        outcome, reason, attempts = "rejected by Scenic", "", 0
        try:
            with timer.stage("simulate"), _deadline(time_limit):
                # a simulation that breaks a requirement is drawn again (a new scene: its draws are the scene's)
                run = None
                while run is None and attempts < ATTEMPTS:
                    attempts += 1
                    scene, _ = scenario.generate(maxIterations=100)
                    run = simulator.simulate(scene, maxSteps=sim.steps, maxIterations=1, timestep=sim.timestep)
        except RejectionException as exc:
            run, reason = None, f"no scene: {str(exc)[:200]}"
        except _TimedOut:
            run, outcome, reason = None, "timed out", f"past --time-limit {time_limit:g} s"
        if run is not None:
            with timer.stage("check"):
                frames = variant_rows(name, sim, clip, run.result.records["r2s_states"], index)
                scenes = [_read_back(f, roads) for f in frames]
                verdict = check_clip(kept, scenes, config)
            if verdict.ok:
                outcome = "written"
                with timer.stage("write"):
                    for frame in frames:
                        write(frame)
            else:
                first = verdict.violations[0]
                outcome = "rejected by the checker"
                reason = f"{len(verdict.violations)} violations, the first {first}"
        elif not reason:
            lanes = f" (the last: {watch.failure})" if watch.failure else ""
            reason = f"a requirement failed during each of {attempts} simulations{lanes}"
        variant = Variant(k, s, name, outcome, reason, attempts)
        variants.append(variant)
        if report is not None:
            report(variant, n)
    return variants


class _deadline:
    """SIGALRM after `seconds` (None: no limit) raises _TimedOut in the block; the simulation runs in this thread."""

    def __init__(self, seconds: float | None) -> None:
        self.seconds = seconds

    def __enter__(self) -> None:
        if self.seconds is not None:
            self.old = signal.signal(signal.SIGALRM, self._fire)
            signal.setitimer(signal.ITIMER_REAL, self.seconds)

    @staticmethod
    def _fire(signum, frame) -> None:
        raise _TimedOut

    def __exit__(self, *exc) -> None:
        if self.seconds is not None:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self.old)


def variant_rows(name: str, sim: Simulated, clip: Clip, records, index: RoadIndex) -> list[list[dict]]:
    """A simulation's states at the clip's frame steps as frames rows (docs/formats.md): per frame, ego first, every
    simulated entity in the ego frame of the simulated ego, its world place and speed, its lane facts on the road."""
    states = dict(records)  # step -> [(x, y, Scenic heading in radians from +y, speed)] in sim.placed's order
    first = clip.scenes[0]
    by_id = first.by_id()
    entities = [first.ego if i == "ego" else by_id[i] for i in sim.placed]
    # an entity is in the frames it is in in the recording (a track that leaves the clip or has gaps keeps them)
    present = [{clip.times.index(x.t) for x in clip.track(i).samples} for i in sim.placed]
    out = []
    for k, (scene, step) in enumerate(zip(clip.scenes, sim.frame_steps)):
        now = states[min(step, max(states))]
        xs, ys, hs = world_states(now, sim.offset)  # as the lane rules Scenic requires read them
        facts = index.facts(xs, ys, hs)
        ego = WorldPose(xs[0], ys[0], hs[0])
        rows = []
        for e, x, y, h, state, fact, there in zip(entities, xs, ys, hs, now, facts, present):
            if k not in there:
                continue
            lx, ly = ego.local(x, y)
            rows.append({
                "frame_id": f"{name}/{k}", "source": "r2s-simulate", "scene": name, "frame_index": k,
                "timestamp_us": scene.world.timestamp_us, "entity_id": e.id, "track_id": e.id, "type": e.type,
                "category": e.type, "x": lx, "y": ly, "heading": normalize(h - hs[0]),
                "length": e.length, "width": e.width, "is_ego": e.id == "ego", "speed": float(state[3]),
                "map_id": index.road.map_id, "map_x": x, "map_y": y, "map_heading": h, "lanes": list(fact.lanes),
                "lane": fact.lane, "in_intersection": fact.in_intersection, "on_crosswalk": fact.on_crosswalk,
                "off_road": fact.off_road,
            })
        out.append(rows)
    return out


def _read_back(rows: list[dict], roads: FrameRoads) -> Scene:
    """A variant's frame as r2s scene reads it from the written frames and map (the checker sees what is written)."""
    columns = FrameColumns.of(to_table(rows))
    place = EgoPlace.of(columns)
    road, _ = roads.road(columns, place)
    return frame_to_scene(columns, road, place)


def progress_line(variant: Variant, n: int) -> None:
    """One line on stderr per variant (r2s simulate's progress)."""
    why = f": {variant.reason}" if variant.reason else ""
    sys.stderr.write(f"r2s simulate: variant {variant.index + 1}/{n} ({variant.scene}): {variant.outcome}{why}\n")
    sys.stderr.flush()
