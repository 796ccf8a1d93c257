"""LabVIEW Measurement files (.lvm): one channel of a text file written by LabVIEW, as a series.

Layout: a file header (a first line 'LabVIEW Measurement', tagged lines: Separator, Decimal_Separator,
X_Columns, ..., ending in ***End_of_Header***), then one or more segments: a segment header
(Channels, Samples, Y_Unit_Label, X0, Delta_X, ... ending in ***End_of_Header***; its cells line up
with the data columns after the first), a column row (X_Value, the channel names, maybe Comment)
and rows of numbers, ended by a blank line. X_Columns One: one time column (X_Value) first; Multi:
one before each channel; No: none (the rows start with an empty cell), the time is X0 + k Delta_X.
Segments (with their own headers, or more rows after a blank line) are concatenated.

The time comes from the channel's X_Value column when there is one: LabVIEW writes X0 + k Delta_X
with a few decimals, so stamps that lie on a regular grid to their printed digits are read as
that grid. A header Delta_X that disagrees with the column (it was not updated after
downsampling, or it is rounded) is noted and logged, and the column is used.
"""

from __future__ import annotations

import csv
import io
import logging
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError
from vibinverse.io.file_basics import TIME_REFERENCE_NOTE, UNITS_NOTE, choose_channel, evenly_spaced

logger = logging.getLogger(__name__)

MAGIC = "LabVIEW Measurement"
END = "***End_of_Header***"
#: the Separator values of the header (any other one-character value is taken literally)
SEPARATORS = {"tab": "\t", "comma": ",", "semicolon": ";", "space": " "}
X_COLUMNS = ("no", "one", "multi")
#: a header Delta_X further than this (relative) from the X_Value column's step is noted
DELTA_RTOL = 1e-3
#: stamps this large (s) are absolute (LabVIEW counts from 1904-01-01 UTC): the series counts from its first
ABSOLUTE_S = 1e6
LABVIEW_EPOCH = datetime(1904, 1, 1, tzinfo=UTC)
_NUMBER_START = frozenset("0123456789+-.")
#: the tags that may open a segment header (a new segment right after the rows of the previous one)
SEGMENT_TAGS = frozenset(("Notes", "Test_Name", "Test_Numbers", "UUT_Serial_Number", "Channels", "Samples"))


@dataclass(frozen=True)
class Lvm:
    """One channel of an lvm file: time (s), values, the channel's name and unit, and notes."""

    time: NDArray[np.float64]
    intensity: NDArray[np.float64]
    channel: str
    unit: str | None
    notes: list[str] = field(default_factory=list)


@dataclass
class _Segment:
    tags: dict[str, tuple[int, list[str]]]  # tag -> (1-based line, cells after the tag)
    names: list[str]  # the column row's names (without Comment)
    comment: bool  # the column row ends with Comment: rows may carry more cells
    names_line: int  # 1-based line of the column row
    start: int  # index (0-based) of the first data line
    stop: int  # index past the last data line


def is_lvm(head: bytes) -> bool:
    """Whether a file starting with the bytes `head` is a LabVIEW Measurement file."""
    return head.removeprefix(b"\xef\xbb\xbf").startswith(MAGIC.encode())


