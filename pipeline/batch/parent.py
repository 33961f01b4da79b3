"""A worker process of a pool (`r2s run`, `r2s extract --jobs`) ends with the process that started it.

Light on purpose (no numpy, no synth): it is the workers' initializer, imported before anything else they do.
"""

from __future__ import annotations

import os
import threading
import time


def watch_parent(parent: int, every_s: float = 0.5) -> None:
    """A worker's initializer: end this process as soon as `parent` (the run that started it) is gone. A worker
    otherwise finds out only when it asks for its next task, after the frame it is running (minutes, or never
    for a hung one), and a killed run (kill -9, the OOM killer) would leave its workers computing for nobody.
    A thread polls the parent id (it changes when the parent dies: the orphan is re-parented); os._exit, since
    the worker has nothing to save. Not prctl(PR_SET_PDEATHSIG): it fires when the thread that forked the
    worker ends, and loky forks from threads that may end before the run does."""
    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(every_s)
        os._exit(70)

    if os.getppid() != parent:  # died before this worker got here
        os._exit(70)
    threading.Thread(target=watch, name="r2s-watch-parent", daemon=True).start()
