"""`r2s simulate RUN_OUTPUT --frames FRAMES --out DIR`: every clip program of an `r2s run --clip` output simulated K
times (pipeline.simulation), one task per clip, through the batch stage (pipeline.batch.stage: its check of the
frames, plan, resume, pool, limits, parts, progress and stop).

A clip's task is a clip task (pipeline.batch.clips) that reads the clip's frames from FRAMES as `r2s run --clip` read
them (the same places, the same hash), checks that the program is theirs (pipeline.simulation.check_program; a
recording changed since the program was made is the clip's error row), and simulates K variants, each read back and
re-checked, their frames written by the worker itself to `DIR/sim-<key>.parquet` as it ends (bounded memory: the
coordinator never holds a variant). Its row, one per clip in `DIR/_simulations/` (the stage's parts), is the clip's
row as the run wrote it with what became of its variants; the frames files are those rows name, and the maps beside
FRAMES are copied to `DIR/_maps/` (the variants name the recording's maps), so DIR is a frames dataset every verb
reads.

Resume: a row is kept for the same clip program (its text and boundaries) on the same recorded frames (the clip's
frame hash as a run computes it: rows, timestamps and maps), with the same K, seed, time limit and configuration (the
config hash) and the same version; anything else is simulated again, and a frames file no kept row names is removed
when the run starts, so nothing stale survives.
"""

from __future__ import annotations

import contextlib
import filecmp
import functools
import hashlib
import io
import json
import math
import os
import shutil
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from frames.frame_hash import FrameHasher, frame_keys, from_hex
from frames.maps import maps_dir
from frames.writer import frames_writer
from pipeline.batch import DEFAULT_PART_ROWS
from pipeline.batch.clips import ClipSpec, ClipTask
from pipeline.batch.options import RunOptions
from pipeline.batch.rules import Summary
from pipeline.batch.stage import _WindowRun
from pipeline.batch.store import RunStore
from pipeline.batch.windows import FramePlace, frame_places
from pipeline.errors import UserError
from pipeline.outputs import check_apart
from pipeline.programs import CLIP_SCHEMA, ProgramsError, programs_files
from pipeline.simulation import MAX_VARIANTS, check_program, read_program_json, simulate_clip
from storage.atomic import atomic_path
from storage.frame_index import FrameIndex, frame_hashes
from synth.config import SynthConfig, as_config
from synth.search.budget import peak_rss_mb
from synth.version import ROWS_VERSION

STATUS_DIR = "_simulations"  # the per-clip rows (the stage's parts), hidden from frames readers by its "_"
FRAMES_PREFIX, FRAMES_SUFFIX = "sim-", ".parquet"
# A clip's row: the clip's own (CLIP_SCHEMA, frame_hash and config_hash those of its simulation) and then these.
SIMULATION_FIELDS = (("program_hash", pa.string()), ("seed", pa.int64()), ("variants_asked", pa.int32()),
                     ("written", pa.int32()), ("rejected_by_scenic", pa.int32()), ("timed_out", pa.int32()),
                     ("rejected_by_checker", pa.int32()), ("variants", pa.string()),
                     ("not_simulated", pa.list_(pa.string())), ("frames_file", pa.string()))
SIMULATION_SCHEMA = pa.schema(list(CLIP_SCHEMA) + [pa.field(n, t) for n, t in SIMULATION_FIELDS])
# What a bad RUN_OUTPUT's line says to give instead.
HOW = "r2s run FRAMES --clip S --lanes --out RUN_OUTPUT writes one"


