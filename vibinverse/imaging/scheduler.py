"""Where Dask work runs: dask's threaded scheduler on this machine (default), or an existing
`dask.distributed` cluster given by its scheduler address (`--scheduler tcp://host:8786`).

    with session(scheduler=None, workers=2) as run:
        a, b = run.compute(x, y)          # any dask collections (arrays, delayed)
    a, b = compute(x, y, scheduler="tcp://10.0.0.5:8786")

The same graph runs either way; a session keeps one connection to a cluster for several passes.
Exceptions raised inside tasks come back as themselves (a `DataError` stays a `DataError`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
from collections.abc import Iterator
from typing import Any

import dask

from vibinverse.errors import InputError

logger = logging.getLogger(__name__)

CONNECT_TIMEOUT = 10.0  # s to reach a scheduler before giving up (distributed's default is 30 s)
PROGRESS_MINIMUM = 1.0  # s: a local computation shorter than this shows no progress bar


def default_workers() -> int:
    """Threads of the local scheduler when none is given: the cores this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # not Linux
        return max(1, os.cpu_count() or 1)


def check_workers(workers: int | None) -> int | None:
    """`workers` as given, or a one-line InputError when it is not a positive integer."""
    if workers is None:
        return None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise InputError(f"--workers: {workers!r} is not a number of threads (an integer >= 1)")
    return workers


class Runner:
    """Runs dask collections on one scheduler (made by `session`)."""

    def __init__(self, threads: int, client: Any = None, progress: bool = False) -> None:
        self.threads = threads  # threads that run tasks at once (local, or summed over the cluster)
        self.client = client  # a distributed.Client, or None for the local threaded scheduler
        self.progress = progress

    @property
    def address(self) -> str | None:
        """The cluster's scheduler address, or None for the local scheduler."""
        return None if self.client is None else str(self.client.scheduler.address)

    def compute(self, *collections: Any) -> tuple:
        """The collections computed (a tuple, as `dask.compute`)."""
        if not collections:
            return ()
        if self.client is not None:
            return tuple(self.client.compute(list(collections), sync=True))
        with self._bar():
            return dask.compute(*collections, scheduler=_threads(), num_workers=self.threads)

    def persist(self, *collections: Any) -> tuple:
        """The collections with their results kept in memory (local) or on the workers (cluster)."""
        if not collections:
            return ()
        if self.client is not None:
            return tuple(self.client.persist(list(collections)))
        with self._bar():
            return dask.persist(*collections, scheduler=_threads(), num_workers=self.threads)

    def _bar(self) -> contextlib.AbstractContextManager:
        if not self.progress:
            return contextlib.nullcontext()
        from dask.diagnostics import ProgressBar

        return ProgressBar(minimum=PROGRESS_MINIMUM, out=sys.stderr)


def _threads() -> Any:
    """dask's threaded scheduler as a function: named ("threads"), dask imports distributed to look
    for a client first (0.1-0.3 s in a fresh process)."""
    import dask.threaded

    return dask.threaded.get


@contextlib.contextmanager
def session(
    scheduler: str | None = None,
    workers: int | None = None,
    *,
    progress: bool = False,
    timeout: float = CONNECT_TIMEOUT,
) -> Iterator[Runner]:
    """A `Runner` for the block: `scheduler` None -> dask's threaded scheduler with `workers` threads
    (default: this machine's cores); an address -> a `dask.distributed.Client` connected to it (the
    cluster's own workers run the tasks; `workers` is then ignored). One-line InputError naming
    --scheduler when the address is malformed or does not answer within `timeout` seconds, or when
    dask.distributed is not installed."""
    workers = check_workers(workers)
    if scheduler is None:
        yield Runner(workers or default_workers(), progress=progress)
        return
    try:
        from distributed import Client
    except ImportError:
        raise InputError(
            "--scheduler: needs dask.distributed, which is not installed (pip install 'vibinverse[imaging]')"
        ) from None
    if workers is not None:
        logger.warning("--workers is ignored with --scheduler: the cluster's own workers run the tasks")
    try:
        client = Client(str(scheduler), timeout=timeout, set_as_default=False)
    except (OSError, ValueError, TypeError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise InputError(f"--scheduler: cannot connect to {scheduler!r} ({reason})") from None
    try:
        threads = max(1, sum(client.nthreads().values()))
        logger.info(f"dask: {len(client.nthreads())} workers, {threads} threads at {client.scheduler.address}")
        yield Runner(threads, client=client, progress=progress)
    finally:
        client.close()


def compute(*collections: Any, scheduler: str | None = None, workers: int | None = None) -> tuple:
    """Compute dask collections on the local threaded scheduler or a cluster (`session`)."""
    with session(scheduler, workers) as run:
        return run.compute(*collections)
