"""Faults injected into `r2s run`'s workers from the tests: each frame runs `fault(SPEC)` instead of synthesize
(and each clip of `r2s simulate RUN_OUTPUT --frames FRAMES` `simulation_fault(SPEC)` instead of simulate_clip, FRAME_ID
the clip's first frame).

SPEC is ACTION[=ARG]@FRAME_ID (FRAME_ID "*": every frame). Actions: kill (the worker sends itself SIGKILL, as the
kernel's OOM killer would), exit (os._exit(3)), alloc=MB (touch MB of memory, under the frame's hard cap), raise,
sleep=S, hang; then the frame is synthesized as usual. dreal-crash and dreal-hang break the real dReal instead
(`make dreal`): its first call in the frame dies of SIGSEGV, as a native library does, or never returns, as a
native call that no time limit interrupts; they are what the real solver cannot be made to do on demand. The
fault is given to run_frames (or to a ChunkTask) as its `synthesizer`; the task carries it to the worker process
by reference to this module (tests.support.faults), which the workers import: loky and dask start them with the
parent's sys.path, where the repository's root is.

`python -m tests.support.faults SPEC VERB ARGS...` (from the repository's root) is the `r2s` command itself, with
the fault in every frame that run_frames gives its workers (real processes, real signals, real exit codes).
"""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import sys
import time

from pipeline.simulation import simulate_clip
from synth.smt.dreal_backend import load_dreal
from synth.synthesize import synthesize


def faulty_synthesize(spec: str, scene, config):
    _inject(spec, scene.frame_id)
    return synthesize(scene, config)


def faulty_simulate(spec: str, program, clip, *args):
    """pipeline.simulation.simulate_clip with SPEC injected into the clip whose first frame is FRAME_ID (`r2s simulate
    RUN_OUTPUT --frames FRAMES`'s workers: pipeline.batch.simulations)."""
    _inject(spec, clip.scenes[0].frame_id)
    return simulate_clip(program, clip, *args)


def _inject(spec: str, frame_id: str) -> None:
    action, _, target = spec.partition("@")
    if target in ("*", frame_id):
        name, _, arg = action.partition("=")
        if name == "kill":
            os.kill(os.getpid(), signal.SIGKILL)
        elif name == "exit":
            os._exit(3)
        elif name == "alloc":
            blocks = [bytearray(2**20) for _ in range(int(arg))]  # touched pages: RSS, not only address space
            del blocks
        elif name == "raise":
            raise RuntimeError(f"fault injected in frame {frame_id}")
        elif name == "sleep":
            time.sleep(float(arg))
        elif name == "hang":
            _hang()
        elif name in ("dreal-crash", "dreal-hang"):
            _break_dreal(name)
        else:
            raise ValueError(f"unknown fault {spec!r}")


def _hang():
    while True:
        time.sleep(1)


def _break_dreal(how: str) -> None:
    def broken(formula, delta):
        if how == "dreal-crash":
            os.kill(os.getpid(), signal.SIGSEGV)
        _hang()

    load_dreal().CheckSatisfiability = broken  # the worker dies or is killed: nothing to put back


def fault(spec: str):
    """The synthesizer that injects SPEC (picklable: a partial of a function of this module)."""
    return functools.partial(faulty_synthesize, spec)


def simulation_fault(spec: str):
    """The clip simulator that injects SPEC (a partial of a function of this module)."""
    return functools.partial(faulty_simulate, spec)


def r2s_with_fault(spec: str, *args: str) -> list[str]:
    """The command line of `r2s ARGS...` with SPEC injected into its frames (subprocess.run / Popen, with the
    repository's root as the working directory)."""
    return [sys.executable, "-m", "tests.support.faults", spec, *args]


@contextlib.contextmanager
def small_filesystem(path, size_kb: int = 64, read_only: bool = False):
    """A tmpfs of `size_kb` KB mounted at `path` (a full disk, or a read-only one, for real), unmounted after;
    skips the test where mounting is not allowed (not root, or no CAP_SYS_ADMIN in the container)."""
    import subprocess

    import pytest

    os.makedirs(path, exist_ok=True)
    options = f"size={size_kb}k" + (",ro" if read_only else "")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(path)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({mounted.stderr.decode().strip()[:80]}): needs root")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], capture_output=True)


def main(argv: list[str]) -> int:
    import pipeline.batch.simulations
    import pipeline.batch.stage
    from pipeline.cli import main as r2s

    spec, *args = argv
    # the verb imports run_frames (simulate_run) when it runs: it gets this one
    pipeline.batch.stage.run_frames = functools.partial(pipeline.batch.stage.run_frames, synthesizer=fault(spec))
    pipeline.batch.simulations.simulate_run = functools.partial(pipeline.batch.simulations.simulate_run,
                                                                simulator=simulation_fault(spec))
    return r2s(args)


if __name__ == "__main__":
    # this module under its importable name (not __main__): the tasks name its functions so
    from tests.support.faults import main as main_by_name

    sys.exit(main_by_name(sys.argv[1:]))
