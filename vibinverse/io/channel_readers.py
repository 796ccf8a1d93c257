"""The multi-channel readers: one `ChannelReader` per file format, found through the registry
`CHANNEL_READERS` (`vibinverse.io.channels.load_channels` validates what they read).

`channel_reader_for(path)` picks the reader of a file: by its suffix, else by its first bytes
(`ChannelReader.claims`: a LabVIEW Measurement header, a UFF delimiter line, a MATLAB header, the
HDF5 / netCDF, TDMS, NUMPY, zip and Parquet signatures), else the CSV/TSV reader for a text file;
anything else is an unknown format. A reader returns a `Table` (time, values, names, units, notes);
every problem is a one-line `DataError` naming the file and the field. The readers of the logger
formats import their libraries (npTDMS, pyuff) when they read: a missing one is a one-line
InputError naming the extra to install (`pip install 'vibinverse[loggers]'`).
"""

from __future__ import annotations

import csv as csvlib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError
from vibinverse.io.file_basics import TIME_REFERENCE_NOTE, UNITS_NOTE, first_line, netcdf_format, real_numbers

#: the options of `load_channels` a reader may take
OPTIONS = ("time_column", "fs")
#: column / array / variable names taken as the time (case-insensitive, units in brackets stripped)
TIME_NAMES = frozenset(
    {"time", "t", "times", "seconds", "second", "sec", "secs", "time_s", "time_sec", "timestamp", "x_value"}
    | {"elapsed", "elapsed_time", "elapsed time"}
)
#: scalar arrays / variables / attributes that give the sampling rate (Hz)
RATE_NAMES = ("fs", "sample_rate", "sampling_rate", "samplerate", "sampling_frequency")
#: string arrays that name the columns of a 2-D array, and that give the channels' units
NAME_ARRAYS = ("channel_names", "channels", "names", "labels")
UNIT_ARRAYS = ("units", "channel_units", "unit")
#: dimension names taken as the channel axis of a 2-D netCDF variable
CHANNEL_DIMS = ("channel", "channels", "chan", "sensor", "sensors", "name")
#: unit labels that mean "no unit given"
NO_UNIT = frozenset({"", "none", "-", "n/a", "na"})
#: cells that are a gap (NaN) in a CSV/TSV table, besides the ones float() reads as NaN
GAP_CELLS = frozenset({"", "na", "n/a", "null", "-"})
#: time units (a header's brackets, a netCDF/TDMS units attribute) in seconds
TIME_UNITS = {
    **dict.fromkeys(("s", "sec", "secs", "second", "seconds"), 1.0),
    **dict.fromkeys(("ms", "msec", "msecs", "millisecond", "milliseconds"), 1e-3),
    **dict.fromkeys(("us", "\u00b5s", "\u03bcs", "microsecond", "microseconds"), 1e-6),
    **dict.fromkeys(("ns", "nanosecond", "nanoseconds"), 1e-9),
    **dict.fromkeys(("min", "mins", "minute", "minutes"), 60.0),
    **dict.fromkeys(("h", "hr", "hrs", "hour", "hours"), 3600.0),
}
#: how a library missing for a format is installed
EXTRA = "pip install 'vibinverse[loggers]'"
HEAD_BYTES = 1024
_UNIT_IN_NAME = re.compile(r"^(.*?)\s*[\[(]([^\[\]()]*)[\])]\s*$")
_DECIMAL_COMMA = re.compile(r"[+-]?(?:\d+,\d*|,\d+)(?:[eE][+-]?\d+)?")
_HDF5 = b"\x89HDF\r\n\x1a\n"


@dataclass
class Table:
    """What a reader read, not yet validated: `values` (samples, channels) float with NaN gaps,
    `time` (s; None: the time comes from fs), the channels' names and units (None: not given),
    notes, and where the time came from (`time_from`, for the errors) and the file line of each
    sample when the format has lines (`lines`)."""

    time: NDArray[np.float64] | None
    values: NDArray[np.float64]
    names: list[str]
    units: list[str | None]
    notes: list[str] = field(default_factory=list)
    time_from: str = "time"
    lines: NDArray[np.int64] | None = None


class ChannelReader:
    """A multi-channel file format. Subclasses set `name`, `label` (how the errors name it),
    `suffixes` (lower case, with the dot) and `options` (which of time_column, fs they take), and
    implement `read`; a format recognised by its content also implements `claims`."""

    name: ClassVar[str] = ""
    label: ClassVar[str] = ""
    suffixes: ClassVar[tuple[str, ...]] = ()
    options: ClassVar[frozenset[str]] = frozenset(OPTIONS)

    def claims(self, head: bytes) -> bool:
        """Whether a file starting with the bytes `head` is of this format, whatever its suffix."""
        return False

    def refuse(self, p: Path, given: list[str]) -> DataError:
        """The error for options (of OPTIONS) this format does not take."""
        return DataError(
            f"channels: {', '.join(given)}: not taken by the {self.label} file {p}: its time is in the file"
        )

    def read(self, p: Path, *, time_column: str | None, fs: float | None) -> Table:
        """The table of file `p` (an existing, non-empty file); options not in `options` are None."""
        raise NotImplementedError


#: the readers by name, in the order their signatures are tried; CSV/TSV is the fallback for text
CHANNEL_READERS: dict[str, ChannelReader] = {}
TEXT_FALLBACK = "csv"


def register(cls: type[ChannelReader]) -> type[ChannelReader]:
    """Class decorator: add an instance of the reader `cls` to CHANNEL_READERS under its name."""
    CHANNEL_READERS[cls.name] = cls()
    return cls


def formats() -> str:
    """The formats read, for the errors: 'CSV/TSV (.csv, .tsv, ...), Parquet (.parquet), ...'."""
    return ", ".join(f"{r.label} ({', '.join(r.suffixes)})" for r in CHANNEL_READERS.values())


