"""What every series reader shares: the notes' prefixes, the uniform-grid tolerance, the choice
of a channel among a file's series, the check that values are real numbers, and the netCDF flavour
of a file. `vibinverse.io.series` (validation) and `vibinverse.io.readers` (the formats) both use
it, so neither imports the other's insides.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from vibinverse.errors import DataError, InputError

# a uniform grid's tolerance, relative to its step: a timing error of 1e-3 of a sample moves a line at
# Nyquist by 3e-3 rad, far below any phase a fit resolves
UNIFORM_RTOL = 1e-3
#: how the readers note a time reference and the intensity's units (`Series.notes`)
TIME_REFERENCE_NOTE = "time: seconds since "
UNITS_NOTE = "intensity units: "


#: a spreadsheet reads a text cell starting with one of these as a formula
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


def csv_cell(value: object) -> object:
    """A text cell of a CSV table that a spreadsheet will not run as a formula (a leading quote
    before = + - @); numbers and other values pass through."""
    if isinstance(value, str) and value.startswith(FORMULA_START):
        return "'" + value
    return value


def evenly_spaced(t: np.ndarray) -> bool:
    """Whether stamps `t` lie on one regular grid to UNIFORM_RTOL of its step."""
    step = (t[-1] - t[0]) / (t.size - 1)
    return bool(np.max(np.abs(t - (t[0] + np.arange(t.size) * step))) <= UNIFORM_RTOL * step)


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


def choose_channel(p: Path, names: list[str], value_column: str | None, what: str = "channels") -> int:
    """The index in `names` (the series a file holds) of the one `value_column` names: a name
    (exactly, else case-insensitively, surrounding blanks ignored) or a 0-based index written as text
    ("2"); None chooses the only one. A missing or ambiguous choice is a one-line DataError listing
    `names`."""
    shown = ", ".join(names)
    if value_column is None:
        if len(names) == 1:
            return 0
        raise DataError(f"data: {p} has {len(names)} {what} ({shown or 'none'}): choose one with --value-column")
    key = str(value_column).strip()
    found = [i for i, n in enumerate(names) if n == key] or [i for i, n in enumerate(names) if n.lower() == key.lower()]
    if len(found) > 1:
        raise DataError(f"data: {p} names {len(found)} of its {what} {key}: choose one by its 0-based index ({shown})")
    if found:
        return found[0]
    if key.isdigit() and int(key) < len(names):
        return int(key)
    one = what[:-1] if what.endswith("s") and not what.endswith("series") else what
    raise DataError(
        f"data: {p} has no {one} {value_column!r}; its {what}: {shown or 'none'} "
        "(choose one with --value-column: a name or a 0-based index)"
    )


def real_numbers(a: Any, what: str) -> np.ndarray:
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


def first_line(exc: BaseException) -> str:
    """The first line of an exception's message (its type's name when it has none): what a one-line
    error quotes of a library's failure."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def positive_option(value: Any, name: str, unit: str, error: type[InputError] = InputError) -> float | None:
    """An option that is None or a finite positive number (a sampling rate, a frame rate); else a
    one-line `error` naming the option, its unit and the allowed range."""
    if value is None:
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise error(f"{name}: {value!r} is not a number ({unit})") from None
    if isinstance(value, bool) or not (math.isfinite(v) and v > 0):
        raise error(f"{name}: {value!r} {unit}; allowed range (0, inf)")
    return v


#: stamps whose every step is within this fraction of their mean step are read on the regular grid
#: by the frequency-domain likelihoods (a logger's clock whose rate wanders: a smartphone's 425 Hz
#: stamps keep every step within 0.1 % but wander 3.6 % of a step (rms) off one grid; a frequency then
#: moves by at most this fraction, 0.2 mHz at 17.85 Hz at 0.1 %); a dropped frame or a jittered camera
#: is not steady
STEADY_RTOL = 0.01


def steady(t: np.ndarray) -> bool:
    """Whether every step of the stamps `t` is within STEADY_RTOL of their mean step (uniform
    stamps are)."""
    steps = np.diff(t)
    mean = (t[-1] - t[0]) / (t.size - 1)
    return bool(mean > 0 and np.max(np.abs(steps - mean)) <= STEADY_RTOL * mean)
