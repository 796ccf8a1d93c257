"""What a fitter of the robustness bench reports (`FitOutcome`), what a fitter is (`Fitter`), and
what ours and the peers (`vibinverse.bench.robustness_peers`) share: a failed fit's outcome, the
line and mode detection threshold, and silence while fitting."""

from __future__ import annotations

import contextlib
import io
import logging
import math
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from vibinverse.detection import DETECTION_GAIN  # the peers' line tests pass the threshold ours do


@dataclass
class FitOutcome:
    """What a fitter reports: mode frequencies and damping ratios, line frequencies and amplitudes
    (each in the fitter's own order), 90 % intervals (q05, q95) by name (`modes[i].frequency`,
    `modes[i].damping_ratio`, `lines[j].frequency`, `lines[j].amplitude`) where it has them, which
    components passed its detection test, what formed the intervals (`posterior`: "emcee",
    "importance", "laplace", ...; "" where the fitter does not say), the wall time, and whether it
    failed (with a note)."""

    frequencies: list[float] = field(default_factory=list)
    damping_ratios: list[float] = field(default_factory=list)
    line_frequencies: list[float] = field(default_factory=list)
    line_amplitudes: list[float] = field(default_factory=list)
    intervals: dict[str, tuple[float, float]] = field(default_factory=dict)
    lines_detected: list[bool] = field(default_factory=list)
    modes_detected: list[bool] = field(default_factory=list)
    posterior: str = ""
    seconds: float = 0.0
    failed: bool = False
    note: str = ""


class Fitter(Protocol):
    """A method of the comparison. `order` (modes, lines) is the order an analyst expects; a
    fitter that chooses its order from the data ignores it."""

    name: str

    def fit(self, t: np.ndarray, y: np.ndarray, order: tuple[int, int] | None = None) -> FitOutcome: ...


def failed_outcome(t0: float, exc: BaseException) -> FitOutcome:
    """The outcome of a fit started at `t0` (perf_counter) that raised `exc`: failed, its first line as the note."""
    text = (str(exc).strip().splitlines() or [""])[0][:120]
    return FitOutcome(seconds=time.perf_counter() - t0, failed=True, note=f"{type(exc).__name__}: {text}")


def detection_threshold(band: float, span: float) -> float:
    """The gain in log-likelihood a component must pass: `vibinverse.detection`'s 12.5 + ln(band x span)."""
    return DETECTION_GAIN + math.log(max(1.0, band * span))


@contextlib.contextmanager
def quiet() -> Iterator[None]:
    """No prints, progress bars or warnings from a fitter."""
    logging.disable(logging.WARNING)
    try:
        with (
            warnings.catch_warnings(),
            contextlib.redirect_stdout(io.StringIO()),
            contextlib.redirect_stderr(io.StringIO()),
        ):
            warnings.simplefilter("ignore")
            yield
    finally:
        logging.disable(logging.NOTSET)
