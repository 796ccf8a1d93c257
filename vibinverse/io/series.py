"""Measured series: read CSV / TSV / Parquet / .npy / .npz / netCDF, validate, and report gaps.

A NaN intensity is a gap (a missing sample): kept, counted and handled by the likelihoods. Every
problem raises `vibinverse.errors.DataError` with one line naming it.
"""

from __future__ import annotations

import copy
import csv as csvlib
import math
import re
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError
from vibinverse.io import jsonio

# a uniform grid's tolerance, relative to its step: a timing error of 1e-3 of a sample moves a line at
# Nyquist by 3e-3 rad, far below any phase a fit resolves
UNIFORM_RTOL = 1e-3
#: the fewest cycles of a frequency the record must hold for a prior to reach it (a structure
#: swaying through one or two cycles in a clip is still fitted, and flagged: FEW_CYCLES)
MIN_CYCLES = 1.0
#: below this many cycles in the record a frequency is poorly constrained, and the summary says so
FEW_CYCLES = 3.0
#: how the readers note a time reference and the intensity's units (`Series.notes`)
TIME_REFERENCE_NOTE = "time: seconds since "
UNITS_NOTE = "intensity units: "


def _noted(notes: list[str], prefix: str) -> str | None:
    """The text after `prefix` of the first note that starts with it."""
    return next((n[len(prefix) :].strip() for n in notes if n.startswith(prefix)), None)


def evenly_spaced(t: np.ndarray) -> bool:
    """Whether stamps `t` lie on one regular grid to UNIFORM_RTOL of its step."""
    step = (t[-1] - t[0]) / (t.size - 1)
    return bool(np.max(np.abs(t - (t[0] + np.arange(t.size) * step))) <= UNIFORM_RTOL * step)


@dataclass(frozen=True)
class Series:
    time: NDArray[np.float64]
    intensity: NDArray[np.float64]  # NaN = gap
    source: str
    scene: dict[str, Any] | None = None  # the true scene, when the file carries it (vibinverse simulate)
    notes: list[str] = field(default_factory=list)  # what the reader recorded: a time reference, units

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

_KINDS = {
    "U": "text",
    "S": "text (bytes)",
    "O": "Python objects",
    "b": "booleans",
    "c": "complex values",
    "M": "dates",
    "m": "time spans",
    "V": "records",
}
_HDF5 = b"\x89HDF\r\n\x1a\n"
_TIME_UNITS = {
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), 1.0),
    **dict.fromkeys(("ms", "msec", "msecs", "millisecond", "milliseconds"), 1e-3),
    **dict.fromkeys(("us", "\u00b5s", "microsecond", "microseconds"), 1e-6),
    **dict.fromkeys(("ns", "nanosecond", "nanoseconds"), 1e-9),
    **dict.fromkeys(("min", "mins", "minute", "minutes"), 60.0),
    **dict.fromkeys(("h", "hr", "hrs", "hour", "hours"), 3600.0),
    **dict.fromkeys(("d", "day", "days"), 86400.0),
}


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


def netcdf_format(p: Path, what: str) -> str:
    """'hdf5' (netCDF-4) or 'netcdf3' from the file's signature, else one-line DataError."""
    try:
        with open(p, "rb") as fh:
            head = fh.read(8)
            if head[:3] == b"CDF" and head[3:4] in (b"\x01", b"\x02", b"\x05"):
                return "netcdf3"
            offset = 0
            while True:  # HDF5 puts its signature at 0, 512, 1024, 2048, ... (after a user block)
                if head == _HDF5:
                    return "hdf5"
                offset = 512 if offset == 0 else 2 * offset
                fh.seek(offset)
                head = fh.read(8)
                if len(head) < 8:
                    break
    except OSError as exc:
        raise DataError(f"{what}: cannot read {p}: {exc.strerror or exc}") from None
    raise DataError(f"{what}: {p} is not a netCDF file (it has neither the netCDF-4/HDF5 nor the netCDF-3 signature)")


