"""The series readers: one `SeriesReader` per file format, found through the registry `READERS`.

`reader_for(path)` picks the reader of a file: by its suffix (.npy, .npz, .nc, .parquet, .lvm), else
by its signature (a text file whose first line starts with 'LabVIEW Measurement' is an lvm file,
whatever its suffix), else the CSV/TSV reader. A reader returns the raw arrays (`Raw`);
`vibinverse.io.series.load_series` validates them. Every problem is a one-line `DataError`.
"""

from __future__ import annotations

import csv as csvlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from vibinverse.errors import DataError
from vibinverse.io import jsonio
from vibinverse.io.file_basics import (
    TIME_REFERENCE_NOTE,
    UNITS_NOTE,
    choose_channel,
    first_line,
    netcdf_format,
    real_numbers,
)

#: the options of `load_series` a reader may take
OPTIONS = ("time_column", "value_column", "fs")


@dataclass
class Raw:
    """What a reader read, not yet validated: time (s), intensity, the truth a file carries, notes."""

    time: Any
    intensity: Any
    scene: dict | None = None
    notes: list[str] = field(default_factory=list)


class SeriesReader:
    """A series file format. Subclasses set `name`, `suffixes` (lower case, with the dot) and
    `options` (which of time_column, value_column, fs they take), and implement `read`; a format
    recognised by its content also implements `claims`."""

    name: ClassVar[str] = ""
    suffixes: ClassVar[tuple[str, ...]] = ()
    options: ClassVar[frozenset[str]] = frozenset()

    def claims(self, head: bytes) -> bool:
        """Whether a file starting with the bytes `head` is of this format, whatever its suffix."""
        return False

    def refuse_options(self, p: Path, given: list[str]) -> DataError:
        """The error for options (of OPTIONS) this format does not take."""
        return DataError(
            f"data: time_column, value_column and fs apply to CSV/TSV and Parquet tables, not {p.suffix.lower()} files"
        )

    def read(self, p: Path, *, time_column: str | None, value_column: str | None, fs: float | None) -> Raw:
        """The raw series of file `p` (an existing, non-empty file); options not in `options` are None."""
        raise NotImplementedError


#: the readers by name, in the order their signatures are tried; CSV is the fallback
READERS: dict[str, SeriesReader] = {}
FALLBACK = "csv"
HEAD_BYTES = 512


def register(cls: type[SeriesReader]) -> type[SeriesReader]:
    """Class decorator: add an instance of the reader `cls` to READERS under its name."""
    READERS[cls.name] = cls()
    return cls


def reader_for(p: Path) -> SeriesReader:
    """The reader of file `p`: by suffix, else by signature (`SeriesReader.claims`), else CSV/TSV."""
    suffix = p.suffix.lower()
    for name, reader in READERS.items():
        if name != FALLBACK and suffix in reader.suffixes:
            return reader
    try:
        with open(p, "rb") as fh:
            head = fh.read(HEAD_BYTES)
    except OSError as exc:
        raise DataError(f"data: cannot read {p}: {exc.strerror or exc}") from None
    for reader in READERS.values():
        if reader.claims(head):
            return reader
    return READERS[FALLBACK]


def _signature(p: Path, magic: bytes, kind: str, name: str) -> None:
    with open(p, "rb") as fh:
        if fh.read(len(magic)) != magic:
            raise DataError(f"data: {p} is not a {kind} file (no {name} signature)")


def _np_load(p: Path, load, what: str) -> np.ndarray:
    try:
        return load()
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise DataError(f"data: {what} holds Python objects (pickled); real numbers are needed") from None
        raise


def _positive(value: float, what: str) -> float:
    if not (np.isfinite(value) and value > 0):
        raise DataError(f"data: {what}: {value:g} Hz; allowed range (0, inf)")
    return value


# ---------------------------------------------------------------------------------------------- .npy


