"""Bench work in processes with a wall-clock limit: each `Step` (a function and its arguments) runs
in its own forked process, killed at its limit; a `Job` is a generator of steps that is sent each
step's `StepResult` (so a fit can follow its detection), and `run_jobs` keeps at most `workers`
steps running. Used by `vibinverse bench --realdata` and `--calibration`."""

from __future__ import annotations

import logging
import multiprocessing as mp
import os
import time
from collections import deque
from collections.abc import Callable, Generator, Sequence
from dataclasses import dataclass
from multiprocessing.connection import wait
from typing import Any

LOG = logging.getLogger(__name__)


@dataclass(frozen=True)
class Step:
    """One unit of work in its own process: `fn(*args)` (returning a picklable dict) within `limit_s`."""

    name: str
    fn: Callable[..., dict[str, Any]]
    args: tuple
    limit_s: float
    label: str = ""  # what it works on, for the log


@dataclass
class StepResult:
    """How a step ended: status "ok" (value set), "error" (error set) or "timeout"; its wall time."""

    status: str
    seconds: float
    value: dict[str, Any] | None = None
    error: str = ""


def _child(conn: Any, fn: Callable[..., dict[str, Any]], args: tuple, threads: int) -> None:
    from threadpoolctl import threadpool_limits

    from vibinverse.bench.robustness_fit import quiet
    from vibinverse.parallel import WORKERS_VARIABLE

    os.environ.setdefault(WORKERS_VARIABLE, str(threads))  # its share of the cores, unless the user set it
    t0 = time.perf_counter()
    try:
        with threadpool_limits(1), quiet():
            value = fn(*args)
        conn.send(StepResult("ok", time.perf_counter() - t0, value))
    except Exception as exc:  # noqa: BLE001 - a failure is a result of the bench
        text = (str(exc).strip().splitlines() or [""])[0][:160]
        conn.send(StepResult("error", time.perf_counter() - t0, error=f"{type(exc).__name__}: {text}"))
    finally:
        conn.close()


Job = Generator[Step, StepResult, list[dict[str, Any]]]


def run_jobs(jobs: Sequence[Job], workers: int = 1) -> list[list[dict[str, Any]]]:
    """Run each job (a generator that yields Steps, is sent their StepResults and returns its rows),
    at most `workers` steps at once, each in a forked process killed at its limit; a job's next
    step goes ahead of the jobs not started. Returns each job's rows, in order."""
    from vibinverse.parallel import available_cores

    ctx = mp.get_context("fork")
    threads = max(1, available_cores() // max(1, workers))  # each step's share of the cores
    results: list[list[dict[str, Any]]] = [[] for _ in jobs]
    ready: deque[tuple[int, Step]] = deque()
    running: dict[Any, tuple[int, Step, Any, float]] = {}

    def advance(i: int, sent: StepResult | None, first: bool = False) -> None:
        try:
            step = next(jobs[i]) if sent is None else jobs[i].send(sent)
        except StopIteration as stop:
            results[i] = stop.value or []
            return
        (ready.append if first else ready.appendleft)((i, step))

    for i in range(len(jobs)):
        advance(i, None, first=True)
    while ready or running:
        while ready and len(running) < max(1, workers):
            i, step = ready.popleft()
            recv, send = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_child, args=(send, step.fn, step.args, threads), daemon=True)
            proc.start()
            send.close()
            running[recv] = (i, step, proc, time.perf_counter())
        now = time.perf_counter()
        deadline = min(t0 + step.limit_s for _, step, _, t0 in running.values())
        for conn in wait(list(running), timeout=max(0.0, deadline - now)):
            i, step, proc, t0 = running.pop(conn)
            try:
                res: StepResult = conn.recv()
            except EOFError:
                proc.join(5)
                res = StepResult("error", time.perf_counter() - t0, error=f"process ended (exit {proc.exitcode})")
            conn.close()
            proc.join(5)
            how = f"{res.status}: {res.error}" if res.error else res.status
            LOG.info(f"  {step.label} {step.name}: {how} ({res.seconds:.0f} s)")
            advance(i, res)
        now = time.perf_counter()
        for conn in [c for c, (_, step, _, t0) in running.items() if now - t0 > step.limit_s]:
            i, step, proc, t0 = running.pop(conn)
            proc.kill()
            proc.join(5)
            conn.close()
            LOG.info(f"  {step.label} {step.name}: no answer within {step.limit_s:g} s")
            advance(i, StepResult("timeout", step.limit_s))
    return results
