"""Measured series: read CSV / .npy / .npz / netCDF, validate, and report gaps.

A NaN intensity is a gap (a missing sample): kept, counted and handled by the likelihoods. Every
problem raises `vibinverse.errors.DataError` with one line naming it.
"""

from __future__ import annotations

import copy
import csv as csvlib
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError
from vibinverse.io import jsonio

# a uniform grid's tolerance, relative to its step: a timing error of 1e-3 of a sample moves a line at
# Nyquist by 3e-3 rad, far below any phase a fit resolves
UNIFORM_RTOL = 1e-3


@dataclass(frozen=True)
class Series:
    time: NDArray[np.float64]
    intensity: NDArray[np.float64]  # NaN = gap
    source: str
    scene: dict[str, Any] | None = None  # the true scene, when the file carries it (vibinverse simulate)
    notes: list[str] = field(default_factory=list)

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
        t = self.time
        step = (t[-1] - t[0]) / (t.size - 1)
        return bool(np.max(np.abs(t - (t[0] + np.arange(t.size) * step))) <= UNIFORM_RTOL * step)

    @property
    def fs(self) -> float:
        return 1.0 / self.dt

    def describe(self) -> str:
        kind = f"uniform at {self.fs:g} Hz" if self.uniform else f"non-uniform (median step {self.dt:g} s)"
        return (
            f"{self.time.size} samples over {self.time[-1] - self.time[0]:g} s, {kind}; "
            f"{self.n_gaps} gaps ({self.n_gaps / self.time.size:.1%})"
        )


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


def load_series(path: str | Path) -> Series:
    """Read and validate a series. Formats: CSV with columns time,intensity (more named columns are
    ignored; '#' comment lines allowed, '# scene: {json}' carries the truth), .npy (N x 2),
    .npz (arrays 'time' and 'intensity'), netCDF (.nc; variables 'time' and 'intensity'; a time
    with CF units, e.g. 'milliseconds since 2024-01-01', is converted to seconds)."""
    p = check_file(path, "data")
    suffix = p.suffix.lower()
    scene = None
    try:
        if suffix == ".npy":
            t, x = _read_npy(p)
        elif suffix == ".npz":
            t, x = _read_npz(p)
        elif suffix in (".nc", ".netcdf", ".cdf"):
            t, x = _read_netcdf(p)
        else:
            t, x, scene = _read_csv(p)
    except DataError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"data: cannot read {p}: {_first_line(exc)}") from None
    return validate(t, x, str(p), scene)


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


def _read_netcdf(p: Path) -> tuple[np.ndarray, np.ndarray]:
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
    if units is not None:
        unit = str(units).strip().lower().split(" since ")[0].strip()
        if unit not in _TIME_UNITS:
            raise DataError(
                f"data: {p}: time units {str(units)!r} are not a time unit; allowed: seconds, milliseconds, "
                "microseconds, nanoseconds, minutes, hours, days (optionally 'since' an epoch)"
            )
        t = t.astype(float) * _TIME_UNITS[unit]
    return t, x


def _read_csv(p: Path) -> tuple[np.ndarray, np.ndarray, dict | None]:
    scene, header, rows = None, None, []
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
            cells = [c.strip() for c in next(csvlib.reader([s]))]
            if header is None:
                header = [c.lower() for c in cells]
                if "time" not in header or "intensity" not in header:
                    raise DataError(f"data: {p} header must name columns time and intensity, got {','.join(cells)}")
                for name in ("time", "intensity"):
                    if header.count(name) > 1:
                        raise DataError(f"data: {p} header names the column {name} twice: {','.join(cells)}")
                it, ix = header.index("time"), header.index("intensity")
                continue
            # a row with more cells than the header is malformed (a decimal comma, a missing header
            # name): taking its first cells would read the wrong numbers
            if len(cells) <= max(it, ix) or any(cells[len(header) :]):
                raise DataError(
                    f"data: {p} line {n}: {len(cells)} cells; the header names {len(header)} ({','.join(header)})"
                )
            try:
                rows.append((float(cells[it]), float(cells[ix] or "nan")))
            except ValueError:
                raise DataError(f"data: {p} line {n}: not a number: {s[:60]}") from None
    if header is None:
        raise DataError(f"data: {p} has no header row time,intensity")
    arr = np.array(rows, dtype=float).reshape(-1, 2)
    return arr[:, 0], arr[:, 1], scene


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


def validate(t: Any, x: Any, source: str = "array", scene: dict | None = None) -> Series:
    """Check a series; NaN intensities are gaps, anything else non-finite is an error. Refused, each
    with one line: non-numeric, complex or boolean values, fewer than 16 samples, a time that is not
    strictly increasing, values beyond +-MAX_ABS, and an intensity that is constant (or varies by
    less than MIN_SPREAD): nothing to fit."""
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
        raise DataError(f"data: time must be strictly increasing (sample {k + 1}: {t[k + 1]:g} after {t[k]:g})")
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
    return Series(t, x, source, scene)


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
    3 cycles in the record."""
    nyquist = 0.5 * series.fs
    if frequency_hz >= nyquist:
        raise InputError(f"{what}: {frequency_hz:g} Hz is at or above the Nyquist frequency {nyquist:g} Hz of the data")
    span = series.time[-1] - series.time[0]
    if frequency_hz * span < 3.0:
        raise InputError(
            f"{what}: {frequency_hz:g} Hz needs at least {3.0 / frequency_hz:g} s of data "
            f"(3 cycles); the series spans {span:g} s"
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