@register
class NpyReader(SeriesReader):
    """.npy: one N x 2 array of numbers (time s, intensity)."""

    name = "npy"
    suffixes = (".npy",)

    def read(
        self, p: Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
    ) -> Raw:
        _signature(p, b"\x93NUMPY", ".npy", "NUMPY")
        arr = _np_load(p, lambda: np.load(p, allow_pickle=False), str(p))
        real_numbers(arr, str(p))
        if arr.ndim != 2:
            raise DataError(f"data: {p} must hold an N x 2 array (time, intensity), got shape {arr.shape}")
        if arr.shape[1] != 2:
            hint = "; transpose it" if arr.shape[0] == 2 else ""
            raise DataError(
                f"data: {p} must hold exactly 2 columns (time, intensity), got {arr.shape[1]} (shape {arr.shape}){hint}"
            )
        return Raw(arr[:, 0], arr[:, 1])


# ---------------------------------------------------------------------------------------------- .npz

#: scalar arrays of an .npz that give its sampling rate (Hz), and string arrays that name the
#: columns of a 2-D array
NPZ_RATES = ("fs", "sample_rate", "sampling_rate")
NPZ_NAMES = ("channel_names", "channels", "names")


@register
class NpzReader(SeriesReader):
    """.npz: arrays 'time' and 'intensity'; or named arrays: a 1-D array, or a column of a 2-D array
    whose columns a string array names (channel_names, channels or names), chosen with value_column
    (the one candidate by default), its time from the array 'time' (time_column), else from a scalar
    fs / sample_rate / sampling_rate, else from fs=."""

    name = "npz"
    suffixes = (".npz",)
    options = frozenset(OPTIONS)

    def read(
        self, p: Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
    ) -> Raw:
        _signature(p, b"PK\x03\x04", ".npz", "zip")
        with np.load(p, allow_pickle=False) as z:
            if time_column is None and value_column is None and fs is None and "time" in z and "intensity" in z:
                return Raw(
                    real_numbers(_np_load(p, lambda: z["time"], f"{p}: time"), f"{p}: time"),
                    real_numbers(_np_load(p, lambda: z["intensity"], f"{p}: intensity"), f"{p}: intensity"),
                )
            arrays: dict[str, np.ndarray | None] = {}
            for key in z.files:
                try:
                    arrays[key] = z[key]
                except ValueError:  # pickled objects: never a candidate
                    arrays[key] = None
        return _named_arrays(p, arrays, time_column, value_column, fs)


