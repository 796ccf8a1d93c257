"""Several channels measured on one clock: a logger's table of N samples x C channels (accelerometers,
strain gauges, displacement sensors, a hammer's or shaker's force), with each channel's name, units and
optional sensor position, and which channels are measured inputs (known excitation) rather than
responses.

`load_channels` reads such a table from a file (CSV/TSV, Parquet, .npy, .npz, netCDF, LabVIEW lvm,
TDMS, MATLAB .mat, UFF dataset 58: the readers are in `vibinverse.io.channel_readers`), chooses and
orders its channels, flags the measured inputs and places the sensors from a geometry table.

A NaN value is a gap in that channel. Every problem raises `vibinverse.errors.InputError` (a file's
content: its subclass `DataError`) with one line naming the field.
"""

from __future__ import annotations

import csv
import math
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError
from vibinverse.io.channel_readers import Table, channel_reader_for
from vibinverse.io.file_basics import UNITS_NOTE, evenly_spaced, first_line, positive_option
from vibinverse.io.series import Series, check_file


@dataclass(frozen=True)
class Channels:
    """`values[k, c]` is channel c at `time[k]` (s, increasing); `names[c]`, `units[c]` (None when
    the file gives none), `positions[c]` = (x, y, z) in metres when a geometry table gave them,
    `inputs` the names of the channels that are measured excitation (an input the geometry does not
    place, a drive voltage, has a NaN position)."""

    time: NDArray[np.float64]
    values: NDArray[np.float64]  # (samples, channels), NaN = gap
    names: tuple[str, ...]
    units: tuple[str | None, ...]
    source: str
    positions: NDArray[np.float64] | None = None  # (channels, 3), metres
    inputs: tuple[str, ...] = ()
    notes: list[str] = field(default_factory=list)

    def __post_init__(self) -> None:
        t = np.asarray(self.time, dtype=float)
        v = np.asarray(self.values, dtype=float)
        if v.ndim == 1:
            v = v[:, None]
        if t.ndim != 1 or v.ndim != 2 or v.shape[0] != t.size:
            raise InputError(
                f"channels {self.source}: time must be 1-D and values (samples, channels) with one row per "
                f"stamp; got shapes {t.shape} and {np.shape(self.values)}"
            )
        if t.size < 2 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
            raise InputError(f"channels {self.source}: time must hold >= 2 finite, strictly increasing stamps")
        names, units = tuple(str(n) for n in self.names), tuple(self.units)
        if len(names) != v.shape[1] or len(units) != v.shape[1]:
            raise InputError(
                f"channels {self.source}: {v.shape[1]} channel(s) need as many names and units; got "
                f"{len(names)} names and {len(units)} units"
            )
        if len(set(names)) != len(names):
            dup = next(n for n in names if names.count(n) > 1)
            raise InputError(f"channels {self.source}: channel name {dup!r} appears twice; names must be unique")
        unknown = [n for n in self.inputs if n not in names]
        if unknown:
            raise InputError(f"inputs: {unknown[0]!r} is not a channel; allowed: {', '.join(names)}")
        if self.positions is not None:
            p = np.asarray(self.positions, dtype=float)
            # a measured input (a drive voltage) may have no place: its row all NaN
            shaped = p.shape == (v.shape[1], 3)
            unplaced = np.array([n in self.inputs for n in names]) & (np.isnan(p).all(axis=1) if shaped else False)
            if not shaped or not np.all(np.isfinite(p).all(axis=1) | unplaced):
                raise InputError(
                    f"positions: need finite (x, y, z) for each of the {v.shape[1]} channel(s) (NaN only for a "
                    f"measured input); got shape {p.shape}"
                )
            object.__setattr__(self, "positions", p)
        object.__setattr__(self, "time", t)
        object.__setattr__(self, "values", v)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "units", units)
        object.__setattr__(self, "inputs", tuple(self.inputs))

    @property
    def n_channels(self) -> int:
        return int(self.values.shape[1])

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.time)))

    @property
    def fs(self) -> float:
        return 1.0 / self.dt

    @property
    def uniform(self) -> bool:
        return evenly_spaced(self.time)

    @property
    def gaps(self) -> NDArray[np.bool_]:
        """(samples, channels): True where a value is missing."""
        return ~np.isfinite(self.values)

    @property
    def responses(self) -> tuple[str, ...]:
        """The channels that are not measured inputs, in file order."""
        return tuple(n for n in self.names if n not in self.inputs)

    def index(self, name: str) -> int:
        """The column of channel `name`; a one-line InputError naming the allowed names otherwise."""
        if name not in self.names:
            raise InputError(f"channels: no channel {name!r}; allowed: {', '.join(self.names)}")
        return self.names.index(name)

    def rows(self, start: int, stop: int) -> Channels:
        """Samples start .. stop - 1 of every channel (names, units, positions and inputs kept)."""
        return replace(self, time=self.time[start:stop], values=self.values[start:stop], notes=list(self.notes))

    def select(self, names: list[str] | tuple[str, ...]) -> Channels:
        """These channels, in this order (their positions and input flags kept)."""
        if not names:
            raise InputError("channels: select at least one channel")
        idx = [self.index(n) for n in names]
        return replace(
            self,
            values=self.values[:, idx],
            names=tuple(self.names[i] for i in idx),
            units=tuple(self.units[i] for i in idx),
            positions=None if self.positions is None else self.positions[idx],
            inputs=tuple(n for n in self.inputs if n in names),
        )

    def channel(self, name: str) -> Series:
        """One channel as a Series (its units in the notes, as a file-read series carries them)."""
        i = self.index(name)
        notes = list(self.notes)
        if self.units[i]:
            notes.append(f"{UNITS_NOTE} {self.units[i]}")
        return Series(self.time, self.values[:, i], f"{self.source}:{name}", notes=notes)

    def describe(self) -> str:
        kind = f"uniform at {self.fs:g} Hz" if self.uniform else "irregular stamps"
        gaps = int(self.gaps.sum())
        inputs = f"; inputs: {', '.join(self.inputs)}" if self.inputs else ""
        return (
            f"{self.time.size} samples x {self.n_channels} channels ({', '.join(self.names)}) over "
            f"{self.time[-1] - self.time[0]:g} s, {kind}; {gaps} missing values{inputs}"
        )


