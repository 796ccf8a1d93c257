"""Threads for independent evaluations whose work runs in numba kernels that release the GIL (the
Kalman filter, Whittle's density): `thread_map`. The models keep their scratch arrays per thread
(`ModalModel._scratch`), so one model may be evaluated from several threads at once."""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

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
