"""What a fitter of the robustness bench reports (`FitOutcome`), what a fitter is (`Fitter`), ours
(`ModalFitter`: `vi.fit` without a scene, read by `outcome_from_summary`), and what ours and the
peers (`vibinverse.bench.robustness_peers`) share: a failed fit's outcome, the line and mode
detection threshold, and silence while fitting."""

from __future__ import annotations

import contextlib
import io
import logging
import math
import time
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any, Protocol

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


@dataclass
class ModalFitter:
    """Ours: `vi.fit` with the scene-less modal model; `fixed` False chooses the order by BIC (no
    scene), True fits the analyst's order with drift and AR(1) noise."""

    method: str = "auto"
    fixed: bool = False
    noise: str = "ar1"
    name: str = ""

    def __post_init__(self) -> None:
        self.name = self.name or ("ours-fixed" if self.fixed else "ours")

    def fit(self, t: np.ndarray, y: np.ndarray, order: tuple[int, int] | None = None) -> FitOutcome:
        import vibinverse as vi

        t0 = time.perf_counter()
        try:
            series = vi.series(t, y, source="robustness bench")
            if self.fixed:
                k, m = order if order is not None else (1, 1)
                scene = {"modal": {"modes": int(k), "lines": int(m), "drift": True, "noise": self.noise, "gain": False}}
            else:
                scene = None
            with quiet():
                result = vi.fit(series, scene, method=self.method)
            out = outcome_from_summary(result.summary())
        except Exception as exc:  # noqa: BLE001 - a failed fit is a result of the bench
            return failed_outcome(t0, exc)
        out.seconds = time.perf_counter() - t0
        return out


def outcome_from_summary(summary: dict[str, Any]) -> FitOutcome:
    """A FitOutcome from a modal fit's summary: `modes[i].*`, `lines[j].*`, their q05/q95, and the
    detection tests `mode_{i}_detected`, `line_{j}_detected` of the diagnostics (a component with
    no test counts as claimed). Where the fit reports that a resonance's values depend on a line the
    data cannot decide (an ambiguous reading with `intervals`), its intervals are the union of the
    two readings': what the report tells the analyst. `posterior` is the summary's approximation
    ("importance", "laplace"), or "emcee" where the fit has posterior draws."""
    p = summary["parameters"]
    diag = summary.get("diagnostics", {})
    out = FitOutcome(posterior=str(summary.get("approximation") or "emcee"))  # no approximation: draws of emcee
    i = 0
    while f"modes[{i}].frequency" in p:
        out.frequencies.append(float(p[f"modes[{i}].frequency"]["median"]))
        out.damping_ratios.append(float(p[f"modes[{i}].damping_ratio"]["median"]))
        out.modes_detected.append(bool(diag.get(f"mode_{i}_detected", True)))
        i += 1
    j = 0
    while f"lines[{j}].frequency" in p:
        out.line_frequencies.append(float(p[f"lines[{j}].frequency"]["median"]))
        out.line_amplitudes.append(float(p[f"lines[{j}].amplitude"]["median"]))
        out.lines_detected.append(bool(diag.get(f"line_{j}_detected", True)))
        j += 1
    for name, entry in p.items():
        if name.startswith(("modes[", "lines[")) and entry.get("q05") is not None and entry.get("q95") is not None:
            out.intervals[name] = (float(entry["q05"]), float(entry["q95"]))
    for reading in diag.get("ambiguous") or []:  # a resonance's values that depend on an undecided line
        for name, (lo, hi) in (reading.get("intervals") or {}).items():
            if name.startswith("modes[") and name in out.intervals:
                a, b = out.intervals[name]
                out.intervals[name] = (min(a, float(lo)), max(b, float(hi)))
    return out


# ------------------------------------------------------------------ which fitters can run