def _named_arrays(
    p: Path, arrays: dict[str, np.ndarray | None], time_column: str | None, value_column: str | None, fs: float | None
) -> Raw:
    tname = time_column or "time"
    if time_column is not None and time_column not in arrays:
        raise DataError(f"data: {p} has no array {time_column!r} (time_column); its arrays: {', '.join(arrays)}")
    labels = next(
        (
            [str(s).strip() for s in a]
            for k in NPZ_NAMES
            if (a := arrays.get(k)) is not None and a.ndim == 1 and a.dtype.kind in "US"
        ),
        None,
    )
    candidates: dict[str, tuple[str, int | None, int]] = {}  # name -> (array, column or None, axis of samples)
    for key, a in arrays.items():
        if key == tname or key in NPZ_RATES or a is None or a.dtype.kind not in "fiu":
            continue
        if a.ndim == 1 and a.size > 1:
            candidates[key] = (key, None, 0)
        elif a.ndim == 2:
            if labels is not None and len(labels) == a.shape[1]:
                axis, names = 0, labels
            elif labels is not None and len(labels) == a.shape[0]:
                axis, names = 1, labels
            else:
                axis = 0 if a.shape[0] >= a.shape[1] else 1
                names = [f"{key}[{j}]" for j in range(a.shape[1 - axis])]
            for j, name in enumerate(names):
                candidates[name if name not in candidates else f"{key}[{j}]"] = (key, j, axis)
    shown = ", ".join(candidates) or "none"
    if value_column is None:
        if len(candidates) != 1:
            what = "no series" if not candidates else f"{len(candidates)} candidate series ({shown})"
            raise DataError(
                f"data: {p} has no arrays 'time' and 'intensity' and {what}: choose one with --value-column "
                f"(value_column=); its arrays: {', '.join(arrays)}"
            )
        chosen = next(iter(candidates))
    elif value_column not in candidates and value_column in arrays:  # an array that is not numbers: say why
        a = arrays[value_column]
        if a is None:
            raise DataError(f"data: {p}: {value_column} holds Python objects (pickled); real numbers are needed")
        real_numbers(a, f"{p}: {value_column}")
        raise DataError(
            f"data: {p}: {value_column} has shape {a.shape}; a 1-D series (or a named 2-D column) is needed"
        )
    else:
        chosen = list(candidates)[choose_channel(p, list(candidates), value_column, "candidate series")]
    key, column, axis = candidates[chosen]
    a = arrays[key]
    x = real_numbers(a if column is None else np.take(a, column, axis=1 - axis), f"{p}: {chosen}")
    if arrays.get(tname) is not None:
        if fs is not None:
            raise DataError(
                f"data: {p} has a time array ({tname}) and fs was given: the time is ambiguous; drop fs (--fs)"
            )
        t = real_numbers(arrays[tname], f"{p}: time")
        if t.shape != x.shape:
            raise DataError(f"data: {p}: time has shape {t.shape}, {chosen} has shape {x.shape}; they must match")
        return Raw(t, x)
    rate = next((k for k in NPZ_RATES if (r := arrays.get(k)) is not None and r.size == 1), None)
    if rate is not None:
        value = _positive(float(real_numbers(arrays[rate], f"{p}: {rate}").reshape(())), f"{p}: {rate}")
        if fs is not None and not np.isclose(fs, value, rtol=1e-9, atol=0.0):
            raise DataError(f"data: {p} gives {rate} = {value:g} Hz and fs was given as {fs:g} Hz; drop fs (--fs)")
        fs = value
    if fs is None:
        raise DataError(
            f"data: {p} has no time: no array 'time' nor a sampling rate ({', '.join(NPZ_RATES)}); give fs= (--fs)"
        )
    return Raw(np.arange(x.size) / fs, x)


# ------------------------------------------------------------------------------------------- netCDF

_TIME_UNITS = {
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), 1.0),
    **dict.fromkeys(("ms", "msec", "msecs", "millisecond", "milliseconds"), 1e-3),
    **dict.fromkeys(("us", "\u00b5s", "microsecond", "microseconds"), 1e-6),
    **dict.fromkeys(("ns", "nanosecond", "nanoseconds"), 1e-9),
    **dict.fromkeys(("min", "mins", "minute", "minutes"), 60.0),
    **dict.fromkeys(("h", "hr", "hrs", "hour", "hours"), 3600.0),
    **dict.fromkeys(("d", "day", "days"), 86400.0),
}


@register
class NetcdfReader(SeriesReader):
    """netCDF (.nc): variables 'time' and 'intensity'; a time with CF units ('milliseconds since
    2024-01-01') in seconds since its epoch; the intensity's units noted, its values kept."""

    name = "netcdf"
    suffixes = (".nc", ".netcdf", ".cdf")

    def read(
        self, p: Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
    ) -> Raw:
        import xarray as xr

        engine = "h5netcdf" if netcdf_format(p, "data") == "hdf5" else "scipy"
        # times are converted here (CF units to seconds), not decoded to dates
        with xr.open_dataset(p, engine=engine, decode_times=False, decode_timedelta=False) as ds:
            if "intensity" not in ds:
                raise DataError(
                    f"data: {p} has no variable 'intensity' (variables: {', '.join(map(str, ds.variables))})"
                )
            xa = ds["intensity"]
            if "time" in ds.variables:
                ta = ds["time"]
            elif xa.dims and xa.dims[0] in ds.variables:
                ta = ds[xa.dims[0]]
            else:
                raise DataError(f"data: {p} has no variable 'time' (nor a coordinate on the intensity's dimension)")
            x = real_numbers(xa.values, f"{p}: intensity")
            t = real_numbers(ta.values, f"{p}: time")
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
        return Raw(t, x, None, notes)