def simulate_run(run_output: str | os.PathLike, frames: str | os.PathLike, out: str | os.PathLike,
                 config: SynthConfig | Mapping[str, Any] | None = None, *, n: int = 1, seed: int = 0,
                 time_limit: float | None = None, jobs: int | None = None, backend: str = "loky",
                 scheduler: str | None = None, part_rows: int = DEFAULT_PART_ROWS,
                 log: Callable[[str], None] | None = None, log_every_s: float = 30.0,
                 terminal: bool | None = None, simulator: Callable | None = None) -> Summary:
    """K = n simulated variants of every clip program of `run_output` (an `r2s run FRAMES --clip S --lanes` output)
    on the clips' frames in `frames` (those the run was made from, with their maps), written to the folder `out` (the
    module docstring; docs/cli.md, `r2s simulate`). `config`: the configuration the clips were synthesized with (the
    checker's; lanes is always on); its memory_limit caps each clip's worker. `time_limit`: wall seconds per
    simulation (a variant past it is "timed out"). `simulator`: what each clip runs instead of
    pipeline.simulation.simulate_clip (its signature; a module-level function or a partial of one, carried to the
    workers by reference: tests.support.faults). The other keywords are RunOptions' (pipeline.batch.options).
    Returns the stage's summary (one row per clip); raises UserError on bad input (one line, nothing written)."""
    config = as_config(config).with_(lanes=True)
    if not 1 <= n <= MAX_VARIANTS:
        raise UserError(f"--n must be from 1 to {MAX_VARIANTS:,}, got {n}")
    if not 0 <= seed < 2**32:
        raise UserError(f"--seed must be from 0 to 2^32 - 1, got {seed}")
    if time_limit is not None and not (math.isfinite(time_limit) and time_limit > 0):
        raise UserError(f"--time-limit must be a positive number of seconds, got {time_limit}")
    if time_limit is not None and backend == "dask":
        # _deadline is an alarm signal, which only a main thread receives; dask workers run tasks in threads
        raise UserError("--time-limit is per simulation, an alarm only a worker's main thread receives: give it "
                        "with --backend loky (the default), or run --backend dask without it")
    options = RunOptions(jobs, backend, scheduler, 1, part_rows, log_every_s, terminal)
    options.check()
    out = Path(out)
    check_apart(out, [("input frames", frames), ("run output", run_output)], directory=True)
    spec = SimulationSpec(1.0, n=n, seed=seed, time_limit=time_limit)
    return _SimulationRun(str(frames), out, config, options, log or _log, Path(run_output), spec, simulator).go()


def _log(line: str) -> None:
    sys.stderr.write(f"r2s simulate: {line}\n")
    sys.stderr.flush()


@dataclass(frozen=True)
class SimulationSpec(ClipSpec):
    """What a clip's simulation is besides its program and frames: K, the seed and the time limit per simulation,
    in the config hash of its row (another K, seed or limit simulates every clip again). The tiling fields are
    unused: the clips are the run output's."""

    n: int = 1
    seed: int = 0
    time_limit: float | None = None

    @property
    def text(self) -> str:
        return f"simulate n={self.n} seed={self.seed} time_limit={self.time_limit!r}"


class ClipUnit(NamedTuple):
    """A clip to simulate: a WindowUnit's fields (the pool and the clip task read those) and the clip's row as the
    run wrote it, and the name its variants' scenes start with."""

    label: str
    scene: str
    frames: tuple[FramePlace, ...]
    first_timestamp_us: int
    last_timestamp_us: int
    timestamps_us: tuple[int, ...]
    row: Mapping[str, Any]
    name: str


