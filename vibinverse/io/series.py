"""Measured series: read CSV / .npy / .npz / netCDF, validate, and report gaps.

A NaN intensity is a gap (a missing sample): kept, counted and handled by the likelihoods. Every
problem raises `vibinverse.errors.DataError` with one line naming it.
"""

from __future__ import annotations

import copy
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import DataError, InputError


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
        d = np.diff(self.time)
        return bool(np.all(np.abs(d - d[0]) <= 1e-9 * d[0]))

    @property
    def fs(self) -> float:
        return 1.0 / self.dt

    def describe(self) -> str:
        kind = f"uniform at {self.fs:g} Hz" if self.uniform else f"non-uniform (median step {self.dt:g} s)"
        return (
            f"{self.time.size} samples over {self.time[-1] - self.time[0]:g} s, {kind}; "
            f"{self.n_gaps} gaps ({self.n_gaps / self.time.size:.1%})"
        )


def load_series(path: str | Path) -> Series:
    """Read and validate a series. Formats: CSV with columns time,intensity (more columns are
    ignored; '#' comment lines allowed, '# scene: {json}' carries the truth), .npy (N x 2),
    .npz (arrays 'time' and 'intensity'), netCDF (.nc; variables 'time' and 'intensity')."""
    p = Path(path)
    if not p.is_file():
        raise DataError(f"data: file not found: {p}")
    suffix = p.suffix.lower()
    scene = None
    try:
        if suffix == ".npy":
            arr = np.load(p, allow_pickle=False)
            if arr.ndim != 2 or arr.shape[1] < 2:
                raise DataError(f"data: {p} must hold an N x 2 array (time, intensity), got shape {arr.shape}")
            t, x = arr[:, 0], arr[:, 1]
        elif suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                if "time" not in z or "intensity" not in z:
                    raise DataError(f"data: {p} needs arrays 'time' and 'intensity', has {sorted(z.files)}")
                t, x = z["time"], z["intensity"]
        elif suffix in (".nc", ".netcdf", ".cdf"):
            import xarray as xr

            with xr.open_dataset(p) as ds:
                if "intensity" not in ds:
                    raise DataError(f"data: {p} has no variable 'intensity'")
                x = ds["intensity"].values
                t = ds["time"].values if "time" in ds.variables else ds["intensity"][ds["intensity"].dims[0]].values
        else:
            t, x, scene = _read_csv(p)
    except DataError:
        raise
    except (OSError, ValueError) as exc:
        raise DataError(f"data: cannot read {p}: {str(exc).splitlines()[0]}") from None
    return validate(np.asarray(t, dtype=float), np.asarray(x, dtype=float), str(p), scene)


def _read_csv(p: Path) -> tuple[np.ndarray, np.ndarray, dict | None]:
    scene, header, rows = None, None, []
    with open(p, encoding="utf-8") as fh:
        for n, line in enumerate(fh, 1):
            s = line.strip()
            if not s:
                continue
            if s.startswith("#"):
                if s.startswith("# scene:"):
                    try:
                        scene = json.loads(s[len("# scene:") :])
                    except json.JSONDecodeError:
                        scene = None
                continue
            cells = [c.strip() for c in s.split(",")]
            if header is None:
                header = cells
                if "time" not in header or "intensity" not in header:
                    raise DataError(f"data: {p} header must name columns time and intensity, got {','.join(header)}")
                continue
            try:
                rows.append((float(cells[header.index("time")]), float(cells[header.index("intensity")] or "nan")))
            except (ValueError, IndexError):
                raise DataError(f"data: {p} line {n}: not a number: {s[:60]}") from None
    if header is None:
        raise DataError(f"data: {p} has no header row time,intensity")
    arr = np.array(rows, dtype=float).reshape(-1, 2)
    return arr[:, 0], arr[:, 1], scene


def validate(t: np.ndarray, x: np.ndarray, source: str = "array", scene: dict | None = None) -> Series:
    """Check a series; NaN intensities are gaps, anything else non-finite is an error."""
    if t.ndim != 1 or x.ndim != 1 or t.size != x.size:
        raise DataError(f"data: time and intensity must be 1-D of equal length, got {t.shape} and {x.shape}")
    if t.size < 16:
        raise DataError(f"data: {t.size} samples; at least 16 are needed")
    if not np.all(np.isfinite(t)):
        raise DataError("data: time has non-finite values")
    if not np.all(np.diff(t) > 0):
        k = int(np.argmin(np.diff(t) > 0))
        raise DataError(f"data: time must be strictly increasing (sample {k + 1}: {t[k + 1]:g} after {t[k]:g})")
    if np.any(np.isinf(x)):
        raise DataError("data: intensity has infinite values (use NaN for missing samples)")
    if np.isfinite(x).sum() < 16:
        raise DataError(f"data: only {int(np.isfinite(x).sum())} valid samples; at least 16 are needed")
    return Series(t, x, source, scene)


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
