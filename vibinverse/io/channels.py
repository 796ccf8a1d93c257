"""Several channels measured on one clock: a logger's table of N samples x C channels (accelerometers,
strain gauges, displacement sensors, a hammer's or shaker's force), with each channel's name, units and
optional sensor position, and which channels are measured inputs (known excitation) rather than
responses.

A NaN value is a gap in that channel. Every problem raises `vibinverse.errors.InputError` with one
line naming the field.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from vibinverse.errors import InputError
from vibinverse.io.file_basics import UNITS_NOTE, evenly_spaced
from vibinverse.io.series import Series


@dataclass(frozen=True)
class Channels:
    """`values[k, c]` is channel c at `time[k]` (s, increasing); `names[c]`, `units[c]` (None when
    the file gives none), `positions[c]` = (x, y, z) in metres when a geometry table gave them,
    `inputs` the names of the channels that are measured excitation."""

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
            if p.shape != (v.shape[1], 3) or not np.all(np.isfinite(p)):
                raise InputError(
                    f"positions: need finite (x, y, z) for each of the {v.shape[1]} channel(s); got shape {p.shape}"
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