def channel_reader_for(p: Path) -> ChannelReader:
    """The reader of file `p`: by suffix, else by signature, else CSV/TSV for a text file; else a
    one-line DataError naming the formats read."""
    suffix = p.suffix.lower()
    for name, reader in CHANNEL_READERS.items():
        if name != TEXT_FALLBACK and suffix in reader.suffixes:
            return reader
    try:
        with open(p, "rb") as fh:
            head = fh.read(HEAD_BYTES)
    except OSError as exc:
        raise DataError(f"channels: cannot read {p}: {exc.strerror or exc}") from None
    for reader in CHANNEL_READERS.values():
        if reader.claims(head):
            return reader
    if suffix in CHANNEL_READERS[TEXT_FALLBACK].suffixes or _is_text(head):
        return CHANNEL_READERS[TEXT_FALLBACK]
    raise DataError(f"channels: {p}: unknown format (suffix {suffix or 'none'}, binary content); allowed: {formats()}")


def _is_text(head: bytes) -> bool:
    if b"\x00" in head:
        return False
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as exc:  # a multi-byte character cut at the end of the head is text
        return exc.start >= len(head) - 3
    return True


def _signature(p: Path, magic: bytes, label: str) -> None:
    with open(p, "rb") as fh:
        if fh.read(len(magic)) != magic:
            raise DataError(f"channels: {p} is not a {label} file (no {magic!r} signature)")


def _missing(library: str, label: str) -> InputError:
    return InputError(f"channels: reading {label} files needs {library}: {EXTRA}")


# ------------------------------------------------------------------------------------- shared pieces


def split_unit(cell: str) -> tuple[str, str | None]:
    """A header cell's name and unit: 'acc1 [g]' and 'acc1 (m/s^2)' -> ('acc1', 'g'), ('acc1', 'm/s^2');
    'acc1' -> ('acc1', None)."""
    text = str(cell).strip()
    m = _UNIT_IN_NAME.match(text)
    if m and m.group(1).strip():
        return m.group(1).strip(), _unit(m.group(2))
    return text, None


def _unit(label: Any) -> str | None:
    """A unit label, or None for an empty one or a 'NONE' placeholder."""
    if label is None:
        return None
    if isinstance(label, bytes):
        label = label.decode("utf-8", "replace")
    text = str(label).strip()
    return None if text.lower() in NO_UNIT else text


def _is_time_name(name: str) -> bool:
    return name.strip().lower() in TIME_NAMES or split_unit(name)[0].lower() in TIME_NAMES


def _find(names: list[str], wanted: str) -> int | None:
    """The index of `wanted` among names (exactly, else case-insensitively, the cell or its name
    without the unit)."""
    for key in (lambda n: n, lambda n: n.strip().lower(), lambda n: split_unit(n)[0].lower()):
        hits = [i for i, n in enumerate(names) if key(n) == key(wanted)]
        if len(hits) == 1:
            return hits[0]
    return None


def _time_factor(p: Path, where: str, unit: str | None) -> tuple[float, str | None]:
    """Seconds per unit of a time given in `unit` (None: seconds), and the reference of a CF
    'UNIT since EPOCH'; a unit that is not a time is a one-line DataError."""
    if unit is None:
        return 1.0, None
    text = str(unit).strip()
    base, _, epoch = text.lower().partition(" since ")
    if base.strip() not in TIME_UNITS:
        raise DataError(
            f"channels: {p}: {where} units {text!r} are not a time unit; allowed: s, ms, us, ns, min, h "
            "(or their names, optionally 'since' an epoch)"
        )
    ref = text[text.lower().index(" since ") + 7 :].strip() if epoch.strip() else None
    return TIME_UNITS[base.strip()], ref


@dataclass
class _Header:
    """The columns of a table with named columns: which one is the time (None: from fs), the
    channels' columns, names and units, and the time's scale to seconds."""

    time: int | None
    columns: list[int]
    names: list[str]
    units: list[str | None]
    factor: float
    time_from: str


def _header(
    p: Path, cells: list[str], time_column: str | None, fs: float | None, given_units: list[str | None] | None = None
) -> _Header:
    """Which column is the time: `time_column`, else one named like a time (TIME_NAMES), else, when
    fs is not given, the first column; the others are the channels, names split from their units."""
    shown = ", ".join(cells)
    if time_column is not None:
        it = _find(cells, time_column)
        if it is None:
            raise DataError(f"channels: {p} has no time column {time_column!r} (time_column); its columns: {shown}")
        time_from = f"the time column {cells[it]}"
    else:
        named = [i for i, c in enumerate(cells) if _is_time_name(c)]
        if len(named) > 1:
            raise DataError(
                f"channels: {p} has {len(named)} time columns ({', '.join(cells[i] for i in named)}): "
                "choose one with time_column="
            )
        it = named[0] if named else None
        time_from = f"the time column {cells[it]}" if it is not None else ""
    if fs is not None and it is not None:
        raise DataError(
            f"channels: {p} has a time column ({cells[it]}) and fs was given: the time is ambiguous; drop fs "
            "or the time column"
        )
    if it is None and fs is None:
        if len(cells) < 2:
            raise DataError(
                f"channels: {p} has one column ({shown}) and no fs: it would be the time with no channel; give fs="
            )
        it, time_from = 0, f"the first column {cells[0]} (taken as the time: no column is named time; "
        time_from += "name it with time_column= or give fs=)"
    columns = [i for i in range(len(cells)) if i != it]
    if not columns:
        raise DataError(f"channels: {p} has only a time column ({shown}); no channel")
    split = [split_unit(c) for c in cells]
    units = [given_units[i] if given_units and given_units[i] else split[i][1] for i in range(len(cells))]
    factor = 1.0
    if it is not None:
        factor, _ = _time_factor(p, f"time column {cells[it]}", units[it])
    names = [split[i][0] or f"ch{k}" for k, i in enumerate(columns)]
    return _Header(it, columns, names, [units[i] for i in columns], factor, time_from)


def _strings(a: Any) -> list[str] | None:
    """A list of strings if `a` is text (a string, an array of strings, a list of them), else None."""
    if isinstance(a, str):
        return [a]
    if isinstance(a, (list, tuple)) and a and all(isinstance(s, (str, np.str_)) for s in a):
        return [str(s).strip() for s in a]
    if isinstance(a, np.ndarray) and a.ndim <= 1 and a.size:
        items = list(np.atleast_1d(a))
        if a.dtype.kind in "US" or all(isinstance(s, (str, bytes)) for s in items):  # a cell array: objects
            return [s.decode() if isinstance(s, bytes) else str(s).strip() for s in items]
    return None