def program_hash(row: Mapping[str, Any]) -> str:
    """What a clip's variants are drawn from in its row: the clip program's text and boundaries (32 hex digits)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(str(row["program"]).encode() + b"\0" + str(row["boundaries"]).encode())
    return h.hexdigest()


def simulation_key(row: Mapping[str, Any], clip_hash: str) -> str:
    """A clip's simulation row's frame_hash: its program's hash and its frames' (ClipSpec.unit_hash as read)."""
    return hashlib.blake2b(f"{program_hash(row)}\0{clip_hash}".encode(), digest_size=16).hexdigest()


@dataclass(frozen=True)
class SimulationTask(ClipTask):
    """Clips to simulate in one go (one, as the run plans them): a clip task whose synthesis is K simulations."""

    out: str = ""  # DIR: where the variants' frames files go
    simulator: Callable | None = None  # None: pipeline.simulation.simulate_clip

    schema = SIMULATION_SCHEMA

    @property
    def sim(self) -> SimulationSpec:
        return self.spec

    def run(self) -> pa.Table:
        _import_scenic()
        return super().run()

    def synthesize(self, scenes: list, unit: ClipUnit, digest: str) -> dict:
        """The clip's row with its simulation: its variants written to DIR/sim-<key>.parquet (none: no file)."""
        started = time.perf_counter()
        row, key = dict(unit.row), simulation_key(unit.row, digest)
        where = f"the clip program of {unit.label}"
        if digest != row["frame_hash"]:
            return self._failure(unit, "error", f"the frames of {unit.label} changed since its program was made: "
                                 "make the clip programs again (r2s run --clip) on these frames", len(scenes[0].others),
                                 digest)
        try:
            doc = {"program": row["program"], "boundaries": json.loads(row["boundaries"]),
                   "frames": row["n_frames"], "first_frame": row["frame_id"], "last_frame": row["last_frame"]}
            program, bounds, doc = read_program_json(json.dumps(doc), where)
            clip, boundaries = check_program(program, bounds, doc, scenes, self.config, where)
        except (UserError, ValueError) as exc:
            return self._failure(unit, "error", str(exc), len(scenes[0].others), digest)
        path = Path(self.out) / f"{FRAMES_PREFIX}{key}{FRAMES_SUFFIX}"
        limit = self.sim.time_limit if threading.current_thread() is threading.main_thread() else None
        # A worker's stdout is its run's: a library's print there is dropped (scenariogeneration printed the object
        # ids an earlier clip's road had used in the process, before pipeline.export.opendrive cleared its registries
        # per file)
        with tempfile.TemporaryDirectory(prefix="r2s-simulate-") as scratch, contextlib.redirect_stdout(io.StringIO()):
            first = Path(scratch) / "first.json"
            first.write_text(scenes[0].to_json(), encoding="utf-8")
            with frames_writer(path) as w:  # atomic: the file is whole, or absent
                result = (self.simulator or simulate_clip)(program, clip, boundaries, str(first), unit.name,
                                       lambda road: Path(self.maps), self.sim.n, self.sim.seed, limit, self.config,
                                       None, w.write_frame)
        if not result.written:
            path.unlink(missing_ok=True)
        row.update(frame_hash=key, config_hash=self.config_hash, version=ROWS_VERSION, error=None,
                   runtime_s=time.perf_counter() - started, peak_rss_mb=peak_rss_mb(), **self._simulation_fields(row),
                   written=result.written, rejected_by_scenic=result.count("rejected by Scenic"),
                   timed_out=result.count("timed out"), rejected_by_checker=result.count("rejected by the checker"),
                   variants=json.dumps([v.to_json_dict() for v in result.variants]),
                   not_simulated=list(result.not_simulated), frames_file=path.name if result.written else None)
        return row

    def _window_fields(self, unit: ClipUnit) -> dict:
        """The clip's own columns, as the run wrote them."""
        return {c: unit.row[c] for c in ("frame_id", "scene", "last_frame", "first_timestamp_us", "last_timestamp_us",
                                         "n_frames", "clip_s", "timestamps_us")}

    def _simulation_fields(self, row: Mapping[str, Any]) -> dict:
        return {"program_hash": program_hash(row), "seed": self.sim.seed, "variants_asked": self.sim.n}

    def _failure(self, unit: ClipUnit, status: str, message: str, n_entities: int, digest: str | None,
                 runtime_s: float = 0.0, peak_mb: float = 0.0) -> dict:
        """The clip's row without variants (the stage's failure row: error, memout, a dead worker), keyed as a
        simulated one, so that a resume keeps the verdict for the same program and frames."""
        row = super()._failure(unit, status, message, n_entities,
                               None if digest is None else simulation_key(unit.row, digest), runtime_s, peak_mb)
        keep = {c: unit.row.get(c) for c in ("program", "boundaries", "cost", "lower_bound", "duration_s",
                                              "relational_cost", "behaviours_s")}
        return {**row, **keep, **self._simulation_fields(unit.row), "written": 0}


def _import_scenic() -> None:
    """Scenic and what its scenarios load (the Newtonian simulator, the driving domain, OpenCV), imported once per
    worker before its first clip: as pipeline.batch.task's module imports, paid outside a clip's memory cap (under it
    a shared object that cannot be mapped is an ImportError, not the clip's memout)."""
    import scenic.core.sensors  # noqa: F401
    import scenic.domains.driving.roads  # noqa: F401
    import scenic.simulators.newtonian  # noqa: F401


