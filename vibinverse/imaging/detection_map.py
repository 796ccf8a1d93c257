"""Which pixels of an image cube (time, y, x) carry a vibration: a per-pixel whitened periodogram,
its strongest peak and the peak's false-alarm probability, the lines seen anywhere in the frame,
and the clusters of pixels that carry them. Run chunk by chunk on Dask (`scheduler`).

Per pixel (float64, a batch of pixels at a time):

1. The mean and a least-squares linear trend are removed.
2. Periodogram on the Fourier frequencies f_k = k / T (T = N dt, the record length; k = 1 .. below
   Nyquist): uniform stamps (within 2 % of a step of a uniform grid) by an rfft (scipy.fft),
   |sum y e^{-2 pi i f t}|^2 / N; irregular stamps (jitter, dropped frames) by the floating-mean
   Lomb-Scargle periodogram of nifty-ls ("psd" normalization: the same quantity on a uniform grid),
   T = span + the median step, up to half the median sample rate. On these frequencies the powers
   of white noise are independent and exponential.
3. Whitening by a robust local noise floor, whatever the noise colour (drift, 1/f, AR(1),
   quantization): first a smooth baseline, a cubic in ln f fitted to ln P (it takes out power laws
   and knees, which a median over a window of linear frequency would smear), then the median of
   P / baseline over windows of w = 2h + 1 bins (h = 64) that tile the frequencies, each bin taking
   its own window's. The floor is baseline * median / c, with c the mean of the (h+1)-th smallest
   of w Exp(1) values, c = H_w - H_h (H_n the harmonic numbers; ln 2 as w grows: the median of an
   exponential is ln 2 times its mean). The whitened power z = P / floor is ~ Exp(1) on noise
   (mean 1 + O(1/h)), and a line's z is its power in units of the floor (its SNR).
4. Its tail is exact for white noise: when P exceeds the window's median, that median is the
   (h+1)-th smallest of the other 2h powers, and for exponential powers (ordered-statistic CFAR,
   Rohling 1983)

       P(z > s) = prod_{i=0}^{h} (2h - i) / (2h - i + s / c),

   which tends to e^{-s} as h grows (with h = 64 it is heavier: ~30x e^{-s} at s = 24, the price
   of estimating the floor from 128 neighbours). `log_tail` computes it.
5. The peak of z in the band: its frequency (refined by a parabola through ln P at the three bins
   around it), its SNR, and its false-alarm probability corrected for the M frequencies searched
   (`pixel_false_alarm_probability`) and for the M frequencies AND the P pixels
   (`false_alarm_probability`): for independent tests of tail p, P(max > z) = 1 - (1 - p)^{M P},
   computed as -expm1(M P log1p(-p)).

Lines: per Fourier frequency, the largest z over all pixels; frequencies whose corrected
false-alarm probability 1 - (1 - p)^{M P} is below `alpha` are lines, merged when at most
`MERGE_GAP` = 2 bins apart (a strong line's sidelobes, a damped resonance's hump, which dips below
the threshold between its bins; so lines closer than 4 / T are one), the strongest `max_lines`
kept. A second pass takes every pixel's z within one bin of each line (the SNR map).
A pixel carries a line when its p-value there (corrected for the <= 3 bins) passes the
Benjamini-Hochberg procedure over all pixels at level `alpha` (expected fraction of false pixels
<= alpha). Clusters are the connected components (8-neighbours, scipy.ndimage.label) of the
pixels that carry any line, numbered 1, 2, ... by decreasing peak SNR; `cluster` (y, x) holds the
number (0: none), `line_of_cluster` the cluster's strongest line, `cluster_lines` every line it
carries (a roof's pixels carry its tilt resonance and its drive together).

Not searched: the first `LOW_BINS` Fourier frequencies (periods longer than a quarter of the
record), where drifts and their leakage live. A rolling shutter's per-row time offset
(coord "row_offset") shifts a row's stamps by a constant: it changes each periodogram's phase,
never its power, and is ignored here.

Chunks: the time axis whole, the frame cut into spatial blocks so that the blocks in flight and
their float64 work fit `memory` bytes (`plan_chunks`). A cube whose time axis is split in chunks
(video frames, netCDF read by frames) is read block by block (each block's reads are its own tasks,
so only its pixels are held), never rechunked whole; a cube that fits in a quarter of `memory` is
read once and kept for the second pass.

No equation of the paper is used here (the paper stops at the sensitivity, eq. 21; sec. 5 asks for
combining pixels, which this map prepares).
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import logging
import math
import numbers
import time
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr
from threadpoolctl import threadpool_limits

from vibinverse.errors import DataError, InputError
from vibinverse.imaging.scheduler import session

logger = logging.getLogger(__name__)

DEFAULT_MEMORY = 512 * 2**20  # bytes: the chunks in flight and their float64 work, all threads together
# float64 work per pixel and time sample in a batch (series, spectra, floor), measured with tracemalloc:
# 29 bytes with the rfft, 85 with nifty-ls (its oversampled NUFFT grid)
WORK_BYTES_PER_SAMPLE = {True: 32, False: 96}  # keyed by uniform stamps
FLOOR_HALF_WIDTH = 64  # h: the running median's window is 2h + 1 = 129 Fourier bins
MIN_HALF_WIDTH = 8  # fewer Fourier frequencies than 2 * 8 + 1 (35 frames): too short a record
BASELINE_DEGREE = 3  # the smooth baseline: a cubic in ln f fitted to ln P
BASELINE_DENSE, BASELINE_STRIDE = 256, 4  # ... at the first 256 frequencies and every 4th after
LOW_BINS = 4  # the first Fourier frequencies, never searched (drift)
LINE_BINS = 1  # a pixel's SNR at a line: its largest z within this many bins of the line's bin
MERGE_GAP = 2  # line frequencies at most 2 bins apart are one line (a damped resonance's hump dips between)
# stamps within this fraction of a step from a uniform grid (a container's rounded stamps: 30 fps in
# milliseconds is 1.5 %) take the rfft: its phase error, at most 2 pi 0.02 f / fs <= 0.063 rad, loses
# < 0.4 % of a line's power
UNIFORM_TOLERANCE = 0.02
MIN_CHUNK_PIXELS = 64  # smaller blocks cost more in scheduling than they save
BATCH_BYTES = 2**20  # float64 series per batch: ~1 MiB stays in a core's cache (2x faster than 8 MiB)


# ----------------------------------------------------------------------------------- the frequencies
@dataclasses.dataclass(frozen=True)
class FrequencyGrid:
    """The Fourier frequencies f = (i + 1) df, i = 0 .. n_freq - 1, of a record with stamps `time`;
    the band searched is i in [lo, hi)."""

    time: np.ndarray
    uniform: bool
    dt: float  # median step, s
    df: float  # 1 / T, Hz
    n_freq: int
    lo: int
    hi: int
    half_width: int  # h of the floor's window

    @property
    def frequencies(self) -> np.ndarray:
        return (np.arange(self.n_freq) + 1.0) * self.df

    @property
    def n_searched(self) -> int:
        """M: the Fourier frequencies in the band (independent for white noise)."""
        return self.hi - self.lo

    @property
    def nyquist(self) -> float:
        return 0.5 / self.dt

    @functools.cached_property
    def windows(self) -> tuple[np.ndarray, np.ndarray]:
        """(first bin of each floor window, the window each bin takes: the nearest centre, which
        contains it). The windows tile the frequencies (the last one ends at the last frequency)."""
        w = 2 * self.half_width + 1
        starts = np.unique(np.r_[np.arange(0, self.n_freq - w + 1, w), self.n_freq - w])
        centres = starts + self.half_width
        j = np.arange(self.n_freq)
        right = np.minimum(np.searchsorted(centres, j), centres.size - 1)  # centres[right - 1] < j <= centres[right]
        left = np.maximum(right - 1, 0)
        nearest = np.where(np.abs(centres[left] - j) <= np.abs(centres[right] - j), left, right)
        return starts, nearest

    @functools.cached_property
    def baseline_basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(A, bins, pinv(A[bins])): the cubic in standardized ln f of the baseline at every
        frequency, the frequencies it is fitted on (all the low ones, whose few bins fix the shape
        at low f on the ln f axis, then every BASELINE_STRIDE-th), and the fit's least-squares inverse."""
        x = np.log(np.arange(1, self.n_freq + 1, dtype=np.float64))
        x = (x - x.mean()) / (x.std() or 1.0)
        a = np.vander(x, BASELINE_DEGREE + 1)
        bins = np.r_[
            np.arange(min(BASELINE_DENSE, self.n_freq)), np.arange(BASELINE_DENSE, self.n_freq, BASELINE_STRIDE)
        ]
        return a, bins, np.linalg.pinv(a[bins])

    @functools.cached_property
    def ramp_spectrum(self) -> np.ndarray:
        """rfft of the centred time ramp at the grid's frequencies (uniform stamps): what a unit
        slope adds to each Fourier coefficient, so that the trend is removed from the spectrum."""
        tc = self.time - self.time.mean()
        return np.fft.rfft(tc)[1 : self.n_freq + 1]