def arrays_table(p: Path, arrays: dict[str, Any], time_column: str | None, fs: float | None) -> Table:
    """The table of named arrays (an .npz, a .mat): the time from the array `time_column` or one
    named like a time (TIME_NAMES), else from a scalar fs / sample_rate / ..., else from `fs`; the
    channels are every other numeric 1-D array of the time's length and the columns of 2-D arrays
    (samples x channels, or channels x samples), named by a string array channel_names / names / ...
    (else `ch0, ch1, ...` for a lone 2-D array, `key[j]` otherwise); units from a string array
    units (one per channel, or one for all)."""
    shown = ", ".join(arrays) or "none"
    numeric = {
        k: np.asarray(a)
        for k, a in arrays.items()
        if isinstance(a, (np.ndarray, int, float)) and np.asarray(a).dtype.kind in "fiu"
    }
    text = {k: s for k, a in arrays.items() if (s := _strings(a)) is not None}
    lower = {k.lower(): k for k in arrays}
    if time_column is not None:
        if time_column not in numeric:
            what = "is not numeric" if time_column in arrays else "is missing"
            raise DataError(f"channels: {p}: the time array {time_column!r} (time_column) {what}; its arrays: {shown}")
        tkey = time_column
    else:
        tkey = next((k for k in numeric if k.lower() in TIME_NAMES and numeric[k].size > 1), None)
    rkey = next(
        (lower[r] for r in RATE_NAMES if r in lower and lower[r] in numeric and numeric[lower[r]].size == 1), None
    )
    labels = next((text[lower[n]] for n in NAME_ARRAYS if n in lower and lower[n] in text), None)
    unit_labels = next((text[lower[n]] for n in UNIT_ARRAYS if n in lower and lower[n] in text), None)
    t = None
    if tkey is not None:
        a = numeric[tkey]
        t = a.astype(float).reshape(-1) if a.ndim == 1 or (a.ndim == 2 and 1 in a.shape) else None
        if t is None:
            raise DataError(
                f"channels: {p}: the time array {tkey!r} has shape {numeric[tkey].shape}; a vector is needed"
            )
    notes: list[str] = []
    if rkey is not None:
        rate = float(numeric[rkey].reshape(()))
        if not (np.isfinite(rate) and rate > 0):
            raise DataError(f"channels: {p}: {rkey} = {rate:g} Hz; allowed range (0, inf)")
        if fs is not None and not np.isclose(fs, rate, rtol=1e-9, atol=0.0):
            raise DataError(f"channels: {p} gives {rkey} = {rate:g} Hz and fs was given as {fs:g} Hz; drop fs")
        if t is None:
            fs = rate
        elif t.size > 1 and abs(rate * float(np.median(np.diff(t))) - 1.0) > 1e-3:
            notes.append(f"time: the file's {rkey} ({rate:g} Hz) disagrees with its time array; the time array is used")
    if t is not None and fs is not None and rkey is None:
        raise DataError(f"channels: {p} has a time array ({tkey}) and fs was given: the time is ambiguous; drop fs")
    candidates = {k: a for k, a in numeric.items() if k not in (tkey, rkey) and a.ndim in (1, 2) and a.size > 1}
    if not candidates:
        raise DataError(
            f"channels: {p} holds no channels: no 2-D numeric array (samples x channels) nor numeric vectors; "
            f"its arrays: {shown}"
        )
    if t is None and fs is None:
        raise DataError(
            f"channels: {p} has no time: no array named time (or t, seconds, ...) nor a sampling rate "
            f"({', '.join(RATE_NAMES)}); give fs= or time_column=; its arrays: {shown}"
        )
    # the number of samples: the time's, else the longest axis of a 2-D array named by the labels, else the longest
    n = t.size if t is not None else None
    if n is None:
        sizes = []
        for a in candidates.values():
            if a.ndim == 1:
                sizes.append(a.size)
            elif labels is not None and len(labels) in a.shape and a.shape[0] != a.shape[1]:
                sizes.append(a.shape[1] if a.shape[0] == len(labels) else a.shape[0])
            else:
                sizes.append(max(a.shape))
        n = max(sizes, default=0)
    columns: list[NDArray[np.float64]] = []
    names: list[str] = []
    ignored: list[str] = []
    lone = len(candidates) == 1
    for k, a in candidates.items():
        if a.ndim == 1 or (1 in a.shape and a.size == n):
            if a.size != n:
                ignored.append(f"{k} ({a.size} values)")
                continue
            columns.append(a.reshape(-1).astype(float))
            names.append(k)
            continue
        if a.shape[0] == n:
            block = a
        elif a.shape[1] == n:
            block = a.T
        else:
            ignored.append(f"{k} (shape {a.shape})")
            continue
        c = block.shape[1]
        if labels is not None and len(labels) == c:
            cols = list(labels)
            labels = None  # names one array only
        else:
            cols = [f"ch{j}" for j in range(c)] if lone else [f"{k}[{j}]" for j in range(c)]
        columns.extend(block[:, j].astype(float) for j in range(c))
        names.extend(cols)
    if not columns:
        raise DataError(
            f"channels: {p} holds no channels of {n} samples (the time's): {', '.join(ignored)} are of another "
            f"length; its arrays: {shown}"
        )
    if ignored:
        notes.append(f"channels: arrays not of {n} samples left out: {', '.join(ignored)}")
    if unit_labels is None:
        units: list[str | None] = [None] * len(names)
    elif len(unit_labels) in (1, len(names)):
        units = [_unit(u) for u in (unit_labels * len(names) if len(unit_labels) == 1 else unit_labels)]
    else:
        raise DataError(
            f"channels: {p}: the units array has {len(unit_labels)} entries for {len(names)} channels; give one per "
            "channel or one for all"
        )
    if t is None:
        t = np.arange(n) / fs
    return Table(t, np.column_stack(columns), names, units, notes, f"the time array {tkey}" if tkey else "time")


# ---------------------------------------------------------------------------------------- CSV / TSV


