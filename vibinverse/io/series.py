"""Measured series: read CSV / TSV / Parquet / .npy / .npz / netCDF / LabVIEW lvm, validate, and
report gaps. The readers of the formats are in `vibinverse.io.readers` (and `vibinverse.io.lvm`).

A NaN intensity is a gap (a missing sample): kept, counted and handled by the likelihoods. Every
problem raises `vibinverse.errors.DataError` with one line naming it.
"""

from __future__ import annotations

import copy
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError
from vibinverse.io.file_basics import (
    TIME_REFERENCE_NOTE,
    UNITS_NOTE,
    evenly_spaced,
    first_line,
    positive_option,
    real_numbers,
)
from vibinverse.io.readers import OPTIONS, reader_for

#: the fewest cycles of a frequency the record must hold for a prior to reach it (a structure
#: swaying through one or two cycles in a clip is still fitted, and flagged: FEW_CYCLES)
MIN_CYCLES = 1.0
#: below this many cycles in the record a frequency is poorly constrained, and the summary says so
FEW_CYCLES = 3.0


def _noted(notes: list[str], prefix: str) -> str | None:
    """The text after `prefix` of the first note that starts with it."""
    return next((n[len(prefix) :].strip() for n in notes if n.startswith(prefix)), None)


@dataclass(frozen=True)
class Series:
    time: NDArray[np.float64]
    intensity: NDArray[np.float64]  # NaN = gap
    source: str
    scene: dict[str, Any] | None = None  # the true scene, when the file carries it (vibinverse simulate)
    notes: list[str] = field(default_factory=list)  # what the reader recorded: a time reference, units
    #: the top (Hz) of the band where the record's spectrum is the process's: below a logger's
    #: anti-alias roll-off (`vibinverse.spectrum.passband_top`); None: up to Nyquist
    passband: float | None = None

    def __post_init__(self) -> None:
        """One value per stamp, both 1-D float arrays; else a one-line InputError naming the shapes."""
        t = np.asarray(self.time, dtype=float)
        y = np.asarray(self.intensity, dtype=float)
        if t.ndim != 1 or y.shape != t.shape:
            raise InputError(
                f"series {self.source}: time and intensity must be 1-D with one value per stamp; got shapes "
                f"{t.shape} and {y.shape}"
            )
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "intensity", y)

    @property
    def gaps(self) -> NDArray[np.bool_]:
        return ~np.isfinite(self.intensity)

    @property
    def n_gaps(self) -> int:
        return int(self.gaps.sum())

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.time)))

    @property
    def uniform(self) -> bool:
        """Whether the stamps lie on one regular grid to UNIFORM_RTOL of its step: camera stamps
        written with 9 significant digits (1e-8 s at 20 s) are uniform, jittered frames are not."""
        return evenly_spaced(self.time)

    @property
    def fs(self) -> float:
        return 1.0 / self.dt

    @property
    def top(self) -> float:
        """The highest frequency (Hz) a model of the record is fitted to: its `passband`, else Nyquist."""
        return float(self.passband) if self.passband is not None else 0.5 * self.fs

    @property
    def time_reference(self) -> str | None:
        """The date-time the stamps count seconds from, when the file gave one (ISO date-times, a
        netCDF axis with CF units `... since EPOCH`); None for plain seconds."""
        return _noted(self.notes, TIME_REFERENCE_NOTE)

    @property
    def intensity_units(self) -> str | None:
        """The intensity's units when the file gave them (a netCDF `units` attribute), else None."""
        units = _noted(self.notes, UNITS_NOTE)
        return None if units is None else units.split(" (")[0]

    def head(self, n: int) -> Series:
        """The first n samples (a leading stretch of the record), with the same source, scene and notes."""
        if not 2 <= n <= self.time.size:
            raise InputError(f"head: n must be in [2, {self.time.size}], got {n}")
        return replace(self, time=self.time[:n], intensity=self.intensity[:n])

    def describe(self) -> str:
        kind = f"uniform at {self.fs:g} Hz" if self.uniform else irregular_sampling(self.time)
        return (
            f"{self.time.size} samples over {self.time[-1] - self.time[0]:g} s, {kind}; "
            f"{self.n_gaps} gaps ({self.n_gaps / self.time.size:.1%})"
        )