def load_series(
    path: str | Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
) -> Series:
    """Read and validate a series. Formats: a table, CSV / TSV (delimiter sniffed from the header:
    comma, semicolon, tab or whitespace; '#' comment lines allowed, '# scene: {json}' carries the
    truth) or Parquet (.parquet), with columns `time_column` (default time) and `value_column`
    (default intensity), named case-insensitively, more named columns ignored; a time of ISO 8601
    date-times (or datetime64) becomes seconds since the first sample (noted in `Series.notes`);
    `fs` (Hz) gives the time of a table without a time column, arange(n) / fs. Decimal commas are
    refused. Also .npy (N x 2), .npz (arrays 'time' and 'intensity'), netCDF (.nc; variables 'time'
    and 'intensity'; a time with CF units, e.g. 'milliseconds since 2024-01-01', is converted to
    seconds since its epoch; the intensity's units are noted, its values kept)."""
    p = check_file(path, "data")
    fs = _check_fs(fs)
    suffix = p.suffix.lower()
    table = suffix not in (".npy", ".npz", ".nc", ".netcdf", ".cdf")
    if not table and (time_column is not None or value_column is not None or fs is not None):
        raise DataError(
            f"data: time_column, value_column and fs apply to CSV/TSV and Parquet tables, not {suffix} files"
        )
    scene, notes = None, []
    try:
        if suffix == ".npy":
            t, x = _read_npy(p)
        elif suffix == ".npz":
            t, x = _read_npz(p)
        elif not table:
            t, x, notes = _read_netcdf(p)
        elif suffix == ".parquet":
            t, x, notes = _read_parquet(p, time_column, value_column, fs)
        else:
            t, x, scene, notes = _read_csv(p, time_column, value_column, fs)
    except DataError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"data: cannot read {p}: {_first_line(exc)}") from None
    return validate(t, x, str(p), scene, notes)


def _check_fs(fs: Any) -> float | None:
    if fs is None:
        return None
    try:
        value = float(fs)
    except (TypeError, ValueError):
        raise DataError(f"data: fs: {fs!r} is not a number (the sampling rate in Hz)") from None
    if isinstance(fs, bool) or not (math.isfinite(value) and value > 0):
        raise DataError(f"data: fs: {fs!r} Hz; allowed range (0, inf)")
    return value


def _columns(
    p: Path, names: list[str], time_column: str | None, value_column: str | None, fs: float | None
) -> tuple[int | None, int]:
    """The indices of the time column (None: the time comes from `fs`) and of the value column among
    `names` (case-insensitive); a missing, doubled or ambiguous column is a one-line DataError."""
    lower = [str(c).strip().lower() for c in names]
    shown = ",".join(map(str, names))

    def find(name: str) -> int | None:
        key = name.strip().lower()
        if lower.count(key) > 1:
            raise DataError(f"data: {p} header names the column {key} twice: {shown}")
        return lower.index(key) if key in lower else None

    it = find(time_column or "time")
    if fs is not None and (time_column is not None or it is not None):
        raise DataError(
            f"data: {p} has a time column ({names[it] if it is not None else time_column}) and fs was given: "
            "the time is ambiguous; drop fs (--fs) or the time column"
        )
    ix = find(value_column or "intensity")
    if ix is None and value_column is None and fs is not None and len(names) == 1:
        ix = 0  # values only: the one column there is
    missing = []
    if ix is None:
        what = repr(value_column) if value_column is not None else "intensity"
        missing.append(f"no value column {what} (choose it with value_column=, --value-column)")
    if it is None and fs is None:
        what = repr(time_column) if time_column is not None else "time"
        missing.append(f"no time column {what} (name it with time_column=, --time-column, or give fs=, --fs)")
    if missing:
        raise DataError(f"data: {p} has {' and '.join(missing)}; its columns: {shown}")
    if it == ix:
        raise DataError(f"data: {p}: the time and the value column are the same column ({names[ix]})")
    return it, ix


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _signature(p: Path, magic: bytes, kind: str, name: str) -> None:
    with open(p, "rb") as fh:
        if fh.read(len(magic)) != magic:
            raise DataError(f"data: {p} is not a {kind} file (no {name} signature)")