def _splitter(header: str) -> tuple[str | None, list[str]]:
    """The delimiter of a table from its header (comma, semicolon or tab: the one giving the most
    cells; None: whitespace) and the header's cells."""
    counts = {d: next(csvlib.reader([header], delimiter=d)) for d in (",", ";", "\t")}
    best = max(counts, key=lambda d: len(counts[d]))
    if len(counts[best]) == 1 and len(header.split()) > 1:
        return None, header.split()
    return best, [c.strip() for c in counts[best]]


def _is_float(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


@register
class CsvReader(ChannelReader):
    """CSV / TSV (any text file no other reader takes): delimiter from the header row (comma,
    semicolon, tab or whitespace), '#' comment lines skipped; the header names the columns, units in
    brackets ('acc1 [g]', 'acc1 (m/s^2)'); a header of numbers is data, the columns named ch0, ch1, ...
    Empty (or NA, null) cells are gaps."""

    name = TEXT_FALLBACK
    label = "CSV/TSV"
    suffixes = (".csv", ".tsv", ".txt", ".dat", ".asc")

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        raw = p.read_bytes()
        try:
            text = raw.decode("utf-8-sig")
        except UnicodeDecodeError:  # a logger on Windows writes its code page (a µ, a °, a ²)
            text = raw.decode("cp1252", "replace")
        rows = [
            (n, line)
            for n, line in enumerate(text.splitlines(), 1)
            if line.strip() and not line.lstrip().startswith("#")
        ]
        if not rows:
            raise DataError(f"channels: {p} has no header row and no data (only blank or '#' lines)")
        first_line, header = rows[0]
        sep, cells = _splitter(header)
        while cells and not cells[-1]:  # 'a,b,c,': a trailing delimiter names no column
            cells.pop()
        if all(_is_float(c) for c in cells):  # no header: the first row is data
            body = rows
            timed = fs is None and time_column is None  # the first column is the time, as under a header
            cells = ["time"] * timed + [f"ch{j}" for j in range(len(cells) - timed)]
        else:
            body = rows[1:]
            dup = next((c for c in cells if cells.count(c) > 1), None)
            if dup is not None:
                raise DataError(f"channels: {p} line {first_line}: the header names the column {dup!r} twice")
            empty = [j for j, c in enumerate(cells) if not c]
            if empty:
                raise DataError(f"channels: {p} line {first_line}: header column {empty[0] + 1} has no name")
        if not body:
            raise DataError(f"channels: {p} has a header row ({', '.join(cells)}) and no data rows")
        head = _header(p, cells, time_column, fs)
        width = len(cells)
        blank = (sep or "") + " \t"
        body = [(n, line) for n, line in body if line.strip(blank)]  # a row of empty cells is no sample
        lines = np.array([n for n, _ in body], dtype=np.int64)
        text_rows = [line for _, line in body]
        split = (lambda s: s.split()) if sep is None else (lambda s: next(csvlib.reader([s], delimiter=sep)))
        count = (lambda s: len(s.split())) if sep is None else (lambda s: s.count(sep) + 1)
        counts = np.fromiter(map(count, text_rows), dtype=np.int64, count=len(text_rows))
        odd = np.flatnonzero(counts != width)
        for k in odd:  # more cells than the header names are allowed only when empty (a trailing delimiter)
            cells_k = split(text_rows[k])
            if len(cells_k) < width or any(c.strip() for c in cells_k[width:]):
                raise DataError(
                    f"channels: {p} line {lines[k]}: {len(cells_k)} cells; the header names {width} "
                    f"({', '.join(cells)})"
                )
        grid = _fast_grid(text_rows, sep, width, int(counts.max()))
        if grid is None:
            grid = _slow_grid(p, [split(r)[:width] for r in text_rows], lines, cells)
        t = None if head.time is None else grid[:, head.time] * head.factor
        return Table(t, grid[:, head.columns], head.names, head.units, [], head.time_from, lines)


def _na_values() -> list[str]:
    cells = GAP_CELLS | {"nan", "-nan", "+nan"}
    return sorted({v for c in cells for v in (c, c.upper(), c.title(), c.capitalize())} | {"NaN"})


def _fast_grid(rows: list[str], sep: str | None, width: int, most: int) -> NDArray[np.float64] | None:
    """The numbers of the rows (samples, width) by pandas' C parser (gaps NaN), or None when a cell
    is not a number as it reads them (`_slow_grid` then says which)."""
    import io

    import pandas as pd

    try:
        df = pd.read_csv(
            io.StringIO("\n".join(rows)),
            sep=sep if sep is not None else r"\s+",
            header=None,
            names=list(range(most)),
            usecols=list(range(width)),
            index_col=False,
            dtype=np.float64,
            na_values=_na_values(),
            keep_default_na=False,
            skipinitialspace=True,
            skip_blank_lines=False,
            engine="c",
        )
    except (ValueError, pd.errors.ParserError):
        return None
    grid = df.to_numpy(dtype=np.float64)
    return grid if grid.shape == (len(rows), width) else None


def _slow_grid(p: Path, split: list[list[str]], lines: NDArray[np.int64], cells: list[str]) -> NDArray[np.float64]:
    """The numbers of the split rows, cell by cell: the first cell that is not a number (nor a gap)
    is a one-line DataError naming its line and column."""
    out = np.empty((len(split), len(cells)))
    for k, row in enumerate(split):
        for j, cell in enumerate(row):
            c = cell.strip()
            if c.lower() in GAP_CELLS:
                out[k, j] = np.nan
                continue
            try:
                out[k, j] = float(c)
            except ValueError:
                hint = "; a decimal comma: write decimal points (1.5, not 1,5)" if _DECIMAL_COMMA.fullmatch(c) else ""
                raise DataError(
                    f"channels: {p} line {lines[k]}, column {cells[j]}: not a number: {c[:40]!r}{hint}"
                ) from None
    return out


# ------------------------------------------------------------------------------------------ Parquet


@register
class ParquetReader(ChannelReader):
    """Parquet (.parquet): a table read as the CSV is (named columns, units in brackets or in a
    field's 'units' metadata, date-times as seconds since the first)."""

    name = "parquet"
    label = "Parquet"
    suffixes = (".parquet", ".pq")

    def claims(self, head: bytes) -> bool:
        return head.startswith(b"PAR1")

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        _signature(p, b"PAR1", "Parquet")
        try:
            import pandas as pd
            import pyarrow.parquet as pq
        except ImportError:
            raise InputError("channels: reading Parquet needs pyarrow: pip install 'vibinverse[parquet]'") from None
        schema = pq.read_schema(p)
        meta = {f.name: _unit((f.metadata or {}).get(b"units") or (f.metadata or {}).get(b"unit")) for f in schema}
        df = pd.read_parquet(p)
        if any(name is not None for name in df.index.names):  # a named index (a time, often) is a column
            df = df.reset_index()
        cells = [str(c) for c in df.columns]
        if len(set(cells)) != len(cells):
            dup = next(c for c in cells if cells.count(c) > 1)
            raise DataError(f"channels: {p} names the column {dup!r} twice")
        head = _header(p, cells, time_column, fs, [meta.get(c) for c in cells])
        if len(df) == 0:
            raise DataError(f"channels: {p} has columns ({', '.join(cells)}) and no rows")

        def column(j: int) -> NDArray[np.float64]:
            col = df.iloc[:, j]
            if pd.api.types.is_numeric_dtype(col) and not pd.api.types.is_bool_dtype(col):
                return col.to_numpy(dtype=float, na_value=np.nan)
            return real_numbers(col.to_numpy(), f"{p}: column {cells[j]}")

        values = np.column_stack([column(j) for j in head.columns])
        notes: list[str] = []
        t = None
        if head.time is not None:
            col = df.iloc[:, head.time]
            if pd.api.types.is_datetime64_any_dtype(col):
                stamps = pd.DatetimeIndex(col)
                if stamps.hasnans:
                    raise DataError(f"channels: {p}: the time column {cells[head.time]} has missing date-times")
                notes.append(f"{TIME_REFERENCE_NOTE}{stamps[0].isoformat()}")
                if stamps.tz is not None:
                    stamps = stamps.tz_convert("UTC").tz_localize(None)
                d = stamps.to_numpy()
                t = (d - d[0]) / np.timedelta64(1, "s")
            else:
                t = column(head.time) * head.factor
        return Table(t, values, head.names, head.units, notes, head.time_from)


# ---------------------------------------------------------------------------------------- .npy / .npz


def _np_load(p: Path, load: Any) -> Any:
    try:
        return load()
    except ValueError as exc:
        if "allow_pickle" in str(exc):
            raise DataError(f"channels: {p} holds Python objects (pickled); real numbers are needed") from None
        raise


@register
class NpyReader(ChannelReader):
    """.npy: N x (1 + C) numbers, the first column the time; N x C (or a vector) with fs; a
    structured array is a table with named columns (as a CSV's)."""

    name = "npy"
    label = ".npy"
    suffixes = (".npy",)
    options = frozenset({"fs"})

    def claims(self, head: bytes) -> bool:
        return head.startswith(b"\x93NUMPY")

    def refuse(self, p: Path, given: list[str]) -> DataError:
        return DataError(f"channels: time_column does not apply to {p}: an .npy's time is its first column (or fs)")

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        _signature(p, b"\x93NUMPY", ".npy")
        arr = _np_load(p, lambda: np.load(p, allow_pickle=False))
        if arr.dtype.names:  # a structured array: named columns
            cells = list(arr.dtype.names)
            head = _header(p, cells, None, fs)
            cols = {c: real_numbers(arr[c], f"{p}: {c}").reshape(-1) for c in cells}
            values = np.column_stack([cols[cells[j]] for j in head.columns])
            t = None if head.time is None else cols[cells[head.time]] * head.factor
            return Table(t, values, head.names, head.units, [], head.time_from)
        arr = real_numbers(arr, str(p))
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2:
            raise DataError(f"channels: {p} must hold an N x (1 + C) array (time, channels), got shape {arr.shape}")
        if fs is None and arr.shape[1] < 2:
            raise DataError(
                f"channels: {p} holds {arr.shape[1]} column (shape {arr.shape}) and no fs was given: an N x (1 + C) "
                "array (time first) or fs= is needed"
            )
        if fs is not None:
            return Table(None, arr, [f"ch{j}" for j in range(arr.shape[1])], [None] * arr.shape[1])
        return Table(
            arr[:, 0],
            arr[:, 1:],
            [f"ch{j}" for j in range(arr.shape[1] - 1)],
            [None] * (arr.shape[1] - 1),
            [],
            "the first column",
        )


@register
class NpzReader(ChannelReader):
    """.npz: named arrays (`arrays_table`): a time array and value arrays of its length, or a 2-D
    array named by channel_names, with a scalar sample_rate."""

    name = "npz"
    label = ".npz"
    suffixes = (".npz",)

    def claims(self, head: bytes) -> bool:
        return head.startswith(b"PK\x03\x04")

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        _signature(p, b"PK\x03\x04", ".npz (zip)")
        arrays: dict[str, Any] = {}
        with np.load(p, allow_pickle=False) as z:
            for key in z.files:
                try:
                    arrays[key] = z[key]
                except ValueError:  # pickled objects: never a channel
                    arrays[key] = None
        return arrays_table(p, arrays, time_column, fs)


# ------------------------------------------------------------------------------------------- netCDF


def _text_values(v: Any) -> list[str] | None:
    a = np.asarray(v)
    if a.dtype.kind in "USO" and a.ndim == 1:
        return [s.decode() if isinstance(s, bytes) else str(s).strip() for s in a]
    return None


@register
class NetcdfReader(ChannelReader):
    """netCDF (.nc): the channels are the numeric variables on the time dimension (`time_column`, else
    one named like a time, else the one dimension they share): a 1-D variable is a channel named by
    the variable, a 2-D (time, channel) variable one channel per entry of its other dimension, named by
    that dimension's string coordinate (else ch0, ch1, ...); units from `units` attributes (or a
    string coordinate 'units' on the channel dimension); the time from the time dimension's coordinate
    (CF units: 'milliseconds since 2024-01-01' becomes seconds since its epoch), else fs."""

    name = "netcdf"
    label = "netCDF"
    suffixes = (".nc", ".netcdf", ".cdf", ".nc4")

    def claims(self, head: bytes) -> bool:
        return (head[:3] == b"CDF" and head[3:4] in (b"\x01", b"\x02", b"\x05")) or head.startswith(_HDF5)

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        import xarray as xr

        engine = "h5netcdf" if netcdf_format(p, "channels") == "hdf5" else "scipy"
        with xr.open_dataset(p, engine=engine, decode_times=False, decode_timedelta=False) as ds:
            return self._table(p, ds, time_column, fs)

    def _table(self, p: Path, ds: Any, time_column: str | None, fs: float | None) -> Table:
        numeric = {str(k): v for k, v in ds.data_vars.items() if v.dtype.kind in "fiu" and v.ndim in (1, 2)}
        dims = sorted({str(d) for v in numeric.values() for d in v.dims})
        shown = ", ".join(map(str, ds.variables)) or "none"
        if time_column is not None:
            if time_column not in ds.dims:
                raise DataError(
                    f"channels: {p} has no time dimension {time_column!r} (time_column); its dimensions: "
                    f"{', '.join(map(str, ds.dims))}"
                )
            tdim = time_column
        else:
            named = [d for d in dims if d.lower() in TIME_NAMES]
            shared = [d for d in dims if all(d in v.dims for v in numeric.values())]
            tdim = named[0] if len(named) == 1 else shared[0] if len(shared) == 1 else None
            if tdim is None:
                raise DataError(
                    f"channels: {p}: which dimension is the time? none is named time and the variables share "
                    f"{len(shared)} ({', '.join(shared) or 'none'}); choose it with time_column=; its variables: "
                    f"{shown}"
                )
        t, notes = None, []
        if tdim in ds.variables:
            if fs is not None:
                raise DataError(
                    f"channels: {p} has a time coordinate ({tdim}) and fs was given: the time is ambiguous; drop fs"
                )
            ta = ds[tdim]
            factor, ref = _time_factor(p, f"time {tdim}", ta.attrs.get("units"))
            t = real_numbers(ta.values, f"{p}: time").astype(float) * factor
            if ref:
                notes.append(f"{TIME_REFERENCE_NOTE}{ref}")
        elif fs is None:
            rate = next((ds.attrs[r] for r in RATE_NAMES if r in ds.attrs), None)
            rate = rate if rate is not None else next((ds[r].values for r in RATE_NAMES if r in ds.data_vars), None)
            if rate is None:
                raise DataError(
                    f"channels: {p}: the time dimension {tdim} has no coordinate and no fs was given; give fs="
                )
            fs = float(np.asarray(rate).reshape(()))
            if not (np.isfinite(fs) and fs > 0):
                raise DataError(f"channels: {p}: sampling rate {fs:g} Hz; allowed range (0, inf)")
        on_time = {k: v for k, v in numeric.items() if tdim in v.dims and k != tdim}
        if not on_time:
            raise DataError(
                f"channels: {p} has no numeric variable on the time dimension {tdim}; its variables: {shown}"
            )
        lone = len(on_time) == 1
        columns, names, units = [], [], []
        for k, v in on_time.items():
            unit = _unit(v.attrs.get("units"))
            if v.ndim == 1:
                columns.append(real_numbers(v.values, f"{p}: {k}").astype(float))
                names.append(k)
                units.append(unit)
                continue
            v = v.transpose(tdim, ...)
            cdim = str(v.dims[1])
            labels = _text_values(ds[cdim].values) if cdim in ds.variables else None
            per = next(
                (ds[c].values for c in ds.variables if str(c).lower() in UNIT_ARRAYS and ds[c].dims == (cdim,)), None
            )
            per = _text_values(per) if per is not None else None
            block = real_numbers(v.values, f"{p}: {k}").astype(float)
            c = block.shape[1]
            cols = labels if labels is not None and len(labels) == c else None
            cols = cols or ([f"ch{j}" for j in range(c)] if lone else [f"{k}[{j}]" for j in range(c)])
            columns.extend(block[:, j] for j in range(c))
            names.extend(cols)
            units.extend(_unit(per[j]) if per is not None and len(per) == c else unit for j in range(c))
        if t is not None and t.size != columns[0].size:
            raise DataError(f"channels: {p}: the time has {t.size} values, the channels {columns[0].size}")
        if t is None:
            t = np.arange(columns[0].size) / fs
        return Table(t, np.column_stack(columns), names, units, notes, f"the time coordinate {tdim}")


# ---------------------------------------------------------------------------------------------- lvm

_X_VALUE = "X_Value"


@register
class LvmReader(ChannelReader):
    """LabVIEW Measurement files (.lvm, or any text file starting 'LabVIEW Measurement'): every
    channel by `vibinverse.io.lvm.read_lvm`, the time from the X_Value column (a header Delta_X
    that disagrees is noted, not used), units from Y_Unit_Label; fs for a file without X_Value."""

    name = "lvm"
    label = "LabVIEW lvm"
    suffixes = (".lvm",)
    options = frozenset({"fs"})

    def claims(self, head: bytes) -> bool:
        from vibinverse.io.lvm import is_lvm

        return is_lvm(head)

    def refuse(self, p: Path, given: list[str]) -> DataError:
        return DataError(
            f"channels: time_column does not apply to the LabVIEW Measurement file {p}: its time is the X_Value "
            "column, or X0 + Delta_X from its header"
        )

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        from vibinverse.io.lvm import read_lvm

        names = self._names(p)
        dup = next((n for n in names if names.count(n) > 1), None)
        if dup is not None:
            raise DataError(f"channels: {p}: the channel name {dup!r} appears twice; names must be unique")
        reads = [read_lvm(p, value_column=n, fs=fs) for n in names]
        t = reads[0].time
        for r in reads[1:]:
            if r.time.shape != t.shape or not np.allclose(
                r.time, t, rtol=0, atol=1e-9 * max(1.0, float(np.abs(t).max()))
            ):
                raise DataError(
                    f"channels: {p}: channel {r.channel}'s X_Value column differs from {reads[0].channel}'s; "
                    "the channels are not on one clock"
                )
        keep = ("channel:", UNITS_NOTE)
        notes = [n for n in reads[0].notes if not n.startswith(keep)]
        return Table(
            t,
            np.column_stack([r.intensity for r in reads]),
            [r.channel for r in reads],
            [r.unit for r in reads],
            notes,
            "the X_Value column",
        )

    @staticmethod
    def _names(p: Path) -> list[str]:
        """The channel names of the first column row (X_Value, names..., Comment), as `read_lvm` names
        them: blanks stripped, an empty name 'column K'."""
        with open(p, encoding="latin-1") as fh:
            for line in fh:
                if line.startswith(_X_VALUE) and len(line) > len(_X_VALUE):
                    sep = line[len(_X_VALUE)]
                    cells = [c.strip() for c in line.rstrip("\r\n").split(sep)]
                    while cells and not cells[-1]:
                        cells.pop()
                    if cells and cells[-1] == "Comment":
                        cells.pop()
                    return [c or f"column {k}" for k, c in enumerate(cells) if c != _X_VALUE]
        from vibinverse.io.lvm import read_lvm

        return [read_lvm(p).channel]  # no column row: read_lvm says what is wrong


# --------------------------------------------------------------------------------------------- TDMS


@register
class TdmsReader(ChannelReader):
    """NI TDMS (.tdms, npTDMS): every channel of every group (named 'group/channel' when more than one
    group holds channels), units from the `unit_string` property; the time from a channel named like
    a time (or `time_column`), else the waveform properties wf_start_offset + k wf_increment, else fs."""

    name = "tdms"
    label = "TDMS"
    suffixes = (".tdms",)

    def claims(self, head: bytes) -> bool:
        return head.startswith(b"TDSm")

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        _signature(p, b"TDSm", "TDMS")
        try:
            from nptdms import TdmsFile
        except ImportError:
            raise _missing("npTDMS", "TDMS") from None
        try:
            tdms = TdmsFile.read(p)
            groups = [(g.name, [(c.name, c[:], dict(c.properties)) for c in g.channels()]) for g in tdms.groups()]
        except Exception as exc:  # noqa: BLE001 - npTDMS raises many kinds on a malformed file
            raise DataError(f"channels: cannot read the TDMS file {p}: {first_line(exc)}") from None
        groups = [(g, chans) for g, chans in groups if chans]
        if not groups:
            raise DataError(f"channels: {p} holds no channels")
        many = len(groups) > 1
        entries = [(f"{g}/{c}" if many else c, c, data, props) for g, chans in groups for c, data, props in chans]
        keys = [e[0] for e in entries]
        if time_column is not None:
            it = _find(keys, time_column) if time_column not in keys else keys.index(time_column)
            if it is None:
                raise DataError(
                    f"channels: {p} has no channel {time_column!r} (time_column); its channels: {', '.join(keys)}"
                )
        else:
            named = [i for i, e in enumerate(entries) if e[1].strip().lower() in TIME_NAMES]
            it = named[0] if len(named) == 1 else None
        sizes = {e[0]: len(e[2]) for e in entries}
        if len(set(sizes.values())) > 1:
            shown = ", ".join(f"{k} {v}" for k, v in sizes.items())
            raise DataError(f"channels: {p}: the channels have different lengths ({shown}); they must share one clock")
        notes: list[str] = []
        t = None
        if it is not None:
            if fs is not None:
                raise DataError(f"channels: {p} has a time channel ({keys[it]}) and fs was given: drop fs")
            data = np.asarray(entries[it][2])
            if data.dtype.kind == "M":
                notes.append(f"{TIME_REFERENCE_NOTE}{np.datetime_as_string(data[0])}")
                t = (data - data[0]) / np.timedelta64(1, "s")
            else:
                factor, _ = _time_factor(p, f"time channel {keys[it]}", _unit(entries[it][3].get("unit_string")))
                t = real_numbers(data, f"{p}: {keys[it]}") * factor
            time_from = f"the time channel {keys[it]}"
        chans = [e for i, e in enumerate(entries) if i != it]
        if not chans:
            raise DataError(f"channels: {p} holds only a time channel ({keys[it]}); no channel")
        if t is None and fs is None:
            steps = {float(e[3]["wf_increment"]) for e in chans if "wf_increment" in e[3]}
            starts = {float(e[3].get("wf_start_offset", 0.0)) for e in chans if "wf_increment" in e[3]}
            if len(steps) != 1 or len(starts) != 1 or any("wf_increment" not in e[3] for e in chans):
                raise DataError(
                    f"channels: {p}: no time channel and the channels do not share one wf_increment "
                    f"({', '.join(map(str, sorted(steps))) or 'none'}); give fs= or time_column="
                )
            (step,), (start,) = steps, starts
            if not (np.isfinite(step) and step > 0):
                raise DataError(f"channels: {p}: wf_increment {step:g} s; allowed range (0, inf)")
            t = start + np.arange(sizes[chans[0][0]]) * step
            time_from = "the wf_increment property"
        elif t is None:
            time_from = "fs"
        values = np.column_stack([real_numbers(np.asarray(e[2]), f"{p}: {e[0]}") for e in chans])
        units = [_unit(e[3].get("unit_string")) for e in chans]
        return Table(t, values, [e[0] for e in chans], units, notes, time_from)


# ------------------------------------------------------------------------------------------- MATLAB


def _matlab_v5(p: Path) -> dict[str, Any]:
    from scipy.io import loadmat

    raw = loadmat(p, simplify_cells=True)
    return {k: v for k, v in raw.items() if not k.startswith("__")}


def _h5_value(h5: Any, obj: Any) -> Any:
    """A MATLAB v7.3 (HDF5) dataset or group as MATLAB shows it: numbers transposed back and
    squeezed, text as str (a char matrix as a list of rows), a cell of text as a list, a struct as a dict."""
    import h5py

    if isinstance(obj, h5py.Group):
        return {k: _h5_value(h5, v) for k, v in obj.items()}
    cls = obj.attrs.get("MATLAB_class", b"")
    cls = cls.decode() if isinstance(cls, bytes) else str(cls)
    data = obj[()]
    if cls == "char":
        codes = np.atleast_2d(np.asarray(data)).T  # MATLAB's rows
        rows = ["".join(map(chr, row)).rstrip() for row in codes]
        return rows[0] if len(rows) == 1 else rows
    if cls == "cell":
        items = [_h5_value(h5, h5[ref]) for ref in np.asarray(data).T.reshape(-1)]
        return items
    if obj.attrs.get("MATLAB_empty", 0):
        return np.zeros((0,))
    a = np.asarray(data)
    if a.dtype.kind not in "fiub":
        return None
    return np.squeeze(a.T)


def _matlab_v73(p: Path) -> dict[str, Any]:
    import h5py

    with h5py.File(p, "r") as h5:
        return {k: _h5_value(h5, v) for k, v in h5.items() if not k.startswith("#")}


@register
class MatReader(ChannelReader):
    """MATLAB .mat (v4-v7 by scipy.io.loadmat, v7.3 = HDF5 by h5py): named arrays as an .npz's
    (`arrays_table`): a 2-D numeric array (samples x channels) or vectors of one length, a time
    vector, a scalar fs, a cell array channel_names / names and units; the fields of a lone struct
    are its arrays (of several structs, 'struct.field')."""

    name = "mat"
    label = "MATLAB"
    suffixes = (".mat",)

    def claims(self, head: bytes) -> bool:
        return head.startswith(b"MATLAB")

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        import h5py
        from scipy.io.matlab import MatReadError

        try:
            arrays = _matlab_v73(p) if h5py.is_hdf5(p) else _matlab_v5(p)
        except (
            NotImplementedError,
            MatReadError,
            ValueError,
            TypeError,
            KeyError,
            IndexError,
            OSError,
            EOFError,
        ) as exc:
            raise DataError(f"channels: cannot read the MATLAB file {p}: {first_line(exc)}") from None
        structs = [k for k, v in arrays.items() if isinstance(v, dict)]
        if len(arrays) == 1 and structs:
            arrays = arrays[structs[0]]
        else:
            for k in structs:
                arrays.update({f"{k}.{f}": v for f, v in arrays.pop(k).items()})
        arrays = {
            k: (np.asarray(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else v)
            for k, v in arrays.items()
        }
        return arrays_table(p, arrays, time_column, fs)


# ------------------------------------------------------------------------------------------ UFF 58

#: UFF58 response directions (rsp_dir) as written after the node number
_DIRECTIONS = {0: "", 1: "+X", 2: "+Y", 3: "+Z", 4: "+RX", 5: "+RY", 6: "+RZ"}
_DIRECTIONS.update({-k: "-" + v[1:] for k, v in _DIRECTIONS.items() if k})
#: function types (UFF58 record 6) that are time records, and abscissa data types that are time
UFF_TIME_FUNCTIONS = frozenset({0, 1})
UFF_TIME_ABSCISSA = frozenset({0, 17})


@register
class UffReader(ChannelReader):
    """Universal File Format dataset 58 (.uff, .unv, or a text file opening with the '-1' delimiter;
    pyuff): each time-response dataset 58 is a channel, named by its ID line 1 (else node and
    direction, '12+Z'), units from its ordinate units label, the time from its abscissa (x); other
    datasets (geometry, units) are left out."""

    name = "uff"
    label = "UFF 58"
    suffixes = (".uff", ".unv", ".uf")
    options = frozenset()

    def claims(self, head: bytes) -> bool:
        lines = head.decode("latin-1").splitlines()
        return len(lines) > 1 and lines[0].strip() == "-1" and lines[1].strip()[:6].isdigit()

    def read(self, p: Path, *, time_column: str | None = None, fs: float | None = None) -> Table:
        try:
            import pyuff
        except ImportError:
            raise _missing("pyuff", "UFF") from None
        try:
            uff = pyuff.UFF(str(p))
            types = [int(t) for t in uff.get_set_types()]
            sets = [uff.read_sets(i) for i, kind in enumerate(types) if kind == 58]
        except Exception as exc:  # noqa: BLE001 - pyuff raises bare Exception on a malformed file
            raise DataError(f"channels: cannot read the UFF file {p}: {first_line(exc)}") from None
        if not sets:
            found = ", ".join(sorted({str(t) for t in types})) or "none"
            raise DataError(f"channels: {p} holds no dataset 58 (time records); its datasets: {found}")
        for k, s in enumerate(sets):
            func, absc = int(s.get("func_type", 0)), int(s.get("abscissa_spec_data_type", 0))
            if func not in UFF_TIME_FUNCTIONS or absc not in UFF_TIME_ABSCISSA:
                raise DataError(
                    f"channels: {p}: dataset 58 #{k + 1} ({s.get('id1', '').strip()}) has function type {func} and "
                    f"abscissa type {absc}; a channel is a time response (function type 1, abscissa 17 = time)"
                )
            if np.iscomplexobj(s["data"]):
                raise DataError(f"channels: {p}: dataset 58 #{k + 1} holds complex values; a time record is real")
        sizes = [len(s["data"]) for s in sets]
        if len(set(sizes)) > 1:
            raise DataError(
                f"channels: {p}: the datasets 58 have different lengths ({sizes}); they must share one clock"
            )
        t = np.asarray(sets[0]["x"], dtype=float)
        for k, s in enumerate(sets[1:], 2):
            x = np.asarray(s["x"], dtype=float)
            if not np.allclose(x, t, rtol=0, atol=1e-9 * max(1.0, float(np.abs(t).max()))):
                raise DataError(f"channels: {p}: dataset 58 #{k}'s abscissa differs from #1's; not one clock")
        ids = [str(s.get("id1", "")).strip() for s in sets]
        if any(_unit(i) is None for i in ids) or len(set(ids)) < len(ids):
            ids = [f"{int(s.get('rsp_node', 0))}{_DIRECTIONS.get(int(s.get('rsp_dir', 0)), '')}" for s in sets]
        values = np.column_stack([np.asarray(s["data"], dtype=float) for s in sets])
        units = [_unit(s.get("ordinate_axis_units_lab")) for s in sets]
        factor, _ = _time_factor(p, "abscissa", _unit(sets[0].get("abscissa_axis_units_lab")))
        return Table(t * factor, values, ids, units, [], "the abscissa")