# ------------------------------------------------------------------------------------ tables (shared)


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
    if ix is None and value_column is None:
        others = [i for i in range(len(names)) if i != it]
        if len(others) == 1 and (it is not None or fs is not None):
            ix = others[0]  # one column besides the time (or values only with fs): the one there is
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


def _since_first(stamps: Any) -> tuple[np.ndarray, str]:
    """Seconds since the first of `stamps` (a pandas DatetimeIndex; an aware one is converted to UTC
    first) and the note recording that reference."""
    ref = stamps[0].isoformat()
    if stamps.tz is not None:
        stamps = stamps.tz_convert("UTC").tz_localize(None)
    d = stamps.to_numpy()
    return (d - d[0]) / np.timedelta64(1, "s"), f"{TIME_REFERENCE_NOTE}{ref}"


# ------------------------------------------------------------------------------------------ Parquet


def _table_column(col: Any, what: str) -> np.ndarray:
    """A pandas column as float64 (missing values NaN) if it holds numbers, else `real_numbers`' refusal."""
    import pandas as pd

    if pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col):
        return col.to_numpy(dtype=float, na_value=np.nan)
    return real_numbers(col.to_numpy(), what)


@register
class ParquetReader(SeriesReader):
    """Parquet (.parquet): a table read as the CSV is (named columns, date-times, fs)."""

    name = "parquet"
    suffixes = (".parquet",)
    options = frozenset(OPTIONS)

    def read(
        self, p: Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
    ) -> Raw:
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
            return Raw(np.arange(x.size) / fs, x)
        col = df.iloc[:, it]
        if pd.api.types.is_datetime64_any_dtype(col):
            stamps = pd.DatetimeIndex(col)
            if stamps.hasnans:
                raise DataError(f"data: {p}: time column {names[it]} has missing date-times")
            t, note = _since_first(stamps)
            return Raw(t, x, None, [note])
        return Raw(_table_column(col, f"{p}: time"), x)


# ---------------------------------------------------------------------------------------------- CSV

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


def _is_float(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


@register
class CsvReader(SeriesReader):
    """CSV / TSV (any file no other reader takes): delimiter sniffed from the header (comma,
    semicolon, tab or whitespace); '#' comment lines, '# scene: {json}' carries the truth; named
    columns (case-insensitive), ISO 8601 date-times, fs for a table without a time column."""

    name = FALLBACK
    suffixes = (".csv", ".tsv", ".txt", ".dat")
    options = frozenset(OPTIONS)

    def read(
        self, p: Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
    ) -> Raw:
        scene, header, values, times, stamps, zone = None, None, [], [], None, None
        # utf-8-sig: a byte-order mark is not part of the header
        with open(p, encoding="utf-8-sig", newline="") as fh:
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
                why = first_line(exc).split(" You might")[0]  # pandas' advice names its own options
                raise DataError(f"data: {p}: time: not ISO 8601 date-times: {why}") from None
            notes.append(note)
        else:
            t = np.array(times, dtype=float)
        return Raw(t, x, scene, notes)


# ---------------------------------------------------------------------------------------------- lvm


@register
class LvmReader(SeriesReader):
    """LabVIEW Measurement text files (.lvm, or any text file whose first line starts with
    'LabVIEW Measurement'): `vibinverse.io.lvm.read_lvm`. value_column chooses the channel (a name
    or a 0-based index); fs gives the time of a file without X_Value columns."""

    name = "lvm"
    suffixes = (".lvm",)
    options = frozenset(("value_column", "fs"))

    def claims(self, head: bytes) -> bool:
        from vibinverse.io.lvm import is_lvm

        return is_lvm(head)

    def refuse_options(self, p: Path, given: list[str]) -> DataError:
        return DataError(
            f"data: time_column does not apply to the LabVIEW Measurement file {p}: its time is the channel's "
            "X_Value column, or X0 + Delta_X from its header"
        )

    def read(
        self, p: Path, *, time_column: str | None = None, value_column: str | None = None, fs: float | None = None
    ) -> Raw:
        from vibinverse.io.lvm import read_lvm

        lvm = read_lvm(p, value_column=value_column, fs=fs)
        return Raw(lvm.time, lvm.intensity, None, lvm.notes)