def _read_npy(p: Path) -> tuple[np.ndarray, np.ndarray]:
    _signature(p, b"\x93NUMPY", ".npy", "NUMPY")
    arr = _np_load(p, lambda: np.load(p, allow_pickle=False), str(p))
    _numbers(arr, str(p))
    if arr.ndim != 2:
        raise DataError(f"data: {p} must hold an N x 2 array (time, intensity), got shape {arr.shape}")
    if arr.shape[1] != 2:
        hint = "; transpose it" if arr.shape[0] == 2 else ""
        raise DataError(
            f"data: {p} must hold exactly 2 columns (time, intensity), got {arr.shape[1]} (shape {arr.shape}){hint}"
        )
    return arr[:, 0], arr[:, 1]


def _read_npz(p: Path) -> tuple[np.ndarray, np.ndarray]:
    _signature(p, b"PK\x03\x04", ".npz", "zip")
    with np.load(p, allow_pickle=False) as z:
        if "time" not in z or "intensity" not in z:
            raise DataError(f"data: {p} needs arrays 'time' and 'intensity', has {sorted(z.files)}")
        return (
            _numbers(_np_load(p, lambda: z["time"], f"{p}: time"), f"{p}: time"),
            _numbers(_np_load(p, lambda: z["intensity"], f"{p}: intensity"), f"{p}: intensity"),
        )


def _np_load(p: Path, load, what: str) -> np.ndarray:
    try:
        return load()
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise DataError(f"data: {what} holds Python objects (pickled); real numbers are needed") from None
        raise


def _read_netcdf(p: Path) -> tuple[np.ndarray, np.ndarray, list[str]]:
    import xarray as xr

    engine = "h5netcdf" if netcdf_format(p, "data") == "hdf5" else "scipy"
    # times are converted here (CF units to seconds), not decoded to dates
    with xr.open_dataset(p, engine=engine, decode_times=False, decode_timedelta=False) as ds:
        if "intensity" not in ds:
            raise DataError(f"data: {p} has no variable 'intensity' (variables: {', '.join(map(str, ds.variables))})")
        xa = ds["intensity"]
        if "time" in ds.variables:
            ta = ds["time"]
        elif xa.dims and xa.dims[0] in ds.variables:
            ta = ds[xa.dims[0]]
        else:
            raise DataError(f"data: {p} has no variable 'time' (nor a coordinate on the intensity's dimension)")
        x = _numbers(xa.values, f"{p}: intensity")
        t = _numbers(ta.values, f"{p}: time")
        units = ta.attrs.get("units")
        x_units = xa.attrs.get("units")
    notes = []
    if units is not None:
        text = str(units).strip()
        unit, _, epoch = text.lower().partition(" since ")
        unit = unit.strip()
        if unit not in _TIME_UNITS:
            raise DataError(
                f"data: {p}: time units {str(units)!r} are not a time unit; allowed: seconds, milliseconds, "
                "microseconds, nanoseconds, minutes, hours, days (optionally 'since' an epoch)"
            )
        t = t.astype(float) * _TIME_UNITS[unit]
        if epoch.strip():  # a CF date axis (datetime64 written by xarray): seconds since its epoch
            notes.append(f"{TIME_REFERENCE_NOTE}{text[text.lower().index(' since ') + 7 :].strip()}")
    if x_units is not None and str(x_units).strip():
        notes.append(f"{UNITS_NOTE}{str(x_units).strip()} (values kept; the fit's gain absorbs them)")
    return t, x, notes