def read_lvm(path: str | Path, *, value_column: str | None = None, fs: float | None = None) -> Lvm:
    """One channel of the lvm file `path`: `value_column` names it (as in the column row, blanks
    stripped) or gives its 0-based index as text; the one channel by default. `fs` (Hz) gives the
    time of a file without X_Value columns (instead of its Delta_X). A malformed file is a one-line
    DataError naming the file and the line."""
    p = Path(path)
    lines = _lines(p)
    sep, dec, xcols, end = _file_header(p, lines)
    segments = _segments(p, lines, sep, end)
    first = [name for _, name in _channels(segments[0])]
    index = choose_channel(p, first, value_column)
    name = first[index]
    notes: list[str] = []
    if len(first) > 1:
        notes.append(f"channel: {name} (of {', '.join(first)})")
    times, values, units, ref, found = [], [], None, 0.0, {}
    for k, seg in enumerate(segments):
        col = _column_of(p, seg, first, index)
        tcol = None if xcols == "no" else next((c for c in range(col - 1, -1, -1) if seg.names[c] == "X_Value"), None)
        t, x = _block(p, lines, seg, sep, dec, tcol, col)
        if k == 0:
            units = _cell(seg, "Y_Unit_Label", col)[1] or None
            start = t[0] if t is not None else _header_number(p, seg, "X0", col, dec) or 0.0
            ref = float(start) if abs(start) >= ABSOLUTE_S else 0.0  # an absolute LabVIEW time
        t, said = _time(p, seg, col, t, fs, dec, ref)
        for kind, note in said.items():
            found.setdefault(kind, note)  # each kind of note once: from the first segment that calls for it
        times.append(t)
        values.append(x)
    notes += found.values()
    t = times[0]
    for k in range(1, len(times)):
        if times[k][0] <= t[-1]:
            raise DataError(
                f"data: {p} line {segments[k].start + 1}: segment {k + 1}'s time starts at {times[k][0] + ref:.9g} s, "
                f"not after segment {k}'s last stamp {t[-1] + ref:.9g} s: the segments are separate records"
            )
        t = np.concatenate([t, times[k]])
    x = np.concatenate(values)
    if ref:
        when = (LABVIEW_EPOCH + timedelta(seconds=ref)).isoformat().replace("+00:00", "Z")
        notes.append(f"{TIME_REFERENCE_NOTE}{when} (the lvm's first stamp, {ref:.17g} s after 1904-01-01 UTC)")
    if units:
        notes.append(f"{UNITS_NOTE}{units} (values kept; the fit's gain absorbs them)")
    return Lvm(t, x, name, units, notes)


def _lines(p: Path) -> list[str]:
    raw = p.read_bytes()
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:  # LabVIEW on Windows writes the local code page (a µ, a °)
        text = raw.decode("latin-1")
    return text.splitlines()


def _file_header(p: Path, lines: list[str]) -> tuple[str, str, str, int]:
    """(separator, decimal separator, X_Columns in lower case, index of the ***End_of_Header*** line)."""
    if not lines or not lines[0].startswith(MAGIC):
        raise DataError(f"data: {p} line 1: not a LabVIEW Measurement file (its first line must start with {MAGIC!r})")
    end = next((i for i, line in enumerate(lines) if line.startswith(END)), None)
    if end is None:
        raise DataError(f"data: {p}: the file header (line 1) never ends: no {END} line")
    used = lines[0][len(MAGIC) : len(MAGIC) + 1]
    sep, declared = (used if used and not used.isalnum() else None), {}
    for i in range(1, end):
        line = lines[i]
        if line.startswith("Separator") and len(line) > len("Separator"):
            char = line[len("Separator")]
            value = line[len("Separator") + 1 :].strip(char + " \t")
            known = SEPARATORS.get(value.lower(), value if len(value) == 1 else None)
            if known is None:
                raise DataError(
                    f"data: {p} line {i + 1}: Separator {value!r}; allowed: Tab, Comma, Semicolon, Space "
                    "or one character"
                )
            sep = known
        elif line.startswith("Decimal_Separator") and len(line) > len("Decimal_Separator"):
            declared["Decimal_Separator"] = (i + 1, line[len("Decimal_Separator") + 1 :].strip(" \t")[:1])
        elif line.startswith("X_Columns") and len(line) > len("X_Columns"):
            value = line[len("X_Columns") + 1 :].strip(" \t,;")
            declared["X_Columns"] = (i + 1, value)
    sep = sep or "\t"
    n, dec = declared.get("Decimal_Separator", (0, "."))
    if dec not in (".", ",") or dec == sep:
        raise DataError(
            f"data: {p} line {n}: Decimal_Separator {dec!r} with the separator {sep!r}; allowed: '.' or ',' "
            "(not the separator)"
        )
    n, xcols = declared.get("X_Columns", (0, "One"))
    if xcols.lower() not in X_COLUMNS:
        raise DataError(f"data: {p} line {n}: X_Columns {xcols!r}; allowed: No, One, Multi")
    return sep, dec, xcols.lower(), end