#: the columns of a geometry table, in metres
GEOMETRY_COLUMNS = ("name", "x", "y", "z")


def load_channels(
    path: str | Path,
    *,
    channels: str | list[str] | tuple[str, ...] | None = None,
    time_column: str | None = None,
    fs: float | None = None,
    inputs: str | list[str] | tuple[str, ...] = (),
    geometry: str | Path | None = None,
) -> Channels:
    """Read a multi-channel file (the reader chosen by suffix, else by its first bytes:
    `vibinverse.io.channel_readers.channel_reader_for`) into `Channels`.

    `channels`: None or "all" = every channel in file order; a list (or a comma-separated string) of
    names chooses and orders them. `time_column` names the time column / array / variable when it is
    not named like a time (time, t, seconds, ...; a table's first column otherwise); `fs` (Hz) gives
    the time of a file without one, arange(n) / fs. `inputs`: the channels that are measured
    excitation (a force, a drive voltage), kept in the table and flagged. `geometry`: a CSV
    name,x,y,z (metres) placing every chosen response channel (`read_geometry`). Empty or NaN
    cells are gaps (NaN). Every problem is a one-line InputError (a file's content: DataError)
    naming the file or option and what is allowed."""
    p = check_file(path, "channels")
    rate = positive_option(fs, "fs", "Hz")
    reader = channel_reader_for(p)
    given = {"time_column": time_column, "fs": rate}
    refused = [name for name, value in given.items() if value is not None and name not in reader.options]
    if refused:
        raise reader.refuse(p, refused)
    try:
        table = reader.read(p, **given)
    except InputError:
        raise
    except (OSError, ValueError, TypeError, KeyError, IndexError, EOFError, zipfile.BadZipFile) as exc:
        raise DataError(f"channels: cannot read {p}: {first_line(exc)}") from None
    time, values = _checked(p, table, rate)
    names = list(table.names)
    wanted = _name_list(channels, "channels", every="all")
    if wanted is not None and not wanted:
        raise InputError("channels: choose at least one channel (or all)")
    chosen = names if wanted is None else _resolve(p, names, wanted, "channels", "a channel")
    flagged = _resolve(p, chosen, _name_list(inputs, "inputs") or [], "inputs", "a chosen channel")
    idx = [names.index(n) for n in chosen]
    positions = None
    if geometry is not None:
        placed = read_geometry(geometry)
        missing = [n for n in chosen if n not in placed and n not in flagged]
        if missing:
            raise DataError(
                f"geometry: {geometry} has no position for channel(s) {', '.join(missing)}; it places: "
                f"{', '.join(placed) or 'none'} (every chosen response channel needs one)"
            )
        positions = np.array([placed.get(n, (np.nan, np.nan, np.nan)) for n in chosen], dtype=float)
    return Channels(
        time=time,
        values=values[:, idx],
        names=tuple(chosen),
        units=tuple(table.units[i] for i in idx),
        source=str(p),
        positions=positions,
        inputs=tuple(flagged),
        notes=list(table.notes),
    )