def _read_parquet(
    p: Path, time_column: str | None, value_column: str | None, fs: float | None
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    _signature(p, b"PAR1", "Parquet", "PAR1")
    try:
        import pandas as pd
        import pyarrow  # noqa: F401 - pandas' Parquet engine
    except ImportError:
        raise DataError("data: reading Parquet needs pyarrow: pip install 'vibinverse[parquet]'") from None
    df = pd.read_parquet(p)
    if any(name is not None for name in df.index.names):  # a named index (a time, often) is a column
        df = df.reset_index()
    names = [str(c) for c in df.columns]
    it, ix = _columns(p, names, time_column, value_column, fs)
    x = _table_column(df.iloc[:, ix], f"{p}: {names[ix]}")
    if it is None:
        return np.arange(x.size) / fs, x, []
    col = df.iloc[:, it]
    if pd.api.types.is_datetime64_any_dtype(col):
        stamps = pd.DatetimeIndex(col)
        if stamps.hasnans:
            raise DataError(f"data: {p}: time column {names[it]} has missing date-times")
        t, note = _since_first(stamps)
        return t, x, [note]
    return _table_column(col, f"{p}: time"), x, []


def _table_column(col: Any, what: str) -> np.ndarray:
    """A pandas column as float64 (missing values NaN) if it holds numbers, else `_numbers`'s refusal."""
    import pandas as pd

    if pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col):
        return col.to_numpy(dtype=float, na_value=np.nan)
    return _numbers(col.to_numpy(), what)


def _since_first(stamps: Any) -> tuple[np.ndarray, str]:
    """Seconds since the first of `stamps` (a pandas DatetimeIndex; an aware one is converted to UTC
    first) and the note recording that reference."""
    ref = stamps[0].isoformat()
    if stamps.tz is not None:
        stamps = stamps.tz_convert("UTC").tz_localize(None)
    d = stamps.to_numpy()
    return (d - d[0]) / np.timedelta64(1, "s"), f"{TIME_REFERENCE_NOTE}{ref}"


# an ISO 8601 date-time (date, optional time with decimal-point fraction, optional zone), and a
# number written with a decimal comma (1,5 or -0,25e-3): refused, never guessed
_ISO = re.compile(r"\d{4}-\d{2}-\d{2}(?:[T ]\d{2}:\d{2}(?::\d{2}(?:\.\d+)?)?)?(Z|[+-]\d{2}:?\d{2})?")
_DECIMAL_COMMA = re.compile(r"[+-]?(?:\d+,\d*|,\d+)(?:[eE][+-]?\d+)?")


def _splitter(header: str) -> tuple[Any, bool]:
    """How the lines split into cells, from the header: the delimiter (comma, semicolon or tab)
    that gives it the most cells, else whitespace, else one column; and whether it is the tab."""
    counts = {d: len(next(csvlib.reader([header], delimiter=d))) for d in (",", ";", "\t")}
    best = max(counts, key=counts.get)  # ties keep the first: comma
    if counts[best] == 1 and len(header.split()) > 1:
        return (lambda s: s.split()), False
    return (lambda s: [c.strip() for c in next(csvlib.reader([s], delimiter=best))]), best == "\t"


def _float(cell: str, p: Path, n: int, s: str) -> float:
    try:
        return float(cell)
    except ValueError:
        if _DECIMAL_COMMA.fullmatch(cell):
            raise DataError(
                f"data: {p} line {n}: {cell!r} has a decimal comma; write decimal points (1.5, not 1,5)"
            ) from None
        raise DataError(f"data: {p} line {n}: not a number: {s[:60]}") from None