def frequency_grid(time: np.ndarray, band: tuple[float, float] | None = None) -> FrequencyGrid:
    """The Fourier frequencies of stamps `time` (s) and the band searched (Hz, default: from the
    (LOW_BINS+1)-th Fourier frequency up to Nyquist). One-line DataError/InputError naming the field."""
    t = np.asarray(time, dtype=np.float64)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise DataError("time: stamps must be a finite 1-D coordinate, in seconds")
    steps = np.diff(t)
    if t.size < 2 or np.any(steps <= 0):
        first = int(np.flatnonzero(steps <= 0)[0]) + 1 if t.size >= 2 else 0
        raise DataError(f"time: stamps must increase strictly (index {first} does not)")
    mean_step = float(t[-1] - t[0]) / (t.size - 1)
    uniform = bool(np.max(np.abs(t - t[0] - mean_step * np.arange(t.size))) <= UNIFORM_TOLERANCE * mean_step)
    dt = mean_step if uniform else float(np.median(steps))
    span = t.size * dt if uniform else float(t[-1] - t[0]) + dt
    n_freq = (t.size - 1) // 2 if uniform else math.floor(0.5 * span / dt + 1e-9) - 1
    half = min(FLOOR_HALF_WIDTH, (n_freq - 1) // 2)
    if half < MIN_HALF_WIDTH:  # (then n_freq >= 2 * MIN_HALF_WIDTH + 1 > LOW_BINS too)
        need = 2 * (2 * MIN_HALF_WIDTH + 1) + 1
        raise DataError(f"time: {t.size} frames are too few for a detection map (at least {need})")
    df = 1.0 / span
    lo, hi = LOW_BINS, n_freq
    if band is not None:
        fmin, fmax = (float(band[0]), float(band[1]))
        fmax = 0.5 / dt if fmax == math.inf else fmax  # "5:" on the command line: up to Nyquist
        allowed = f"0 <= fmin < fmax <= {0.5 / dt:.6g} Hz (Nyquist)"
        if not (math.isfinite(fmin) and math.isfinite(fmax) and 0 <= fmin < fmax):
            raise InputError(f"--band: {fmin:g}:{fmax:g} is not a band; allowed {allowed}")
        if fmax > 0.5 / dt * (1 + 1e-9):
            raise InputError(f"--band: fmax {fmax:g} Hz is above Nyquist; allowed {allowed}")
        f = (np.arange(n_freq) + 1.0) * df
        inside = np.flatnonzero((f >= fmin) & (f <= fmax) & (np.arange(n_freq) >= LOW_BINS))
        if inside.size == 0:
            raise InputError(
                f"--band: no searched frequency in {fmin:g}:{fmax:g} Hz; the searched frequencies are "
                f"{(LOW_BINS + 1) * df:.6g} to {n_freq * df:.6g} Hz in steps of {df:.6g} Hz"
            )
        lo, hi = int(inside[0]), int(inside[-1]) + 1
    return FrequencyGrid(t, uniform, dt, df, n_freq, lo, hi, half)


# ------------------------------------------------------------------------------------- the statistics
def floor_constant(half_width: int) -> float:
    """c = E[(h+1)-th smallest of 2h+1 Exp(1)] = H_{2h+1} - H_h (ln 2 as h grows)."""
    h = int(half_width)
    return float(np.sum(1.0 / (2 * h + 1 - np.arange(h + 1))))


def log_tail(z: np.ndarray | float, half_width: int) -> np.ndarray:
    """ln P(whitened power > z) for noise: prod_{i=0}^{h} (2h - i) / (2h - i + z / c) (module
    docstring, item 4; exact for white noise when z / c >= 1, the range a p-value needs)."""
    h = int(half_width)
    s = np.maximum(np.asarray(z, dtype=np.float64), 0.0) / floor_constant(h)
    out = np.zeros_like(s)
    for i in range(h + 1):
        out -= np.log1p(s / (2 * h - i))
    return out


def corrected(log_p: np.ndarray, trials: float) -> np.ndarray:
    """1 - (1 - p)^trials with p = exp(log_p): the chance that the largest of `trials` independent
    tests passes, computed stably as -expm1(trials * log1p(-p))."""
    p = np.exp(np.asarray(log_p, dtype=np.float64))
    with np.errstate(divide="ignore"):
        return -np.expm1(trials * np.log1p(-np.minimum(p, 1.0)))


def spectrum(y: np.ndarray, grid: FrequencyGrid) -> tuple[np.ndarray, np.ndarray]:
    """(means (pixels,), powers (n_freq, pixels)) of float64 series y (time, pixels; overwritten on
    irregular stamps) with their mean and least-squares line removed, at the grid's frequencies:
    |sum y e^{-2 pi i f t}|^2 / N by scipy's rfft down the columns on uniform stamps (the mean only
    touches f = 0; the line is taken out of the Fourier coefficients, `ramp_spectrum`), nifty-ls
    Lomb-Scargle ("psd" normalization, floating mean) on irregular ones."""
    import scipy.fft

    n = y.shape[0]
    tc = grid.time - grid.time.mean()
    slope = (tc @ y) / float(tc @ tc)
    if grid.uniform:
        coef = scipy.fft.rfft(y, axis=0)
        mean = coef[0].real / n
        coef = coef[1 : grid.n_freq + 1]
        coef -= grid.ramp_spectrum[:, None] * slope[None, :]
        power = np.square(coef.real)
        power += np.square(coef.imag)
        power /= n
        return mean, power
    import nifty_ls

    mean = y.mean(axis=0)
    series = np.ascontiguousarray((y - mean[None, :] - tc[:, None] * slope[None, :]).T)
    res = nifty_ls.lombscargle(
        grid.time,
        series,
        fmin=grid.df,
        fmax=grid.n_freq * grid.df,
        Nf=grid.n_freq,
        normalization="psd",
        nthreads=1,  # dask's threads run the blocks in parallel
    )
    return mean, np.ascontiguousarray(np.asarray(res.power, dtype=np.float64).reshape(-1, grid.n_freq).T)


def periodogram(y: np.ndarray, grid: FrequencyGrid) -> np.ndarray:
    """Powers (n_freq, pixels) of series y (time, pixels) at the grid's frequencies, their mean and
    least-squares line removed (`spectrum`)."""
    series = np.asarray(y, dtype=np.float64)
    return spectrum(np.array(series.reshape(series.shape[0], -1)), grid)[1]


def whiten(power: np.ndarray, grid: FrequencyGrid, bins: np.ndarray | None = None) -> np.ndarray:
    """Whitened powers z = P / floor (module docstring, item 3) of powers (n_freq, pixels), at all
    frequencies or at `bins` only (indices into the grid: only their windows are computed);
    (frequencies, pixels), 0 where a pixel has no power."""
    h = grid.half_width
    a, fitted, pinv = grid.baseline_basis
    starts, nearest = grid.windows
    log_p = np.maximum(power[fitted], np.finfo(np.float64).tiny)
    np.log(log_p, out=log_p)
    coef = pinv @ log_p  # the baseline: ln P ~ a @ coef
    cols = np.arange(grid.n_freq) if bins is None else np.asarray(bins, dtype=np.int64)
    z = np.empty((cols.size, power.shape[1]))
    c = floor_constant(h)
    for w in np.unique(nearest[cols]):  # window by window: small arrays, in cache
        sl = slice(starts[w], starts[w] + 2 * h + 1)
        ratio = a[sl] @ coef
        np.negative(ratio, out=ratio)
        np.exp(ratio, out=ratio)
        ratio *= power[sl]  # P / baseline over the window
        with np.errstate(divide="ignore"):
            scale = c / np.partition(ratio, h, axis=0)[h]  # 1 / floor, in units of the baseline
        sel = np.flatnonzero(nearest[cols] == w)
        z[sel] = ratio[cols[sel] - starts[w]] * scale[None, :]
    z[~np.isfinite(z)] = 0.0
    return z


def _refine(power: np.ndarray, idx: np.ndarray, n_freq: int) -> np.ndarray:
    """Bin offsets in [-0.5, 0.5] of the parabola's vertex through ln P at idx - 1, idx, idx + 1
    (power (n_freq, pixels), idx a bin per pixel)."""
    i = np.clip(idx, 1, n_freq - 2)
    cols = np.arange(idx.size)
    tiny = np.finfo(np.float64).tiny
    a, b, c = (np.log(np.maximum(power[i + d, cols], tiny)) for d in (-1, 0, 1))
    den = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(den < 0, 0.5 * (a - c) / den, 0.0)
    delta = np.clip(np.nan_to_num(delta), -0.5, 0.5)
    return np.where(i == idx, delta, 0.0)


# ---------------------------------------------------------------------------------- one chunk's work
def _batches(block: np.ndarray, grid: FrequencyGrid, batch: int):
    """(slice of the block's pixels, their means, their powers (n_freq, pixels)) for batches of
    `batch` pixels."""
    nt = block.shape[0]
    flat = np.asarray(block).reshape(nt, -1)
    for start in range(0, flat.shape[1], batch):
        sl = slice(start, min(start + batch, flat.shape[1]))
        y = flat[:, sl].astype(np.float64)
        bad = ~np.isfinite(y)
        if bad.any():  # missing samples: the pixel's mean; a pixel without samples: mean NaN, no power
            y[bad] = 0.0
            count = (~bad).sum(axis=0)
            fill = np.divide(y.sum(axis=0), count, out=np.zeros(y.shape[1]), where=count > 0)
            y[bad] = np.broadcast_to(fill[None, :], y.shape)[bad]
            mean, power = spectrum(y, grid)
            mean[count == 0] = np.nan
        else:
            mean, power = spectrum(y, grid)
        yield sl, mean, power


def first_pass(block: np.ndarray, grid: FrequencyGrid, batch: int) -> dict[str, np.ndarray]:
    """A block (time, y, x) -> its maps (peak bin, peak frequency, peak SNR, mean frame; (y, x))
    and the largest z over its pixels at each frequency of the band."""
    _, ny, nx = block.shape
    npix = ny * nx
    peak_bin = np.zeros(npix, dtype=np.int64)
    peak_f = np.zeros(npix)
    peak_z = np.zeros(npix)
    mean = np.zeros(npix)
    zmax = np.zeros(grid.n_searched)
    band = np.arange(grid.lo, grid.hi)
    for sl, m, power in _batches(block, grid, batch):
        z = whiten(power, grid, band)
        k = np.argmax(z, axis=0)
        idx = k + grid.lo
        peak_bin[sl] = idx
        peak_z[sl] = z[k, np.arange(k.size)]
        peak_f[sl] = (idx + 1 + _refine(power, idx, grid.n_freq)) * grid.df
        mean[sl] = m
        np.maximum(zmax, z.max(axis=1), out=zmax)
    shape = (ny, nx)
    return {
        "peak_bin": peak_bin.reshape(shape),
        "peak_frequency": peak_f.reshape(shape),
        "peak_snr": peak_z.reshape(shape),
        "mean_frame": mean.reshape(shape),
        "band_max": zmax,
    }


def line_pass(block: np.ndarray, grid: FrequencyGrid, bins: tuple[int, ...], batch: int) -> dict[str, np.ndarray]:
    """A block -> per line (of Fourier bin `bins[l]`): each pixel's largest z within LINE_BINS of
    it ("snr") and the refined frequency there ("frequency"), arrays (line, y, x)."""
    _, ny, nx = block.shape
    snr = np.zeros((len(bins), ny * nx))
    freq = np.zeros((len(bins), ny * nx))
    near = [np.arange(max(grid.lo, b - LINE_BINS), min(grid.hi, b + LINE_BINS + 1)) for b in bins]
    cols = np.unique(np.concatenate(near))
    for sl, _, power in _batches(block, grid, batch):
        z = whiten(power, grid, cols)
        for k, nb in enumerate(near):
            zk = z[np.searchsorted(cols, nb)]
            j = np.argmax(zk, axis=0)
            idx = nb[j]
            snr[k, sl] = zk[j, np.arange(j.size)]
            freq[k, sl] = (idx + 1 + _refine(power, idx, grid.n_freq)) * grid.df
    return {"snr": snr.reshape(len(bins), ny, nx), "frequency": freq.reshape(len(bins), ny, nx)}


# ------------------------------------------------------------------------------------------- chunks
@dataclasses.dataclass(frozen=True)
class ChunkPlan:
    """Spatial blocks (all time samples each) and the pixels processed at once inside a block."""

    block_y: int
    block_x: int
    batch: int  # pixels per float64 batch
    keep: bool  # read the cube once and keep it for the second pass


def plan_chunks(
    shape: tuple[int, int, int], itemsize: int, threads: int, memory: int, uniform: bool = True
) -> ChunkPlan:
    """Blocks so that `threads` blocks in flight (stored dtype, x2 while assembled from their time
    pieces) plus their float64 batches (WORK_BYTES_PER_SAMPLE per sample) fit in `memory` bytes.
    A cube of at most a quarter of `memory` is kept in memory between the two passes."""
    from dask.utils import format_bytes

    nt, ny, nx = (int(s) for s in shape)
    cube_bytes = nt * ny * nx * itemsize
    keep = cube_bytes <= memory // 4
    per_thread = (memory - (cube_bytes if keep else 0)) / max(threads, 1)
    work = WORK_BYTES_PER_SAMPLE[bool(uniform)]
    batch = int(per_thread / 2 // (work * nt))
    if batch < 1:
        need = 2 * work * nt * max(threads, 1) + (cube_bytes if keep else 0)
        raise InputError(
            f"--memory: {format_bytes(memory)} is too little for {threads} thread(s) on {nt}-sample series "
            f"(at least {format_bytes(need)})"
        )
    pixels = max(batch, int(per_thread / 2 // (2 * itemsize * nt)))
    batch = min(batch, max(1, BATCH_BYTES // (8 * nt)))
    total = ny * nx
    if total >= 2 * threads * MIN_CHUNK_PIXELS:  # at least two blocks per thread: balanced work
        pixels = min(pixels, max(MIN_CHUNK_PIXELS, -(-total // (2 * threads))))
    pixels = min(pixels, total)
    block_y, block_x = (min(ny, pixels // nx), nx) if pixels >= nx else (1, pixels)
    return ChunkPlan(block_y, block_x, min(batch, block_y * block_x), keep)


def _boundaries(chunks: tuple[int, ...]) -> set[int]:
    return set(np.cumsum((0, *chunks)).tolist())


def blocks_of(data: Any, plan: ChunkPlan) -> list[tuple[slice, slice, Any]]:
    """(y slice, x slice, dask array (time, y, x)) of every block of the plan, from a dask array.

    When every source chunk lies inside one block, or the cube is kept in memory anyway, the blocks
    are a rechunk of the source. Otherwise (frames split in time pieces that span many blocks, as
    video and netCDF read by frames) a rechunk would hold every piece until the last block used it:
    the whole cube. There each block reads its own pixels of every piece in tasks of its own
    (`dask.graph_manipulation.clone`; dask fuses the slice into the read where the source allows),
    so only the blocks in flight are held."""
    from dask.graph_manipulation import clone

    _, ny, nx = data.shape
    cuts = [
        (slice(y, min(y + plan.block_y, ny)), slice(x, min(x + plan.block_x, nx)))
        for y in range(0, ny, plan.block_y)
        for x in range(0, nx, plan.block_x)
    ]
    edges_y = {s.stop for s, _ in cuts} | {0}
    edges_x = {s.stop for _, s in cuts} | {0}
    aligned = edges_y <= _boundaries(data.chunks[1]) and edges_x <= _boundaries(data.chunks[2])
    if aligned or plan.keep:
        whole = data.rechunk((-1, plan.block_y, plan.block_x))
        return [(ys, xs, whole[:, ys, xs]) for ys, xs in cuts]
    return [(ys, xs, clone(data, seed=k)[:, ys, xs].rechunk((-1, -1, -1))) for k, (ys, xs) in enumerate(cuts)]


# ------------------------------------------------------------------------------------------ results
@dataclasses.dataclass(frozen=True)
class LineCluster:
    """The pixels of one cluster that carry one line."""

    line: int
    cluster: int
    n_pixels: int
    centroid: tuple[float, float]  # (y, x), pixel indices of the cube
    bbox: tuple[int, int, int, int]  # (y0, y1, x0, x1), half-open pixel index ranges
    mean_snr: float
    max_snr: float


@dataclasses.dataclass(frozen=True)
class Line:
    """A detected line: its frequency, largest SNR over the pixels, corrected false-alarm probability."""

    index: int
    frequency: float  # Hz: SNR-weighted mean of its pixels' refined peak frequencies
    bin_frequency: float  # Hz: the Fourier frequency of its strongest bin
    snr: float
    false_alarm_probability: float
    n_pixels: int  # pixels that carry it
    clusters: tuple[LineCluster, ...]


@dataclasses.dataclass
class DetectionMap:
    """Maps (`xarray.Dataset`, variables on (y, x), (line, y, x), (line,), (cluster_id,)) and lines."""

    maps: xr.Dataset
    lines: list[Line]

    def table(self) -> list[dict[str, Any]]:
        """One row per (line, cluster): frequency_hz, snr (mean over the cluster's pixels carrying the
        line), max_snr, false_alarm_probability (the line's), cluster, n_pixels, centroid, bbox."""
        rows = []
        for line in self.lines:
            for c in line.clusters:
                rows.append(
                    {
                        "line": line.index,
                        "frequency_hz": line.frequency,
                        "snr": c.mean_snr,
                        "max_snr": c.max_snr,
                        "false_alarm_probability": line.false_alarm_probability,
                        "cluster": c.cluster,
                        "n_pixels": c.n_pixels,
                        "centroid_y": c.centroid[0],
                        "centroid_x": c.centroid[1],
                        "bbox_y0": c.bbox[0],
                        "bbox_y1": c.bbox[1],
                        "bbox_x0": c.bbox[2],
                        "bbox_x1": c.bbox[3],
                    }
                )
        return rows

    def cluster(self, k: int) -> np.ndarray:
        """The boolean (y, x) mask of cluster k (1, 2, ...: the `cluster` map), for
        `vi.fit(cube, pixels=found.cluster(k))`; a one-line InputError for a cluster not in the map."""
        labels = np.asarray(self.maps["cluster"].values)
        ids = sorted(int(c) for c in np.unique(labels) if c > 0)
        if int(k) not in ids:
            raise InputError(f"cluster: {k} is not in the detection map; its clusters are {ids or 'none'}")
        return labels == int(k)

    def to_netcdf(self, path: str | Path) -> None:
        self.maps.to_netcdf(str(path), engine="h5netcdf")

    def write_csv(self, path: str | Path) -> None:
        """lines.csv: '#' comment lines (units, alpha), a header, one row per (line, cluster)."""
        rows = self.table()
        names = list(rows[0]) if rows else list(LINE_TABLE_COLUMNS)
        with open(path, "w", encoding="utf-8", newline="") as fh:
            fh.write(
                f"# vibinverse detect: lines (false-alarm probability < {self.maps.attrs['alpha']:g}) and the "
                "pixel clusters that carry them\n"
            )
            fh.write(
                "# frequency_hz in Hz; snr = whitened power (noise floor 1); pixels: 0-based (y, x) indices, "
                "bbox half-open [y0, y1) x [x0, x1)\n"
            )
            writer = csv.DictWriter(fh, fieldnames=names, lineterminator="\n")
            writer.writeheader()
            for r in rows:
                writer.writerow({k: (f"{v:.10g}" if isinstance(v, float) else v) for k, v in r.items()})

    def plot(self, path: str | Path) -> None:
        plot_detection(self, path)


LINE_TABLE_COLUMNS = (
    "line", "frequency_hz", "snr", "max_snr", "false_alarm_probability", "cluster", "n_pixels",
    "centroid_y", "centroid_x", "bbox_y0", "bbox_y1", "bbox_x0", "bbox_x1",
)  # fmt: skip


def plot_detection(result: DetectionMap, path: str | Path) -> None:
    """The detection map over the mean frame: the SNR of each pixel's strongest line where it
    carries one (else its peak's -log10 false-alarm probability, faint), clusters outlined and
    labelled with their lines' frequencies."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ds = result.maps
    ny, nx = ds.sizes["y"], ds.sizes["x"]
    fig, ax = plt.subplots(figsize=(7.0, 7.0 * ny / max(nx, 1) + 0.8), constrained_layout=True)
    ax.imshow(ds["mean_frame"].values, cmap="gray", interpolation="nearest")
    if result.lines:
        carries = ds["carries_line"].values.astype(bool)
        snr = np.where(carries, ds["snr"].values, np.nan)
        shown = np.where(carries.any(axis=0), np.nanmax(np.where(carries, snr, -np.inf), axis=0), np.nan)
        im = ax.imshow(np.ma.masked_invalid(shown), cmap="inferno", alpha=0.75, interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8, label="SNR of the pixel's strongest line (whitened power)")
        cluster = ds["cluster"].values
        for k in ds["cluster_id"].values:
            _outline(ax, cluster == k)
            ys, xs = np.nonzero(cluster == k)
            carried = np.flatnonzero(ds["cluster_lines"].sel(cluster_id=k).values)
            label = ", ".join(f"{ds['line_frequency'].values[i]:.3g}" for i in carried)
            ax.annotate(
                f"{int(k)}: {label} Hz",
                (xs.mean(), ys.min() - 0.6),
                color="cyan",
                fontsize=8,
                ha="center",
                va="bottom",
                bbox={"facecolor": "black", "alpha": 0.5, "pad": 1.0, "linewidth": 0},
            )
        title = f"{len(result.lines)} line(s) detected (false-alarm probability < {ds.attrs['alpha']:g})"
    else:
        with np.errstate(divide="ignore"):
            score = -np.log10(np.maximum(ds["pixel_false_alarm_probability"].values, 1e-300))
        im = ax.imshow(score, cmap="viridis", alpha=0.5, interpolation="nearest")
        fig.colorbar(im, ax=ax, shrink=0.8, label="-log10 false-alarm probability of each pixel's peak")
        title = f"no line detected (false-alarm probability < {ds.attrs['alpha']:g})"
    ax.set_title(title, fontsize=10)
    ax.set_xlabel("x (pixel)")
    ax.set_ylabel("y (pixel)")
    fig.savefig(str(path), dpi=120, format="png")
    plt.close(fig)


def _outline(ax: Any, mask: np.ndarray) -> None:
    """Outline a pixel mask along the pixels' edges (a contour of the mask drawn k times finer)."""
    k = max(1, min(8, 2048 // max(mask.shape)))
    fine = np.kron(mask.astype(np.float64), np.ones((k, k)))
    ys = (np.arange(fine.shape[0]) + 0.5) / k - 0.5
    xs = (np.arange(fine.shape[1]) + 0.5) / k - 0.5
    ax.contour(xs, ys, fine, levels=[0.5], colors="cyan", linewidths=1.0)


# ------------------------------------------------------------------------------------- the whole map
def _check_cube(cube: Any) -> xr.DataArray:
    if not isinstance(cube, xr.DataArray):
        raise InputError(f"cube: an xarray.DataArray (time, y, x) is needed, not {type(cube).__name__}")
    if set(cube.dims) != {"time", "y", "x"}:
        raise DataError(f"cube: dimensions must be (time, y, x), not {tuple(cube.dims)}")
    if "time" not in cube.coords:
        raise DataError("cube: the time coordinate (s) is missing")
    if not (np.issubdtype(cube.dtype, np.number) and not np.issubdtype(cube.dtype, np.complexfloating)):
        raise DataError(f"cube: real numbers or integer counts are needed, not {cube.dtype}")
    if cube.sizes["y"] < 1 or cube.sizes["x"] < 1:
        raise DataError(f"cube: the frame is empty ({cube.sizes['y']} x {cube.sizes['x']} pixels)")
    return cube.transpose("time", "y", "x")


def _lines_of(band_max: np.ndarray, grid: FrequencyGrid, n_pixels: int, alpha: float, max_lines: int):
    """[(peak bin, largest z, corrected FAP)] of the groups of band frequencies whose largest z over
    the pixels has corrected false-alarm probability < alpha (at most MERGE_GAP bins apart: one
    line), strongest first."""
    fap = corrected(log_tail(band_max, grid.half_width), grid.n_searched * n_pixels)
    hit = np.flatnonzero(fap < alpha)
    groups = np.split(hit, np.flatnonzero(np.diff(hit) > MERGE_GAP + 1) + 1) if hit.size else []
    runs = []
    for g in groups:
        k = int(g[np.argmax(band_max[g])])
        runs.append((grid.lo + k, float(band_max[k]), float(fap[k])))
    runs.sort(key=lambda r: -r[1])
    if len(runs) > max_lines:
        logger.info(f"detect: {len(runs)} lines pass alpha = {alpha:g}; kept the {max_lines} strongest")
    return runs[:max_lines]


def _benjamini_hochberg(p: np.ndarray, alpha: float) -> np.ndarray:
    """Boolean mask of the p-values that the Benjamini-Hochberg procedure at level alpha keeps."""
    flat = p.ravel()
    order = np.sort(flat)
    ok = np.flatnonzero(order <= alpha * np.arange(1, flat.size + 1) / flat.size)
    if ok.size == 0:
        return np.zeros(p.shape, dtype=bool)
    return p <= order[ok[-1]]


def _clusters(snr: np.ndarray, carries: np.ndarray):
    """(cluster map (y, x) int32 numbered by decreasing peak SNR, [(id, pixel mask)])."""
    from scipy import ndimage

    union = carries.any(axis=0)
    labels, n = ndimage.label(union, structure=np.ones((3, 3), dtype=bool))
    strength = np.where(carries, snr, 0.0).max(axis=0, initial=0.0)
    peaks = ndimage.maximum(strength, labels, index=np.arange(1, n + 1)) if n else []
    order = np.argsort(-np.asarray(peaks, dtype=float), kind="stable")
    out = np.zeros(labels.shape, dtype=np.int32)
    masks = []
    for new, old in enumerate(order, start=1):
        mask = labels == old + 1
        out[mask] = new
        masks.append((new, mask))
    return out, masks


def _region(mask: np.ndarray) -> tuple[int, tuple[float, float], tuple[int, int, int, int]]:
    ys, xs = np.nonzero(mask)
    return (
        int(ys.size),
        (float(ys.mean()), float(xs.mean())),
        (int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1),
    )


def detection_map(
    cube: xr.DataArray,
    *,
    band: tuple[float, float] | None = None,
    alpha: float = 1e-3,
    max_lines: int = 8,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool = False,
    memory: int = DEFAULT_MEMORY,
) -> DetectionMap:
    """The per-pixel detection map of `cube` (time, y, x; lazy or in memory; float or integer
    counts; coord "time" in s, uniform or not) and its lines (module docstring). `band` (Hz) limits
    the search; `alpha` is the false-alarm probability of the whole map (lines) and the false
    fraction of a line's pixels; `scheduler` None runs on `workers` local threads (default: the
    cores), an address on that dask.distributed cluster; `memory` bounds the chunks in flight (bytes)."""
    cube = _check_cube(cube)
    if not (0.0 < float(alpha) < 1.0):
        raise InputError(f"--alpha: {alpha!r} is not a probability in (0, 1)")
    if isinstance(max_lines, bool) or not isinstance(max_lines, int) or max_lines < 1:
        raise InputError(f"--max-lines: {max_lines!r} is not an integer >= 1")
    if isinstance(memory, bool) or not (isinstance(memory, numbers.Real) and memory > 0):
        raise InputError(f"--memory: {memory!r} is not a number of bytes > 0")
    grid = frequency_grid(cube["time"].values, band)
    _, ny, nx = cube.shape
    n_pixels = ny * nx
    # dask's threads run the blocks in parallel: BLAS threads inside them would only contend
    with session(scheduler, workers, progress=progress) as run, threadpool_limits(1, user_api="blas"):
        plan = plan_chunks(cube.shape, cube.dtype.itemsize, run.threads, int(memory), grid.uniform)
        if cube.chunks is None:  # in memory or a lazy file backend: each block reads its own hyperslab
            data = cube.chunk({"time": -1, "y": plan.block_y, "x": plan.block_x}).data
        else:
            data = cube.data
        blocks = blocks_of(data, plan)
        logger.debug(f"detect: {len(blocks)} blocks of {plan.block_y} x {plan.block_x} pixels, batches of {plan.batch}")
        clock = time.perf_counter()
        if plan.keep:
            arrays = run.persist(*[b for _, _, b in blocks])
            blocks = [(ys, xs, a) for (ys, xs, _), a in zip(blocks, arrays)]
            logger.debug(f"detect: cube read and kept in {time.perf_counter() - clock:.2f} s")
        first = run.compute(*[_delayed(first_pass)(b, grid, plan.batch) for _, _, b in blocks])
        logger.debug(f"detect: first pass (peaks) {time.perf_counter() - clock:.2f} s")
        maps = {
            k: np.zeros((ny, nx), dtype=first[0][k].dtype)
            for k in ("peak_bin", "peak_frequency", "peak_snr", "mean_frame")
        }
        band_max = np.zeros(grid.n_searched)
        for (ys, xs, _), part in zip(blocks, first):
            for k in maps:
                maps[k][ys, xs] = part[k]
            np.maximum(band_max, part["band_max"], out=band_max)
        runs = _lines_of(band_max, grid, n_pixels, float(alpha), max_lines)
        bins = tuple(r[0] for r in runs)
        snr = np.zeros((len(bins), ny, nx))
        freq = np.zeros((len(bins), ny, nx))
        if bins:
            second = run.compute(*[_delayed(line_pass)(b, grid, bins, plan.batch) for _, _, b in blocks])
            logger.debug(f"detect: second pass (SNR maps of {len(bins)} lines) {time.perf_counter() - clock:.2f} s")
            for (ys, xs, _), part in zip(blocks, second):
                snr[:, ys, xs] = part["snr"]
                freq[:, ys, xs] = part["frequency"]
    log_p = log_tail(maps["peak_snr"], grid.half_width)
    pixel_fap = corrected(log_p, grid.n_searched)
    fap = corrected(log_p, grid.n_searched * n_pixels)
    carries = np.zeros((len(bins), ny, nx), dtype=bool)
    for k, b in enumerate(bins):
        width = min(grid.hi, b + LINE_BINS + 1) - max(grid.lo, b - LINE_BINS)
        carries[k] = _benjamini_hochberg(corrected(log_tail(snr[k], grid.half_width), width), float(alpha))
    cluster, masks = _clusters(snr, carries)
    lines = _make_lines(runs, grid, snr, freq, carries, cluster, masks)
    ds = _dataset(cube, grid, maps, pixel_fap, fap, lines, snr, carries, cluster, masks, float(alpha), band)
    logger.info(
        f"detect: {n_pixels} pixels x {grid.n_searched} frequencies ({grid.frequencies[grid.lo]:.4g} to "
        f"{grid.frequencies[grid.hi - 1]:.4g} Hz): {len(lines)} line(s), {len(masks)} cluster(s)"
    )
    return DetectionMap(ds, lines)


def _delayed(fn):
    import dask

    return dask.delayed(fn, pure=True)


def _make_lines(runs, grid, snr, freq, carries, cluster, masks) -> list[Line]:
    lines = []
    for k, (b, zmax, fap) in enumerate(runs):
        member = carries[k]
        w = snr[k][member]
        f = float(np.sum(w * freq[k][member]) / np.sum(w)) if w.size and np.sum(w) > 0 else (b + 1) * grid.df
        parts = []
        for cid, mask in masks:
            sel = mask & member
            if sel.any():
                n, centroid, bbox = _region(sel)
                vals = snr[k][sel]
                parts.append(LineCluster(k, cid, n, centroid, bbox, float(vals.mean()), float(vals.max())))
        lines.append(Line(k, f, float((b + 1) * grid.df), zmax, fap, int(member.sum()), tuple(parts)))
    return lines


# (dims, units, long_name) of every variable of detection.nc; units "1": dimensionless; None: the cube's
VARIABLES = {
    "peak_frequency": (("y", "x"), "Hz", "frequency of the pixel's strongest whitened periodogram peak in the band"),
    "peak_snr": (("y", "x"), "1", "whitened power at the pixel's peak (noise floor = 1)"),
    "false_alarm_probability": (
        ("y", "x"),
        "1",
        "false-alarm probability of the pixel's peak, corrected for the frequencies and pixels searched",
    ),
    "pixel_false_alarm_probability": (
        ("y", "x"),
        "1",
        "false-alarm probability of the pixel's peak, corrected for the frequencies searched",
    ),
    "mean_frame": (("y", "x"), None, "mean intensity over time"),
    "line_frequency": (("line",), "Hz", "frequency of the detected line (SNR-weighted over its pixels)"),
    "line_snr": (("line",), "1", "largest whitened power of the line over the pixels"),
    "line_false_alarm_probability": (
        ("line",),
        "1",
        "false-alarm probability of the line, corrected for the frequencies and pixels searched",
    ),
    "snr": (("line", "y", "x"), "1", "largest whitened power within one Fourier bin of the line"),
    "carries_line": (("line", "y", "x"), "1", "1 where the pixel carries the line (Benjamini-Hochberg at alpha)"),
    "cluster": (("y", "x"), "1", "cluster of pixels carrying a line: 0 none, k >= 1 cluster k (cluster_id)"),
    "line_of_cluster": (("cluster_id",), "1", "index (line) of the cluster's strongest line (largest mean SNR)"),
    "cluster_lines": (("cluster_id", "line"), "1", "1 where the cluster carries the line"),
}


def _dataset(cube, grid, maps, pixel_fap, fap, lines, snr, carries, cluster, masks, alpha, band) -> xr.Dataset:
    n_lines, n_clusters = len(lines), len(masks)
    cluster_lines = np.zeros((n_clusters, n_lines), dtype=np.int8)
    line_of_cluster = np.zeros(n_clusters, dtype=np.int32)
    for i, (_, mask) in enumerate(masks):
        means = np.full(n_lines, -np.inf)
        for k in range(n_lines):
            sel = mask & carries[k]
            if sel.any():
                cluster_lines[i, k] = 1
                means[k] = snr[k][sel].mean()
        line_of_cluster[i] = int(np.argmax(means))
    values = {
        "peak_frequency": maps["peak_frequency"],
        "peak_snr": maps["peak_snr"],
        "false_alarm_probability": fap,
        "pixel_false_alarm_probability": pixel_fap,
        "mean_frame": maps["mean_frame"],
        "line_frequency": np.array([ln.frequency for ln in lines], dtype=np.float64),
        "line_snr": np.array([ln.snr for ln in lines], dtype=np.float64),
        "line_false_alarm_probability": np.array([ln.false_alarm_probability for ln in lines], dtype=np.float64),
        "snr": snr,
        "carries_line": carries.astype(np.int8),
        "cluster": cluster.astype(np.int32),
        "line_of_cluster": line_of_cluster,
        "cluster_lines": cluster_lines,
    }
    units = str(cube.attrs.get("units", "1"))
    ds = xr.Dataset(
        {
            name: (dims, values[name], {"units": u if u is not None else units, "long_name": text})
            for name, (dims, u, text) in VARIABLES.items()
        },
        coords={
            "line": ("line", np.arange(n_lines), {"units": "1", "long_name": "detected line, strongest first"}),
            "cluster_id": (
                "cluster_id",
                np.array([c for c, _ in masks], dtype=np.int32),
                {"units": "1", "long_name": "cluster"},
            ),
        },
    )
    for dim in ("y", "x"):
        if dim in cube.coords and cube.coords[dim].dims == (dim,):
            ds = ds.assign_coords({dim: cube.coords[dim].values})
            ds[dim].attrs.update({k: v for k, v in cube.coords[dim].attrs.items() if isinstance(v, str | int | float)})
    lo_f, hi_f = grid.frequencies[grid.lo], grid.frequencies[grid.hi - 1]
    ds.attrs.update(
        {
            "title": "vibinverse detection map",
            "alpha": alpha,
            "band_searched_hz": np.array([lo_f, hi_f]),
            "band_requested_hz": np.array(band if band is not None else [np.nan, np.nan], dtype=np.float64),
            "frequency_resolution_hz": grid.df,
            "n_frequencies": grid.n_searched,
            "n_pixels": int(cube.sizes["y"] * cube.sizes["x"]),
            "n_frames": int(cube.sizes["time"]),
            "uniform_time": int(grid.uniform),
            "periodogram": "rfft" if grid.uniform else "Lomb-Scargle (nifty-ls, floating mean, psd)",
            "floor_window_bins": 2 * grid.half_width + 1,
            "row_offset": "ignored: a per-row time shift changes the phase of a periodogram, not its power",
            "source": str(cube.attrs.get("source", "")),
            "Conventions": "CF-1.8",
        }
    )
    return ds
