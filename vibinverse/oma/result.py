"""What a multi-channel modal identification returns: modes with frequencies, damping ratios and unit
shapes (each with its 90 % interval and standard deviation), the MAC matrix, each band's fits over
model order (the stabilization-style view) and the singular-value spectrum behind them."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from vibinverse.detection import BROAD_DAMPING

#: the central probability of every interval reported
INTERVAL = 0.90


def mac(a: np.ndarray, b: np.ndarray) -> float:
    """Modal assurance criterion |a . b|^2 / (|a|^2 |b|^2) of two real or complex shapes."""
    a, b = np.asarray(a), np.asarray(b)
    den = float(np.vdot(a, a).real * np.vdot(b, b).real)
    return float(abs(np.vdot(a, b)) ** 2 / den) if den > 0 else 0.0


def mac_matrix(shapes: list[np.ndarray], others: list[np.ndarray] | None = None) -> np.ndarray:
    """MAC of every pair (shapes x others; others default: shapes)."""
    others = shapes if others is None else others
    return np.array([[mac(a, b) for b in others] for a in shapes]).reshape(len(shapes), len(others))


def signed_unit(v: np.ndarray) -> np.ndarray:
    """v / |v|, signed so that its largest-magnitude component is positive (the sign convention of
    every reported shape)."""
    v = np.asarray(v, dtype=float)
    u = v / np.linalg.norm(v)
    return u if u[int(np.argmax(np.abs(u)))] >= 0 else -u


def _number(v: float) -> float | None:
    """A finite float, or None (JSON null) for NaN: a value that was not computed."""
    return float(v) if math.isfinite(v) else None


def interval_text(lo: float, hi: float, fmt: str) -> str:
    """'[lo, hi]' in `fmt`, or 'no interval' where it was not computed (NaN)."""
    return f"[{lo:{fmt}}, {hi:{fmt}}]" if math.isfinite(lo) and math.isfinite(hi) else "no interval"


@dataclass
class OmaMode:
    """One identified mode: MAP values, 90 % intervals and standard deviations of the frequency
    (Hz), damping ratio and unit shape over the response channels (largest component positive)."""

    frequency: float
    damping_ratio: float
    shape: np.ndarray
    frequency_interval: tuple[float, float]
    damping_ratio_interval: tuple[float, float]
    shape_interval: np.ndarray  # (channels, 2)
    frequency_sd: float
    damping_ratio_sd: float
    shape_sd: np.ndarray
    band: tuple[float, float]
    level: float  # the modal response's peak spectral density on the unit shape (units^2 / Hz, one-sided)
    warnings: list[str] = field(default_factory=list)

    @property
    def claimed(self) -> bool:
        """False for a broad hump (damping ratio above `vibinverse.detection.BROAD_DAMPING`): kept in
        the table, not claimed as a resonance."""
        return bool(self.damping_ratio <= BROAD_DAMPING)

    @property
    def has_interval(self) -> bool:
        """False where the posterior was not locally Gaussian: no interval is claimed (NaN)."""
        return bool(np.all(np.isfinite(self.frequency_interval)))

    def without_interval(self) -> OmaMode:
        """This mode with its intervals and sds NaN: what the data gave no interval for."""
        nan = (math.nan, math.nan)
        return replace(
            self,
            frequency_interval=nan,
            damping_ratio_interval=nan,
            shape_interval=np.full_like(self.shape_interval, math.nan),
            frequency_sd=math.nan,
            damping_ratio_sd=math.nan,
            shape_sd=np.full_like(self.shape_sd, math.nan),
        )

    def to_json(self, names: tuple[str, ...]) -> dict[str, Any]:
        """JSON-able; an interval or sd that was not computed is null."""
        return {
            "frequency": self.frequency,
            "frequency_interval": [_number(v) for v in self.frequency_interval],
            "frequency_sd": _number(self.frequency_sd),
            "damping_ratio": self.damping_ratio,
            "damping_ratio_interval": [_number(v) for v in self.damping_ratio_interval],
            "damping_ratio_sd": _number(self.damping_ratio_sd),
            "shape": {n: float(v) for n, v in zip(names, self.shape, strict=True)},
            "shape_interval": {
                n: [_number(a), _number(b)] for n, (a, b) in zip(names, self.shape_interval, strict=True)
            },
            "shape_sd": {n: _number(v) for n, v in zip(names, self.shape_sd, strict=True)},
            "band": list(self.band),
            "peak_density": self.level,
            "warnings": list(self.warnings),
            "claimed": self.claimed,
        }


def mode_from_draws(
    f: float,
    zeta: float,
    shape: np.ndarray,
    draws: tuple[np.ndarray, np.ndarray, np.ndarray],
    band: tuple[float, float],
    level: float,
    warnings: list[str],
    gaussian: bool,
) -> OmaMode:
    """A mode from its MAP values and posterior draws (f, zeta, unit shapes (draws, channels)):
    central INTERVAL quantiles and sds; without an interval (NaN) when the posterior was not
    locally Gaussian (`gaussian` False)."""
    fd, zd, ud = draws
    lo_q, hi_q = (1 - INTERVAL) / 2, 1 - (1 - INTERVAL) / 2
    mode = OmaMode(
        frequency=float(f),
        damping_ratio=float(zeta),
        shape=shape,
        frequency_interval=(float(np.quantile(fd, lo_q)), float(np.quantile(fd, hi_q))),
        damping_ratio_interval=(float(np.quantile(zd, lo_q)), float(np.quantile(zd, hi_q))),
        shape_interval=np.quantile(ud, [lo_q, hi_q], axis=0).T,
        frequency_sd=float(np.std(fd)),
        damping_ratio_sd=float(np.std(zd)),
        shape_sd=np.std(ud, axis=0),
        band=(float(band[0]), float(band[1])),
        level=float(level),
        warnings=list(warnings),
    )
    return mode if gaussian else mode.without_interval()


@dataclass
class BandFit:
    """One band's fits over model order: for each mode count, (BIC, ln L, frequencies, damping
    ratios); `chosen` is the order kept."""

    lo: float
    hi: float
    ordinates: int
    orders: dict[int, dict[str, Any]]
    chosen: int

    def to_json(self) -> dict[str, Any]:
        return {
            "band": [self.lo, self.hi],
            "ordinates": self.ordinates,
            "chosen": self.chosen,
            "orders": {str(k): v for k, v in self.orders.items()},
        }


@dataclass
class OmaResult:
    """The identification of a multi-channel record (`vibinverse.oma.identify.identify`)."""

    modes: list[OmaMode]
    names: tuple[str, ...]
    units: tuple[str | None, ...]
    quantity: str
    bands: list[BandFit]
    sv_freqs: np.ndarray
    sv_values: np.ndarray
    samples: int
    fs: float
    seconds: float
    search: tuple[float, float] = (0.0, float("inf"))  # the band (Hz) searched for modes
    notes: list[str] = field(default_factory=list)
    method: str = "bayesian-fft (multi-channel Whittle in bands) + Laplace"
    #: what `sv_values` is: the curves the stabilization diagram is drawn on
    spectrum: str = "singular value (unit-variance channels)"

    @property
    def mac(self) -> np.ndarray:
        """MAC between the identified modes."""
        return mac_matrix([m.shape for m in self.modes])

    def to_json(self) -> dict[str, Any]:
        return {
            "method": self.method,
            "interval": INTERVAL,
            "channels": list(self.names),
            "units": list(self.units),
            "quantity": self.quantity,
            "samples": self.samples,
            "fs": self.fs,
            "seconds": self.seconds,
            "search_band": list(self.search),
            "modes": [m.to_json(self.names) for m in self.modes],
            "mac": self.mac.tolist(),
            "bands": [b.to_json() for b in self.bands],
            "notes": list(self.notes),
        }

    def table(self) -> str:
        """The mode table as text: f and zeta with 90 % intervals, the shape per channel."""
        p = int(100 * INTERVAL)
        lines = [
            f"{len(self.modes)} mode(s) from {len(self.names)} channel(s) ({', '.join(self.names)}); {p} % intervals"
        ]
        for i, m in enumerate(self.modes):
            shape = "  ".join(
                f"{n}={v:+.3f}" + (f"[{a:+.3f},{b:+.3f}]" if math.isfinite(a) else " (no interval)")
                for n, v, (a, b) in zip(self.names, m.shape, m.shape_interval, strict=True)
            )
            lines.append(
                f"mode {i + 1}: f = {m.frequency:.5g} Hz {interval_text(*m.frequency_interval, '.5g')}  "
                f"zeta = {m.damping_ratio:.4f} {interval_text(*m.damping_ratio_interval, '.4f')}  shape: {shape}"
            )
            lines += [f"  warning: {w}" for w in m.warnings]
        lines += [f"note: {n}" for n in self.notes]
        return "\n".join(lines)
