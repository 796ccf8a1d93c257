"""Is a fitted line stationary? A shaker's drive that stops mid-record, a tone whose amplitude
steps, is fitted by a stationary line as its average: the fit is then a wrong description with an
interval that looks fine. This check measures each deterministic line's amplitude in segments of
the record and says when it changes, and when.

Per segment s (the record cut into S equal spans of time, each with at least MIN_CYCLES cycles of
the line and MIN_SAMPLES samples): least squares of the data on a constant, a slope and a cosine
and a sine at every fitted line frequency (so that the lines do not leak into each other); the
line's amplitude A_s = |c + i s| and its standard error SE_s = sigma_s sqrt(2 / n_s) (sigma_s the
segment's residual sd; the white-noise value, a floor for coloured noise near the line). The
amplitudes agree with one level when chi2 = sum (A_s - A_w)^2 / SE_s^2 (A_w their
inverse-variance mean) is below the chi-squared(S - 1) quantile at ALPHA. A change is reported
when chi2 fails AND it matters: the best single split of the segments (the least weighted squares
about the two levels) gives levels that differ by at least MATERIAL of the larger. Its time is the
split's segment boundary (resolution: one segment, T / S).

No equation of the paper is used here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

ALPHA = 1e-3
MATERIAL = 0.25  # levels that differ by a quarter of the larger
MAX_SEGMENTS = 16
MIN_CYCLES = 10.0  # cycles of the line in a segment
MIN_SAMPLES = 40


def segment_count(span: float, n: int, frequencies: list[float]) -> int:
    """Segments of the record: as many as MAX_SEGMENTS with MIN_CYCLES of the slowest line and
    MIN_SAMPLES samples each; 0 when fewer than 2."""
    if not frequencies or span <= 0:
        return 0
    s = min(MAX_SEGMENTS, int(span * min(frequencies) // MIN_CYCLES), n // MIN_SAMPLES)
    return s if s >= 2 else 0


def segment_amplitudes(
    time: np.ndarray, y: np.ndarray, frequencies: list[float], segments: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(amplitudes (segments, lines), standard errors (segments, lines), segment edges in s) of the
    lines at `frequencies` (Hz) in `segments` equal spans of the record; NaN samples skipped."""
    t = np.asarray(time, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    edges = np.linspace(t[0], t[-1], segments + 1)
    edges[-1] = np.nextafter(edges[-1], np.inf)
    f = np.asarray(frequencies, dtype=np.float64)
    amp = np.full((segments, f.size), np.nan)
    se = np.full((segments, f.size), np.nan)
    for s in range(segments):
        inside = (t >= edges[s]) & (t < edges[s + 1]) & np.isfinite(y)
        ts, ys = t[inside], y[inside]
        k = 2 + 2 * f.size
        if ts.size <= k + 2:
            continue
        phase = 2 * np.pi * np.outer(ts, f)
        x = np.column_stack([np.ones_like(ts), ts - ts.mean(), np.cos(phase), np.sin(phase)])
        coef, *_ = np.linalg.lstsq(x, ys, rcond=None)
        resid = ys - x @ coef
        sigma = math.sqrt(float(resid @ resid) / (ts.size - k))
        c, q = coef[2 : 2 + f.size], coef[2 + f.size :]
        amp[s] = np.hypot(c, q)
        se[s] = sigma * math.sqrt(2.0 / ts.size)
    return amp, se, edges


def _split(a: np.ndarray, w: np.ndarray) -> tuple[int, float, float]:
    """(k, level before, level after) of the best split of amplitudes a (weights w) at 1 <= k < S."""
    best = (1, float(a[0]), float(a[0]), math.inf)
    for k in range(1, a.size):
        lo = float(np.average(a[:k], weights=w[:k]))
        hi = float(np.average(a[k:], weights=w[k:]))
        sse = float(np.sum(w[:k] * (a[:k] - lo) ** 2) + np.sum(w[k:] * (a[k:] - hi) ** 2))
        if sse < best[3]:
            best = (k, lo, hi, sse)
    return best[0], best[1], best[2]


def line_stationarity(time: np.ndarray, y: np.ndarray, lines: dict[str, float]) -> dict[str, Any]:
    """Per line (label -> fitted frequency in Hz): {"segments", "amplitudes", "chi2", "p",
    "stationary", and when not: "change_time_s", "before", "after"}; {} when the record is too
    short for two segments (module docstring)."""
    labels = [k for k, v in lines.items() if math.isfinite(v) and v > 0]
    freqs = [float(lines[k]) for k in labels]
    t = np.asarray(time, dtype=np.float64)
    n = segment_count(float(t[-1] - t[0]) if t.size > 1 else 0.0, int(np.isfinite(y).sum()), freqs)
    if not n:
        return {}
    amp, se, edges = segment_amplitudes(t, y, freqs, n)
    out: dict[str, Any] = {}
    for j, label in enumerate(labels):
        ok = np.isfinite(amp[:, j]) & (se[:, j] > 0)
        a, e = amp[ok, j], se[ok, j]
        if a.size < 2:
            continue
        w = 1.0 / e**2
        mean = float(np.average(a, weights=w))
        chi2 = float(np.sum(w * (a - mean) ** 2))
        p = float(stats.chi2.sf(chi2, a.size - 1))
        k, before, after = _split(a, w)
        material = abs(after - before) >= MATERIAL * max(abs(before), abs(after))
        entry: dict[str, Any] = {
            "frequency_hz": freqs[j],
            "segments": int(a.size),
            "amplitudes": [float(v) for v in a],
            "chi2": chi2,
            "p": p,
            "stationary": not (p < ALPHA and material),
        }
        if not entry["stationary"]:
            starts = edges[:-1][ok]
            entry.update({"change_time_s": float(starts[k] - t[0]), "before": before, "after": after})
        out[label] = entry
    return out


def describe_change(label: str, entry: dict[str, Any]) -> str:
    """One sentence on a non-stationary line."""
    before, after = entry["before"], entry["after"]
    what = "stops" if after < MATERIAL * before else ("starts" if before < MATERIAL * after else "changes amplitude")
    return (
        f"{label.replace('_', ' ')} at {entry['frequency_hz']:.6g} Hz {what} at t = {entry['change_time_s']:.3g} s "
        f"(amplitude {before:.3g} before, {after:.3g} after; p = {entry['p']:.2g}): the fit's stationary line "
        "is an average"
    )
