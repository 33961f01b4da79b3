"""Connecting `r2s run --backend dask` to a cluster. dask is imported here only, when that backend is asked for.

Without --scheduler a LocalCluster is started: one single-threaded worker *process* per job, so a frame never
shares a process with another frame or with the run (the worker's RSS is what the Budget's memory poll sees),
and dask's nanny replaces a worker that dies. The hard RLIMIT_AS cap of the loky backend is not used on dask
(a worker's process may be shared by threads); the Budget's poll and dask's own worker memory limit apply.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager

from pipeline.batch.pool import DaskPool
from pipeline.batch.task import one_line
from pipeline.errors import UserError

CONNECT_TIMEOUT_S = 10
WORKERS_TIMEOUT_S = 60


@contextmanager
def dask_pool(scheduler: str | None, jobs: int | None) -> Iterator[DaskPool]:
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise UserError("--backend dask needs dask.distributed (pip install '.[dask]')") from None
    with ExitStack() as stack:
        if scheduler:
            try:
                client = stack.enter_context(Client(scheduler, timeout=CONNECT_TIMEOUT_S))
            except (OSError, ValueError, TypeError) as exc:
                raise UserError(f"cannot reach the dask scheduler {scheduler}: {one_line(str(exc), 160)}") from None
        else:
            cluster = stack.enter_context(LocalCluster(
                n_workers=jobs or os.cpu_count() or 1, threads_per_worker=1, processes=True,
                dashboard_address=None, silence_logs=logging.CRITICAL,  # deaths are our log lines
            ))
            client = stack.enter_context(Client(cluster))
        try:
            client.wait_for_workers(1, timeout=WORKERS_TIMEOUT_S)
        except TimeoutError:
            raise UserError(f"the dask scheduler {scheduler} has no workers (waited {WORKERS_TIMEOUT_S} s)") from None
        yield DaskPool(client, jobs)