def _is_data(line: str, sep: str) -> bool:
    """Whether a (non-blank) line is a row of numbers: its first cell is a number, or empty."""
    head = line[:1]
    if head in _NUMBER_START:
        return True
    first = line.split(sep, 1)[0].strip()
    return not first or first[0] in _NUMBER_START or first.lower() in ("nan", "inf", "infinity")


def _segments(p: Path, lines: list[str], sep: str, end: int) -> list[_Segment]:
    """The segments after the file header (its last line at index `end`)."""
    blank = sep + " \t"
    segments: list[_Segment] = []
    current: _Segment | None = None
    i, n = end + 1, len(lines)
    while i < n:
        line = lines[i]
        if not line.strip(blank):
            i += 1
            continue
        if line.startswith("***Start_Special***"):
            close = next((k for k in range(i + 1, n) if lines[k].startswith("***End_Special***")), None)
            if close is None:
                raise DataError(f"data: {p} line {i + 1}: a ***Start_Special*** block that never ends")
            i = close + 1
            continue
        if _is_data(line, sep):
            if current is None:
                raise DataError(f"data: {p} line {i + 1}: numbers before any column row (X_Value, channel names)")
            j = i + 1
            while j < n and (lines[j][:1] in _NUMBER_START or (lines[j].strip(blank) and _is_data(lines[j], sep))):
                j += 1
            if current.stop > current.start:  # more rows after a blank line: a segment without a header
                current = _Segment(current.tags, current.names, current.comment, current.names_line, i, j)
            else:
                current.start, current.stop = i, j
            segments.append(current)
            following = lines[j].split(sep, 1)[0].strip() if j < n else ""
            if j < n and lines[j].strip(blank) and not lines[j].startswith("***") and following not in SEGMENT_TAGS:
                raise DataError(f"data: {p} line {j + 1}: not a number: {lines[j].strip()[:60]}")
            i = j
            continue
        current, i = _segment_header(p, lines, sep, i)
    if not segments:
        raise DataError(f"data: {p} has no data rows after its headers")
    return segments


def _segment_header(p: Path, lines: list[str], sep: str, i: int) -> tuple[_Segment, int]:
    """The segment whose header starts at index i (without its rows yet), and the index after its column row."""
    start, n, tags = i, len(lines), {}
    while i < n and not lines[i].startswith(END):
        if lines[i].strip(sep + " \t") and _is_data(lines[i], sep):
            raise DataError(
                f"data: {p} line {i + 1}: numbers inside the segment header of line {start + 1} (no {END} before them)"
            )
        cells = lines[i].split(sep)
        tags[cells[0].strip()] = (i + 1, [c.strip() for c in cells[1:]])
        i += 1
    if i == n:
        raise DataError(f"data: {p} line {start + 1}: the segment header never ends: no {END} line")
    i += 1
    while i < n and not lines[i].strip(sep + " \t"):
        i += 1
    if i == n or lines[i].split(sep, 1)[0].strip() != "X_Value":
        shown = "the end of the file" if i == n else repr(lines[i].strip()[:40])
        raise DataError(
            f"data: {p} line {min(i, n - 1) + 1}: the column row (X_Value, channel names) is missing after "
            f"the segment header; found {shown}"
        )
    names = [c.strip() for c in lines[i].split(sep)]
    while names and not names[-1]:
        names.pop()
    comment = names[-1] == "Comment"
    if comment:
        names.pop()
    return _Segment(tags, names, comment, i + 1, i + 1, i + 1), i + 1


def _channels(seg: _Segment) -> list[tuple[int, str]]:
    """(column, name) of each channel of a segment: every column but the X_Value ones."""
    return [(c, name or f"column {c}") for c, name in enumerate(seg.names) if name != "X_Value"]


def _column_of(p: Path, seg: _Segment, first: list[str], index: int) -> int:
    """The column of the chosen channel (`first[index]` of the first segment's channels) in a segment:
    the same index when the segment has the first one's channels, else by its name."""
    channels = _channels(seg)
    names = [name for _, name in channels]
    if names == first:
        return channels[index][0]
    if names.count(first[index]) == 1:
        return channels[names.index(first[index])][0]
    raise DataError(
        f"data: {p} line {seg.names_line}: this segment has {names.count(first[index]) or 'no'} channel "
        f"{first[index]}; its channels: {', '.join(names)}"
    )


