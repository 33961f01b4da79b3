"""How `r2s run` runs, as one frozen value (what `run_frames` takes besides its input, output and config).

Light on purpose (no pyarrow, no synth), as the defaults it takes from pipeline.batch.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from pipeline.batch import DEFAULT_CHUNK_SIZE, DEFAULT_PART_ROWS
from pipeline.errors import UserError

BACKENDS = ("loky", "dask")


@dataclass(frozen=True)
class RunOptions:
    """`jobs`: workers (None: every core, or the cluster's threads); `backend`: loky (processes here) or dask
    (`scheduler`: its address, None for a local cluster); `chunk_size`: the most frames a task takes; `part_rows`:
    rows per part file; `log_every_s`: seconds between log lines without a terminal; `terminal`: force the progress
    bar on or off (None: a bar when stderr is a terminal); `synthesizer`: what each frame runs instead of
    synth.synthesize (a module-level function or a partial of one: the tasks carry it to the workers by
    reference)."""

    jobs: int | None = None
    backend: str = "loky"
    scheduler: str | None = None
    chunk_size: int = DEFAULT_CHUNK_SIZE
    part_rows: int = DEFAULT_PART_ROWS
    log_every_s: float = 30.0
    terminal: bool | None = None
    synthesizer: Callable | None = None
    # r2s run --window: one program per window of `window_s` seconds of a scene's frames (pipeline.batch.windows),
    # the next starting `stride_s` after (None: consecutive), no window across a gap of more than `max_gap_s`.
    window_s: float | None = None
    stride_s: float | None = None
    max_gap_s: float | None = None
    # r2s run --clip: one clip program per clip of `clip_s` seconds (pipeline.batch.clips), tiled as windows are.
    clip_s: float | None = None

    @property
    def window(self):
        """The window (or clip) options as a WindowSpec (a ClipSpec), or None for one program per frame."""
        if self.clip_s is not None:
            from pipeline.batch.clips import ClipSpec

            return ClipSpec(self.clip_s, self.stride_s, self.max_gap_s)
        if self.window_s is None:
            return None
        from pipeline.batch.windows import WindowSpec

        return WindowSpec(self.window_s, self.stride_s, self.max_gap_s)

    def check(self) -> None:
        """Refuse values no run can use (UserError: one line, exit 2), before anything is read or written."""
        if self.jobs is not None and self.jobs < 1:
            raise UserError(f"--jobs must be at least 1, got {self.jobs}")
        if self.chunk_size < 1:
            raise UserError(f"--chunk-size must be at least 1, got {self.chunk_size}")
        if self.part_rows < 1:
            raise UserError(f"--part-rows must be at least 1, got {self.part_rows}")
        if self.backend not in BACKENDS:
            raise UserError(f"unknown backend {self.backend!r} (backends: {', '.join(BACKENDS)})")
        if self.scheduler and self.backend != "dask":
            raise UserError("--scheduler needs --backend dask")
        if self.window_s is not None and self.clip_s is not None:
            raise UserError("--window and --clip are two kinds of rows: give one")
        if self.window is None and (self.stride_s is not None or self.max_gap_s is not None):
            raise UserError("--stride and --max-gap need --window or --clip")
        if self.window is not None:
            self.window.check()
            if self.synthesizer is not None:
                raise UserError(f"a synthesizer replaces one frame's synthesis; --{self.window.name} synthesizes "
                                f"{self.window.name}s")