def _read_csv(
    p: Path, time_column: str | None, value_column: str | None, fs: float | None
) -> tuple[np.ndarray, np.ndarray, dict | None, list[str]]:
    scene, header, values, times, stamps, zone = None, None, [], [], None, None
    with open(p, encoding="utf-8-sig", newline="") as fh:  # utf-8-sig: a byte-order mark is not part of the header
        for n, line in enumerate(fh, 1):
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                if s.startswith("# scene:"):
                    try:
                        scene = jsonio.loads(s[len("# scene:") :])
                    except ValueError:  # not JSON: the file carries no truth
                        scene = None
                continue
            if header is None:
                split, tabs = _splitter(s)
                cells = split(s)
                header = [c.lower() for c in cells]
                it, ix = _columns(p, cells, time_column, value_column, fs)
                need = max(ix, -1 if it is None else it)
                continue
            cells = split(line.strip(" \r\n") if tabs else s)  # a tab-separated row may end in an empty cell
            # a row with more cells than the header is malformed (a decimal comma, a missing header
            # name): taking its first cells would read the wrong numbers
            if len(cells) <= need or any(cells[len(header) :]):
                raise DataError(
                    f"data: {p} line {n}: {len(cells)} cells; the header names {len(header)} ({','.join(header)})"
                )
            if it is not None:
                cell = cells[it]
                if stamps is None:  # the first row decides: numbers (seconds) or ISO 8601 date-times
                    stamps = not _is_float(cell) and _ISO.fullmatch(cell) is not None
                if stamps:
                    m = _ISO.fullmatch(cell)
                    if m is None:
                        raise DataError(f"data: {p} line {n}: not an ISO 8601 date-time: {cell[:40]}")
                    if zone is None:
                        zone = m.group(1) is not None
                    elif zone != (m.group(1) is not None):
                        raise DataError(f"data: {p} line {n}: date-times with and without a time zone are mixed")
                    times.append(cell)
                else:
                    times.append(_float(cell, p, n, s))
            values.append(_float(cells[ix] or "nan", p, n, s))
    if header is None:
        raise DataError(f"data: {p} has no header row time,intensity")
    x, notes = np.array(values, dtype=float), []
    if it is None:
        t = np.arange(x.size) / fs
    elif stamps:
        import pandas as pd

        try:
            t, note = _since_first(pd.DatetimeIndex(pd.to_datetime(times, format="ISO8601", utc=bool(zone))))
        except (ValueError, OverflowError) as exc:
            why = _first_line(exc).split(" You might")[0]  # pandas' advice names its own options
            raise DataError(f"data: {p}: time: not ISO 8601 date-times: {why}") from None
        notes.append(note)
    else:
        t = np.array(times, dtype=float)
    return t, x, scene, notes


def _is_float(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _numbers(a: Any, what: str) -> np.ndarray:
    """`a` as float64 if it holds real numbers (or, for a time, time spans: in seconds), else one-line
    DataError naming what it holds."""
    a = np.asarray(a)
    kind = a.dtype.kind
    if kind in "fiu":
        return a.astype(float)
    if kind == "m" and what.endswith("time"):
        return a / np.timedelta64(1, "s")
    unit = " (seconds)" if what.endswith("time") else ""
    raise DataError(f"data: {what} holds {_KINDS.get(kind, kind)} (dtype {a.dtype}); real numbers{unit} are needed")


def validate(
    t: Any, x: Any, source: str = "array", scene: dict | None = None, notes: list[str] | None = None
) -> Series:
    """Check a series; NaN intensities are gaps, anything else non-finite is an error. Refused, each
    with one line: non-numeric, complex or boolean values, fewer than 16 samples, a time that is not
    strictly increasing (naming the first offending sample and both stamps), values beyond
    +-MAX_ABS, and an intensity that is constant (or varies by less than MIN_SPREAD): nothing to fit.
    Irregular stamps (jitter, dropped frames; off a regular grid by more than UNIFORM_RTOL of its
    step) are accepted and described in `notes` (`irregular_sampling`)."""
    t, x = _numbers(t, "time"), _numbers(x, "intensity")
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