def _cell(seg: _Segment, tag: str, col: int) -> tuple[int, str]:
    """(line, text) of the segment header's cell `tag` for data column `col` ('' when absent)."""
    line, cells = seg.tags.get(tag, (0, []))
    k = col - (1 if seg.names and seg.names[0] == "X_Value" else 0)
    return line, cells[k] if 0 <= k < len(cells) else ""


def _header_number(p: Path, seg: _Segment, tag: str, col: int, dec: str) -> float | None:
    line, text = _cell(seg, tag, col)
    if not text:
        return None
    try:
        return float(text.replace(dec, "."))
    except ValueError:
        raise DataError(f"data: {p} line {line}: {tag} {text!r} is not a number") from None


def _block(
    p: Path, lines: list[str], seg: _Segment, sep: str, dec: str, tcol: int | None, col: int
) -> tuple[NDArray[np.float64] | None, NDArray[np.float64]]:
    """The time column (None: there is none) and the channel's values of a segment's rows."""
    import pandas as pd

    block = lines[seg.start : seg.stop]
    need = len(seg.names)
    cells = np.fromiter((line.count(sep) for line in block), dtype=np.int64, count=len(block)) + 1
    ragged = np.flatnonzero(cells < need)
    if not seg.comment:  # more cells than names: only empty ones are allowed
        extra = np.flatnonzero(cells > need)
        extra = extra[[any(c.strip() for c in block[k].split(sep)[need:]) for k in extra]]
        ragged = np.union1d(ragged, extra)
    if ragged.size:
        k = int(ragged[0])
        raise DataError(
            f"data: {p} line {seg.start + k + 1}: {cells[k]} cells; the column row (line {seg.names_line}) "
            f"names {need} ({', '.join(seg.names)})"
        )
    use = [col] if tcol is None else [tcol, col]
    try:
        df = pd.read_csv(
            io.StringIO("\n".join(block)),
            sep=sep,
            header=None,
            names=range(int(cells.max())),
            usecols=use,
            index_col=False,
            decimal=dec,
            dtype=np.float64,
            skipinitialspace=True,
            skip_blank_lines=False,
            quoting=csv.QUOTE_NONE,
            engine="c",
        )
    except (ValueError, pd.errors.ParserError) as exc:
        _find_bad_cell(p, block, seg.start, sep, dec, use)
        raise DataError(
            f"data: {p} lines {seg.start + 1}-{seg.stop}: cannot read: {str(exc).splitlines()[0]}"
        ) from None
    x = df[col].to_numpy(dtype=np.float64)
    if tcol is None:
        return None, x
    t = df[tcol].to_numpy(dtype=np.float64)
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        k = int(bad[0])
        raise DataError(
            f"data: {p} line {seg.start + k + 1}: the X_Value cell (column {tcol + 1}) is empty or not finite"
        )
    return t, x


def _find_bad_cell(p: Path, block: list[str], start: int, sep: str, dec: str, use: list[int]) -> None:
    """Raise the one-line error naming the first cell of columns `use` that is not a number."""
    for k, line in enumerate(block):
        cells = line.split(sep)
        for c in use:
            cell = cells[c].strip()
            if not cell or cell.lower() in ("nan", "-nan", "inf", "-inf", "+inf"):
                continue
            if dec == "," and "." in cell:
                raise DataError(f"data: {p} line {start + k + 1}: {cell!r} has a decimal point; the header says ','")
            try:
                float(cell.replace(dec, "."))
            except ValueError:
                raise DataError(f"data: {p} line {start + k + 1}: not a number: {cell[:40]!r}") from None