class SimulationStore(RunStore):
    """The stage's store of the clips' rows, in DIR/_simulations, which also owns DIR's frames files and maps: DIR
    holds nothing else, a frames file no kept row names is removed before the run computes, and DIR/_maps is the
    recording's maps as they are now."""

    def __init__(self, out: Path, maps: Path) -> None:
        super().__init__(out / STATUS_DIR, SIMULATION_SCHEMA)
        self.dir, self.maps = out, maps

    def check_writable(self) -> None:
        if self.dir.exists():
            if not self.dir.is_dir():
                raise UserError(f"--out {self.dir} is a file; r2s simulate writes a frames dataset (a directory)")
            foreign = sorted(p.name for p in self.dir.iterdir() if not _ours(p))
            if foreign:
                raise UserError(f"--out {self.dir} holds files that are not r2s simulate's ({', '.join(foreign[:3])}); "
                                "choose an empty or new directory")
        super().check_writable()

    def remove_temporaries(self) -> None:
        """Called once the resume plan is applied: the rows left are the kept ones."""
        super().remove_temporaries()
        named = set()
        for path in self.sources():
            named.update(f for f in pq.read_table(path, columns=["frames_file"]).column(0).to_pylist() if f)
        for p in self.dir.iterdir():
            if p.is_file() and (p.name.startswith(FRAMES_PREFIX) and p.name not in named
                                or p.name.startswith(f".{FRAMES_PREFIX}") and p.name.endswith(".tmp")):
                p.unlink()
        self._copy_maps()

    def _copy_maps(self) -> None:
        target = self.dir / "_maps"
        target.mkdir(exist_ok=True)
        sources = {p.name: p for p in self.maps.glob("*.parquet")} if self.maps.is_dir() else {}
        for p in target.iterdir():
            if p.name not in sources:
                p.unlink() if p.is_file() else shutil.rmtree(p)
        filecmp.clear_cache()  # compared as they are now, not as an earlier run in this process saw them
        for name, source in sources.items():
            copy = target / name
            if not copy.exists() or not filecmp.cmp(source, copy, shallow=False):  # compared in chunks
                with atomic_path(copy) as tmp:
                    shutil.copyfile(source, tmp)


def _ours(p: Path) -> bool:
    """What r2s simulate writes in DIR: its rows' folder and their lock, its maps, its frames files (and their
    temporaries)."""
    if p.name in (STATUS_DIR, "_maps"):
        return p.is_dir()
    return p.is_file() and (p.name == f".{STATUS_DIR}.lock" or p.name.startswith((FRAMES_PREFIX, f".{FRAMES_PREFIX}")))


class _SimulationRun(_WindowRun):
    """The stage's run whose units are the run output's clips, each simulated by a SimulationTask."""

    unit = "clips"
    verb = "r2s simulate"

    def __init__(self, frames: str, out: Path, config: SynthConfig, options: RunOptions,
                 log: Callable[[str], None], run_output: Path, spec: SimulationSpec,
                 simulator: Callable | None = None) -> None:
        super().__init__(frames, out, config, options, log)
        self.run_output, self._spec, self._simulator = run_output, spec, simulator

    @property
    def schema(self):
        return SIMULATION_SCHEMA

    @property
    def spec(self):
        return self._spec

    def _store(self) -> RunStore:
        return SimulationStore(self.out, self._frames_maps())

    def _frames_maps(self) -> Path:
        return maps_dir(self.frames)

    def _task_type(self):
        return functools.partial(SimulationTask, out=str(self.out), simulator=self._simulator)

    def _wall_guard_s(self) -> float | None:
        # A clip is K simulations (each under --time-limit) and a compile: no guard without a limit.
        t = self.spec.time_limit
        return None if t is None else self.spec.n * (3.0 * t + 10.0) + 120.0

    def _units(self, dataset) -> tuple[int, Any, Any, str]:
        if self._maps(dataset) is None:
            raise UserError(f"{self.frames}: r2s simulate runs on the recorded road: give local frames with their "
                            "maps beside them (as r2s extract writes them)")
        rows, self._skipped = _clip_rows(self.run_output)
        hasher = FrameHasher(keep_lanes=True, coverage=self._coverage(dataset))
        dataset.check(hasher, road=True)  # refuses bad input; keeps each frame's hash
        scenes: dict[str, list] = {}
        for place, scene, index, stamp in frame_places(dataset):
            scenes.setdefault(scene, []).append((-1 if index is None else index, place, stamp))
        at = {}
        for scene, frames in scenes.items():
            frames.sort(key=lambda f: f[0])
            at.update({f[1].frame_id: (scene, i) for i, f in enumerate(frames)})
        units = []
        for row in rows:
            units.append(_unit(row, scenes, at, self.frames, self.run_output))
        self._windows = units
        ids = [p.frame_id for u in units for p in u.frames]
        lane0, lane1 = hasher.lanes(ids) if ids else (np.zeros(0, np.uint64), np.zeros(0, np.uint64))
        keys, k = [], 0
        for u in units:
            m = len(u.frames)
            keys.append(simulation_key(u.row, self.spec.unit_hash(u, ids[k:k + m], lane0[k:k + m], lane1[k:k + m])))
            k += m
        hi, lo = frame_hashes([u.frames[0].frame_id for u in units])
        a, b, _ = from_hex(pa.array(keys, pa.string()))
        return len(units), FrameIndex(hi, lo), FrameIndex(*frame_keys(hi, lo, a, b)), \
            self.spec.config_hash(self.config)

    def _log_plan(self, plan, n_units: int, dataset) -> None:
        super()._log_plan(plan, n_units, dataset)
        if self._skipped:
            self.log(f"{self._skipped} clip row(s) of {self.run_output} have no program (status error or timeout): "
                     "not simulated")

    _skipped = 0

    def _locked(self, store, dataset, n_units: int, plan) -> Summary:
        summary = super()._locked(store, dataset, n_units, plan)
        counts = _variant_counts(store)
        self.log(f"{counts['variants_asked']:,} variants asked: {counts['written']:,} written, "
                 f"{counts['rejected_by_scenic']:,} rejected by Scenic, {counts['timed_out']:,} timed out, "
                 f"{counts['rejected_by_checker']:,} rejected by the checker -> {self.out}")
        return summary