def read_geometry(path: str | Path) -> dict[str, tuple[float, float, float]]:
    """The sensor positions of a CSV table with the header name,x,y,z (metres; any order of those four
    columns, '#' comment lines allowed): {name: (x, y, z)}. A missing or extra column, a ragged row, a
    value that is not a finite number or a name given twice is a one-line DataError naming the line."""
    p = check_file(path, "geometry")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise DataError(f"geometry: cannot read {p}: {first_line(exc)}") from None
    rows = [
        (n, line) for n, line in enumerate(text.splitlines(), 1) if line.strip() and not line.lstrip().startswith("#")
    ]
    if not rows:
        raise DataError(f"geometry: {p} has no header row name,x,y,z")
    n0, first = rows[0]
    header = [c.strip().lower() for c in next(csv.reader([first]))]
    if sorted(header) != sorted(GEOMETRY_COLUMNS):
        raise DataError(
            f"geometry: {p} line {n0}: columns {','.join(header)}; allowed: {','.join(GEOMETRY_COLUMNS)} (metres)"
        )
    col = {c: header.index(c) for c in GEOMETRY_COLUMNS}
    out: dict[str, tuple[float, float, float]] = {}
    for n, line in rows[1:]:
        cells = [c.strip() for c in next(csv.reader([line]))]
        if len(cells) != len(header):
            raise DataError(f"geometry: {p} line {n}: {len(cells)} cells; the header names 4 (name,x,y,z)")
        name = cells[col["name"]]
        if not name:
            raise DataError(f"geometry: {p} line {n}: the name is empty")
        if name in out:
            raise DataError(f"geometry: {p} line {n}: {name!r} is placed twice")
        xyz = []
        for axis in GEOMETRY_COLUMNS[1:]:
            cell = cells[col[axis]]
            try:
                value = float(cell)
            except ValueError:
                raise DataError(f"geometry: {p} line {n}: {axis} {cell[:40]!r} is not a number (metres)") from None
            if not math.isfinite(value):
                raise DataError(f"geometry: {p} line {n}: {axis} {cell!r} is not finite; allowed: a number (metres)")
            xyz.append(value)
        out[name] = (xyz[0], xyz[1], xyz[2])
    if not out:
        raise DataError(f"geometry: {p} has a header and no rows")
    return out


def _name_list(value: Any, what: str, every: str | None = None) -> list[str] | None:
    """The names an option gives: None (or the word `every`, 'all') = every one, else a list from a
    list or a comma-separated string."""
    if value is None:
        return None
    if isinstance(value, str):
        if every is not None and value.strip().lower() == every:
            return None
        items = value.split(",")
    else:
        items = list(value)
    names = [str(v).strip() for v in items]
    if any(not n for n in names):
        raise InputError(f"{what}: an empty name in {value!r}; give names separated by commas")
    return names


def _resolve(p: Path, names: list[str], wanted: list[str], what: str, one: str) -> list[str]:
    """The names of `names` that `wanted` gives (exactly, else case-insensitively), in its order; an
    unknown or repeated one is a one-line InputError listing the allowed names."""
    lower = [n.lower() for n in names]
    out: list[str] = []
    for w in wanted:
        if w in names:
            hit = w
        elif lower.count(w.lower()) == 1:
            hit = names[lower.index(w.lower())]
        else:
            raise InputError(f"{what}: {w!r} is not {one} of {p}; allowed: {', '.join(names)}")
        if hit in out:
            raise InputError(f"{what}: {w!r} is given twice")
        out.append(hit)
    return out


def _where(table: Table, k: int) -> str:
    return f"line {table.lines[k]}" if table.lines is not None else f"sample {k}"


def _checked(p: Path, table: Table, fs: float | None) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """The time and values of a reader's table, checked: at least 2 samples and one channel, unique
    names, a finite, strictly increasing time (from fs when the file has none), no infinite value."""
    values = np.asarray(table.values, dtype=float)
    if values.ndim == 1:
        values = values[:, None]
    n, c = values.shape
    if c == 0:
        raise DataError(f"channels: {p} has no channel")
    if n < 2:
        raise DataError(f"channels: {p} has {n} sample{'s' * (n != 1)}; at least 2 are needed")
    dup = next((name for name in table.names if table.names.count(name) > 1), None)
    if dup is not None:
        raise DataError(f"channels: {p}: the channel name {dup!r} appears twice; names must be unique")
    if table.time is None:
        if fs is None:
            raise DataError(f"channels: {p} has no time; give fs=")
        time = np.arange(n) / fs
    else:
        time = np.asarray(table.time, dtype=float).reshape(-1)
    if time.size != n:
        raise DataError(f"channels: {p}: {time.size} time stamps for {n} samples")
    bad = ~np.isfinite(time)
    if bad.any():
        k = int(np.argmax(bad))
        raise DataError(
            f"channels: {p} {_where(table, k)}: the time is missing (an empty cell) or not finite ({table.time_from})"
        )
    step = np.diff(time)
    if not np.all(step > 0):
        k = int(np.argmin(step > 0)) + 1
        raise DataError(
            f"channels: {p} {_where(table, k)}: the time must be strictly increasing; {time[k]:.9g} s after "
            f"{time[k - 1]:.9g} s ({table.time_from})"
        )
    inf = np.isinf(values)
    if inf.any():
        k, j = (int(i) for i in np.argwhere(inf)[0])
        raise DataError(
            f"channels: {p} {_where(table, k)}, channel {table.names[j]}: an infinite value; a gap is NaN or "
            "an empty cell"
        )
    return time, values