def _time(
    p: Path, seg: _Segment, col: int, t: NDArray[np.float64] | None, fs: float | None, dec: str, ref: float
) -> tuple[NDArray[np.float64], dict[str, str]]:
    """A segment's time (s, counted from `ref`) and the notes it calls for, by kind: from its X_Value
    column (on its regular grid when the stamps are one to their printed digits), else X0 + k Delta_X
    (or X0 + k / fs)."""
    dx = _header_number(p, seg, "Delta_X", col, dec)
    dx = dx if dx is not None and np.isfinite(dx) and dx > 0 else None
    notes: dict[str, str] = {}
    m = seg.stop - seg.start
    if t is None:
        x0 = (_header_number(p, seg, "X0", col, dec) or 0.0) - ref
        if fs is None and dx is None:
            raise DataError(
                f"data: {p} line {seg.names_line}: no X_Value column and no Delta_X for this channel: give fs (--fs)"
            )
        if fs is None:
            return x0 + np.arange(m) * dx, notes
        if dx is not None and abs(dx * fs - 1.0) > DELTA_RTOL:
            notes["delta"] = (
                f"time: the lvm header's Delta_X {dx:.7g} s ({1 / dx:g} Hz) disagrees with fs ({fs:g} Hz): fs is used"
            )
            logger.warning(f"{p}: {notes['delta']}")
        return x0 + np.arange(m) / fs, notes
    if fs is not None:
        raise DataError(
            f"data: {p} has a time column (X_Value) and fs was given: the time is ambiguous; drop fs (--fs)"
        )
    grid, step, regular = regular_grid(t, ref)
    if regular:
        if not evenly_spaced(t - ref):
            notes["grid"] = (
                f"time: the X_Value column is written to {float(np.median(_quantum(t))):g} s: read as its "
                f"regular grid, step {step:.7g} s ({1 / step:g} Hz)"
            )
        t = grid
    else:
        t = t - ref
        step = float(np.median(np.diff(t))) if t.size > 1 else float("nan")
    if dx is not None and step > 0 and abs(dx - step) > DELTA_RTOL * step:
        notes["delta"] = (
            f"time: the lvm header's Delta_X {dx:.7g} s ({1 / dx:g} Hz) disagrees with the X_Value column "
            f"({1 / step:g} Hz): the column is used"
        )
        logger.warning(f"{p}: {notes['delta']}")
    return t, notes


def _quantum(t: NDArray[np.float64]) -> NDArray[np.float64]:
    """The unit of the last digit of each stamp as printed, from its value: 1e-6 for 0.000312, 0.1
    for 19.7; a stamp with more digits than float64 holds gets a few of its ulps."""
    a = np.abs(t)
    q = np.full(a.shape, np.nan)
    for d in range(16):
        s = a * 10.0**d
        hit = np.isnan(q) & (np.abs(s - np.rint(s)) <= 8 * np.finfo(np.float64).eps * np.maximum(s, 1.0))
        q[hit] = 10.0**-d
        if not np.isnan(q).any():
            break
    return np.where(np.isnan(q), 8 * np.finfo(np.float64).eps * np.maximum(a, 1.0), q)


def regular_grid(t: NDArray[np.float64], ref: float = 0.0) -> tuple[NDArray[np.float64], float, bool]:
    """The least-squares regular grid of stamps `t` (counted from `ref`), its step, and whether the
    stamps are that grid but for the rounding of their printed digits: each within one unit of its
    last digit (or of the typical last digit)."""
    m = t.size
    if m < 2:
        return t - ref, float("nan"), False
    q = _quantum(t)
    t = t - ref
    k = np.arange(m, dtype=np.float64)
    kc = k - k.mean()
    mean = float(t.mean())
    # numpy's pairwise sums, not BLAS's dot, whose threads change its last bits: the beam record's
    # fit took another order when read under one BLAS thread than under several
    step = float(np.sum(kc * (t - mean)) / np.sum(kc * kc))
    typical = float(np.median(q))
    start = mean - k.mean() * step
    start = typical * round(start / typical)  # X0 as printed: 0 rather than -1e-17
    grid = start + k * step
    tol = np.maximum(q, typical) + 8 * np.finfo(np.float64).eps * (np.abs(t) + abs(ref))
    return grid, step, bool(step > 0 and np.all(np.abs(t - grid) <= tol))