def sampling_summary(t: NDArray[np.float64]) -> tuple[float, float, int]:
    """(median step s, jitter, dropped frames) of increasing stamps t: each step spans a whole
    number of median steps (frames, at least one), a frame missing between two stamps is dropped, and
    the jitter is the RMS deviation of the stamps from the least-squares regular grid of those frame
    numbers, as a fraction of its step (a drifting clock is a grid, not jitter)."""
    d = np.diff(t)
    step = float(np.median(d))
    frames = np.maximum(np.rint(d / step), 1.0)
    number = np.concatenate([[0.0], np.cumsum(frames)])
    basis = np.stack([np.ones_like(number), number], axis=1)
    coef = np.linalg.lstsq(basis, t - t[0], rcond=None)[0]
    jitter = float(np.sqrt(np.mean((t - t[0] - basis @ coef) ** 2)) / coef[1]) if coef[1] > 0 else 0.0
    return step, jitter, int(frames.sum() - frames.size)


def irregular_sampling(t: NDArray[np.float64]) -> str:
    """The one-line description of irregular stamps (`sampling_summary`)."""
    step, jitter, dropped = sampling_summary(t)
    return f"irregular sampling: median step {step:.6g} s, jitter {100 * jitter:.3g} % (rms), {dropped} dropped frames"


# The values a series may hold. Beyond them float64 arithmetic fails before any model does: the
# squares of 1e100 (1e200), and their sum over any number of samples, stay finite, and the square
# of a 1e-100 spread stays a normal float (> 2.2e-308), so a variance neither overflows to inf nor
# underflows to 0 (both happened: an infinite noise estimate at 1e300, a math domain error at 1e-300).
# No instrument, in any unit, gives values outside.
MAX_ABS = 1e100
MIN_SPREAD = 1e-100


def check_file(path: str | Path, what: str) -> Path:
    """The path of a non-empty regular file, else one-line DataError `what: ...` naming it."""
    p = Path(path)
    if p.is_dir():
        raise DataError(f"{what}: {p} is a directory, not a file")
    if not p.exists():
        raise DataError(f"{what}: file not found: {p}")
    if not p.is_file():
        raise DataError(f"{what}: {p} is not a regular file")
    try:
        empty = p.stat().st_size == 0
    except OSError as exc:
        raise DataError(f"{what}: cannot read {p}: {exc.strerror or exc}") from None
    if empty:
        raise DataError(f"{what}: {p} is empty")
    return p


def load_series(
    path: str | Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
) -> Series:
    """Read and validate a series; the reader is chosen by `vibinverse.io.readers.reader_for`. Formats:
    a table, CSV / TSV (delimiter sniffed from the header: comma, semicolon, tab or whitespace; '#'
    comment lines allowed, '# scene: {json}' carries the truth) or Parquet (.parquet), with columns
    `time_column` (default time) and `value_column` (default intensity), named case-insensitively,
    more named columns ignored; a time of ISO 8601 date-times (or datetime64) becomes seconds since
    the first sample (noted in `Series.notes`); `fs` (Hz) gives the time of a table without a time
    column, arange(n) / fs. Decimal commas are refused. Also .npy (N x 2), .npz (arrays 'time' and
    'intensity'; or named arrays, `value_column` choosing a 1-D array or a named column of a 2-D
    array, the time from an array 'time', a scalar fs / sample_rate, or `fs`), netCDF (.nc;
    variables 'time' and 'intensity'; a time with CF units, e.g. 'milliseconds since 2024-01-01', is
    converted to seconds since its epoch; the intensity's units are noted, its values kept) and
    LabVIEW Measurement files (.lvm, or any text file starting 'LabVIEW Measurement'; `value_column`
    chooses the channel by name or 0-based index; the time from its X_Value column, else X0 + Delta_X
    or `fs`; the channel's unit noted)."""
    p = check_file(path, "data")
    fs = positive_option(fs, "data: fs", "Hz", DataError)
    reader = reader_for(p)
    given = dict(zip(OPTIONS, (time_column, value_column, fs)))
    refused = [name for name, value in given.items() if value is not None and name not in reader.options]
    if refused:
        raise reader.refuse_options(p, refused)
    try:
        raw = reader.read(p, **given)
    except DataError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"data: cannot read {p}: {first_line(exc)}") from None
    return validate(raw.time, raw.intensity, str(p), raw.scene, raw.notes)


