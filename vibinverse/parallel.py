"""Threads for independent evaluations whose work runs in numba kernels that release the GIL (the
Kalman filter, Whittle's density): `thread_map`, and how many a fit uses when not told
(`default_workers`). The models keep their scratch arrays per thread (`ModalModel._scratch`), so
one model may be evaluated from several threads at once."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

from vibinverse.errors import InputError

#: the threads a fit uses when not told (`default_workers`): more add little to Whittle's
#: memory-bound density and the order search's few candidates a step
MAX_DEFAULT_WORKERS = 4
#: the environment variable that sets a fit's default threads (`default_workers`)
WORKERS_VARIABLE = "VIBINVERSE_WORKERS"

T = TypeVar("T")
R = TypeVar("R")


def thread_map(fn: Callable[[T], R], items: Iterable[T], workers: int = 1, name: str = "vibinverse") -> list[R]:
    """[fn(x) for x in items], on `workers` threads when there are more than one and more than one
    item; the results in the items' order (the same numbers as one thread: each call independent).
    The first exception raised is raised here."""
    items = list(items)
    if workers <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    with ThreadPoolExecutor(min(workers, len(items)), thread_name_prefix=name) as pool:
        return list(pool.map(fn, items))


def available_cores() -> int:
    """The cores this process may run on (its CPU affinity; the machine's count elsewhere)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def default_workers() -> int:
    """The threads a fit runs on when `workers` is not given: $VIBINVERSE_WORKERS when set (as
    OMP_NUM_THREADS is for OpenMP: a test runner or a bench that runs fits side by side sets it to
    its share), else the cores this process may use, at most MAX_DEFAULT_WORKERS. Threads only: a
    likelihood that holds the GIL is sampled in processes only when asked (`workers` given)."""
    told = os.environ.get(WORKERS_VARIABLE, "").strip()
    if told:
        if not told.isdigit() or int(told) < 1:
            raise InputError(f"{WORKERS_VARIABLE}: {told!r}; allowed: an integer >= 1")
        return int(told)
    return min(available_cores(), MAX_DEFAULT_WORKERS)
