"""Peaks of a spectrum and the bands around them: the first stage of both modal identifications
(`vibinverse.oma.identify` on the singular values of the responses' spectral matrix,
`vibinverse.oma.input_output` on the magnitude of the frequency response)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from vibinverse.oma.spectral_matrix import SingularValues

PROMINENCE = 1.0  # ln units: a peak e times its surroundings (`local_baseline`)
BASELINE_WIDTH = 0.25  # the surroundings: +-25 % in frequency
BASELINE_GRID = 2000
SMOOTH_WIDTH = 0.005  # the singular value's moving average (+-, relative) before its peaks are read
BASELINE_BINS = 15  # the surroundings span at least +-this many frequencies (short records)
LOCAL_PROMINENCE = 0.3  # ln units above the higher of its neighbourhood's valleys
LOCAL_WIDTH = 0.05  # the neighbourhood: +-5 % in frequency
#: the least damping ratio a peak's fit starts from: from a spike-narrow start the optimizer stays on
#: a periodogram spike beside the mode; from a broad one it narrows onto the mode
START_ZETA = 0.01
MAX_BANDS = 12
MIN_CYCLES = 10.0
BAND_WIDTHS = 6.0
MAX_BAND_ZETA = 0.05  # a band is never wider than +-BAND_WIDTHS x this, relative
#: nor narrower than +-BAND_WIDTHS x this: a fit that went to a spike beside the mode must still see it
MIN_BAND_ZETA = 0.002
MIN_ORDINATES = 16
MAX_MODES_PER_BAND = 6  # a band may hold several close modes (an 8-storey building's top four merge into one)


@dataclass
class Peak:
    """A spectral peak: its frequency (Hz), a damping ratio read from its width, and its height
    above its surroundings (natural log)."""

    f: float
    zeta: float
    prominence: float


def local_baseline(freqs: np.ndarray, log_s: np.ndarray) -> np.ndarray:
    """The running median of log_s over +-BASELINE_WIDTH (relative) in frequency, or +-BASELINE_BINS
    where that is wider, at every frequency (evaluated at up to BASELINE_GRID frequencies and
    interpolated): a peak's height above it does not grow with the record's length, as a prominence
    over the deepest valley of thousands of noisy bins does."""
    n = freqs.size
    df = freqs[1] - freqs[0] if n > 1 else 1.0
    at = np.unique(np.geomspace(1, n, min(n, BASELINE_GRID)).astype(int) - 1)
    half = np.maximum(BASELINE_BINS, (BASELINE_WIDTH * freqs[at] / df).astype(int))
    base = np.array([np.median(log_s[max(0, i - h) : i + h + 1]) for i, h in zip(at, half, strict=True)])
    return np.interp(np.arange(n), at, base)


def relative_smooth(freqs: np.ndarray, values: np.ndarray) -> np.ndarray:
    """values averaged over +-SMOOTH_WIDTH (relative) of each frequency (at least the bin itself):
    the ragged top of a long record's Welch peak evened, a short record's few bins left alone."""
    df = freqs[1] - freqs[0] if freqs.size > 1 else 1.0
    half = (SMOOTH_WIDTH * freqs / df).astype(int)
    c = np.r_[0.0, np.cumsum(values)]
    i = np.arange(freqs.size)
    lo, hi = np.maximum(i - half, 0), np.minimum(i + half + 1, freqs.size)
    return (c[hi] - c[lo]) / (hi - lo)


def pick_peaks(sv: SingularValues, span: float, count: int | None, prominence: float = PROMINENCE) -> list[Peak]:
    """The first singular value's peaks (module docstring, stage 1), strongest first."""
    # Welch's 15 segments leave a long record's peak top ragged, and a width read on a noise spike
    # sets a band too narrow for the mode under it: averaged over +-SMOOTH_WIDTH first
    smooth = relative_smooth(sv.freqs, sv.values[:, 0])
    s1 = np.log(np.maximum(smooth, 1e-300))
    df = sv.freqs[1] - sv.freqs[0]
    lo = MIN_CYCLES / span
    # a peak stands above its surroundings' median (a mode's hump) and above its own neighbourhood
    # (its flanks' and top's ripples do not)
    idx, _ = signal.find_peaks(s1)
    prom_all = s1 - local_baseline(sv.freqs, s1)
    keep = (sv.freqs[idx] >= max(lo, 2 * df)) & (prom_all[idx] >= (prominence if count is None else 0.05))
    idx = idx[keep]
    if count is None:  # within +-LOCAL_WIDTH (relative, >= BASELINE_BINS): a hump's top, not its ripples
        local = np.array(
            [
                signal.peak_prominences(s1, [i], wlen=2 * max(BASELINE_BINS, int(LOCAL_WIDTH * sv.freqs[i] / df)) + 1)[
                    0
                ][0]
                for i in idx
            ]
        )
        idx = idx[local >= LOCAL_PROMINENCE] if idx.size else idx
    prom = prom_all[idx]
    order = np.argsort(prom)[::-1]
    wanted = count if count is not None else MAX_BANDS
    peaks: list[Peak] = []
    spans: list[tuple[float, float]] = []
    for i, p in zip(idx[order], prom[order], strict=True):
        if any(a <= sv.freqs[i] <= b for a, b in spans):
            continue  # a ripple on a stronger peak's top: the order search finds a second mode there
        half = s1[i] - math.log(2.0)
        a, b = i, i
        while a > 0 and s1[a] > half:
            a -= 1
        while b < s1.size - 1 and s1[b] > half:
            b += 1
        spans.append((float(sv.freqs[a]), float(sv.freqs[b])))
        smear = df + SMOOTH_WIDTH * sv.freqs[i]  # the Hann window's and the smoothing's own widths
        width = max((sv.freqs[b] - sv.freqs[a]) / 2.0 - smear, df / 2.0)
        zeta = float(np.clip(width / sv.freqs[i], START_ZETA, 0.2))
        peaks.append(Peak(float(sv.freqs[i]), zeta, float(p)))
        if len(peaks) == wanted:
            break
    return peaks


def band_of(p: Peak, resolution: float) -> tuple[float, float]:
    """The band a peak's modes are fitted in: +-BAND_WIDTHS half-power half-widths, >= MIN_ORDINATES."""
    zeta = min(max(p.zeta, MIN_BAND_ZETA), MAX_BAND_ZETA)
    half = max(BAND_WIDTHS * zeta * p.f, MIN_ORDINATES / 2 * resolution)
    return max(p.f - half, resolution / 2), p.f + half


def group_bands(peaks: list[Peak], resolution: float, nyquist: float) -> list[tuple[float, float, list[Peak]]]:
    """Bands around the peaks, overlapping ones merged (module docstring, stage 2)."""
    spans = sorted(((*band_of(p, resolution), p) for p in peaks), key=lambda t: t[0])
    out: list[tuple[float, float, list[Peak]]] = []
    for lo, hi, p in spans:
        hi = min(hi, nyquist)
        if out and lo <= out[-1][1]:
            out[-1] = (out[-1][0], max(out[-1][1], hi), out[-1][2] + [p])
        else:
            out.append((lo, hi, [p]))
    return out