def validate(
    t: Any, x: Any, source: str = "array", scene: dict | None = None, notes: list[str] | None = None
) -> Series:
    """Check a series; NaN intensities are gaps, anything else non-finite is an error. Refused, each
    with one line: non-numeric, complex or boolean values, fewer than 16 samples, a time that is not
    strictly increasing (naming the first offending sample and both stamps), values beyond
    +-MAX_ABS, and an intensity that is constant (or varies by less than MIN_SPREAD): nothing to fit.
    Irregular stamps (jitter, dropped frames; off a regular grid by more than UNIFORM_RTOL of its
    step) are accepted and described in `notes` (`irregular_sampling`)."""
    t, x = real_numbers(t, "time"), real_numbers(x, "intensity")
    if t.ndim != 1 or x.ndim != 1 or t.size != x.size:
        raise DataError(f"data: time and intensity must be 1-D of equal length, got {t.shape} and {x.shape}")
    if t.size < 16:
        raise DataError(f"data: {t.size} samples; at least 16 are needed")
    if not np.all(np.isfinite(t)):
        raise DataError("data: time has non-finite values")
    _in_range(t, "time")
    if not np.all(np.diff(t) > 0):
        k = int(np.argmin(np.diff(t) > 0))
        a, b = _distinct(t[k + 1], t[k])
        raise DataError(f"data: time must be strictly increasing (sample {k + 1}: {a} after {b})")
    step = float(np.min(np.diff(t)))
    if step < MIN_SPREAD:
        raise DataError(f"data: a time step of {step:g} s; allowed: at least {MIN_SPREAD:g} s")
    if np.any(np.isinf(x)):
        raise DataError("data: intensity has infinite values (use NaN for missing samples)")
    good = x[np.isfinite(x)]
    if good.size < 16:
        raise DataError(f"data: only {good.size} valid samples; at least 16 are needed")
    _in_range(x, "intensity")
    lo, hi = float(good.min()), float(good.max())
    spread = hi - lo
    if spread <= 64 * np.finfo(float).eps * max(abs(lo), abs(hi)):  # equal, or equal but for rounding
        what = f"are {lo:g}" if spread == 0 else f"equal {lo:g} but for rounding"
        raise DataError(f"data: the intensity is constant (all {good.size} valid samples {what}); nothing to fit")
    if spread < MIN_SPREAD:
        raise DataError(
            f"data: the intensity varies by only {spread:g} (peak to peak); at least {MIN_SPREAD:g} is needed "
            "(rescale the data)"
        )
    notes = list(notes or [])
    series = Series(t, x, source, scene, notes)
    if not series.uniform:  # accepted: the frame model's filter steps exactly over each interval
        notes.append(f"time: {irregular_sampling(t)}")
    return series


def _distinct(a: float, b: float) -> tuple[str, str]:
    """a and b written with the fewest significant digits (at least 6) that tell them apart."""
    for digits in range(6, 18):
        sa, sb = f"{a:.{digits}g}", f"{b:.{digits}g}"
        if sa != sb:
            break
    return sa, sb


def _in_range(a: np.ndarray, what: str) -> None:
    big = np.abs(a) > MAX_ABS  # NaN compares False: gaps pass
    if big.any():
        k = int(np.argmax(big))
        raise DataError(
            f"data: {what} {a[k]:g} at sample {k} is outside the allowed range [{-MAX_ABS:g}, {MAX_ABS:g}] "
            "(rescale the data)"
        )


def check_resolves(series: Series, frequency_hz: float, what: str) -> None:
    """One-line error when the series cannot resolve `frequency_hz`: at or above Nyquist, or fewer than
    MIN_CYCLES cycles in the record."""
    nyquist = 0.5 * series.fs
    if frequency_hz >= nyquist:
        raise InputError(f"{what}: {frequency_hz:g} Hz is at or above the Nyquist frequency {nyquist:g} Hz of the data")
    span = series.time[-1] - series.time[0]
    if frequency_hz * span < MIN_CYCLES:
        raise InputError(
            f"{what}: {frequency_hz:g} Hz needs at least {MIN_CYCLES / frequency_hz:g} s of data "
            f"({MIN_CYCLES:g} cycle); the series spans {span:g} s"
        )


def with_sampling(table: dict, series: Series) -> dict:
    """The scene table sampled as the data are (its [sampling] only serves the scene's checks)."""
    out = copy.deepcopy(table)
    out["sampling"] = {
        "fs": series.fs,
        "duration": float(series.time[-1] - series.time[0]) + series.dt,
        "start": float(series.time[0]),
    }
    return out
