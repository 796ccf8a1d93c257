"""Feedback while a long step runs: a spinner with a message and the seconds so far on a terminal,
one log line elsewhere (a log file, CI), and the step's duration when it ends."""

from __future__ import annotations

import itertools
import logging
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

logger = logging.getLogger("vibinverse")

FRAMES = "|/-\\"
INTERVAL = 0.2  # s between frames


@contextmanager
def spinner(message: str, *, stream=None) -> Iterator[None]:
    """Show `message` while the block runs: animated with the elapsed seconds when `stream`
    (default stderr) is a terminal and the package logs at INFO, else logged once at INFO. The
    duration is logged at the end either way."""
    stream = stream if stream is not None else sys.stderr
    animate = bool(getattr(stream, "isatty", lambda: False)()) and logger.isEnabledFor(logging.INFO)
    t0 = time.perf_counter()
    stop = threading.Event()
    thread = None
    if animate:

        def run() -> None:
            for frame in itertools.cycle(FRAMES):
                stream.write(f"\r{frame} {message} {time.perf_counter() - t0:4.0f} s")
                stream.flush()
                if stop.wait(INTERVAL):
                    break
            stream.write("\r" + " " * (len(message) + 10) + "\r")
            stream.flush()

        thread = threading.Thread(target=run, daemon=True)
        thread.start()
    else:
        logger.info("%s ...", message)
    try:
        yield
    finally:
        stop.set()
        if thread is not None:
            thread.join()
        logger.info("%s: %.1f s", message, time.perf_counter() - t0)