def _clip_rows(run_output: Path) -> tuple[list[dict], int]:
    """The clip rows of an `r2s run --clip` output that hold a program, in file order, and how many hold none;
    anything but a clip output one line."""
    try:
        files = programs_files(run_output)
    except ProgramsError as exc:
        raise UserError(f"{exc}: give a clip output ({HOW})") from None
    rows, skipped = [], 0
    for f in files:
        try:
            names = pq.read_schema(f).names
            if "clip_s" not in names or "program" not in names:
                raise UserError(f"{f} holds no clip programs (no clip_s column): give a clip output ({HOW})")
            if "variants_asked" in names:
                raise UserError(f"{f} holds simulated clips (r2s simulate's rows): give a clip output ({HOW})")
            table = pq.read_table(f, columns=CLIP_SCHEMA.names)
        except (pa.ArrowException, OSError, KeyError, ValueError) as exc:
            raise UserError(f"{f} is not a readable clip output ({str(exc)[:120]}): give one ({HOW})") from None
        for r in table.to_pylist():
            if r["program"] is None:
                skipped += 1
            else:
                rows.append(r)
    return rows, skipped


def _unit(row: dict, scenes: dict, at: dict, frames: str, run_output: Path) -> ClipUnit:
    """The clip of a run output's row: its frames in FRAMES (in frame_index order, from its first frame, as many as
    the row says, the last one the row's); a frame missing refuses the run."""
    label = f"{row['frame_id']}..{row['last_frame']}"
    first = at.get(row["frame_id"])
    scene_frames = scenes.get(first[0], []) if first else []
    picked = scene_frames[first[1]:first[1] + row["n_frames"]] if first else []
    if not picked or len(picked) != row["n_frames"] or picked[-1][1].frame_id != row["last_frame"]:
        raise UserError(f"{frames} lacks frames of the clip {label} of {run_output} (its {row['n_frames']} frames "
                        "in order): give the frames the run was made from")
    stamps = tuple(f[2] for f in picked)
    name = f"{first[0]}-clip{picked[0][0]:06d}"
    return ClipUnit(label, first[0], tuple(f[1] for f in picked), stamps[0], stamps[-1], stamps, row, name)


def _variant_counts(store: RunStore) -> dict[str, int]:
    columns = ["variants_asked", "written", "rejected_by_scenic", "timed_out", "rejected_by_checker"]
    counts = dict.fromkeys(columns, 0)
    for path in store.sources():
        table = pq.read_table(path, columns=columns)
        for c in columns:
            counts[c] += int(np.nansum(table.column(c).to_numpy(zero_copy_only=False).astype(float)))
    return counts
