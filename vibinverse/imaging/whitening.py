"""The whitened periodogram of many pixels at once: the Fourier frequencies of a record, each
pixel's periodogram and its whitening by a robust local noise floor, with the exact tail of the
whitened power on noise (what `detection_map` searches).

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
   of estimating the floor from 128 neighbours). `log_tail` computes it; `corrected` corrects it
   for many independent tests.

The first LOW_BINS frequencies (1-4 cycles per record) are searched apart (`slow_lines`): for them
`spectra_rows` also gives each pixel's Fourier coefficients there and `white_floor` its flat
floors (the first and last windows' medians / c, no baseline: at a few bins on the ln f axis the
baseline's fit is unreliable).

Layouts: `spectrum`, `periodogram` and `whiten` take and give (frequency, pixels) arrays; the
`*_rows` functions work on rows (pixels, frequency), where a pixel's floor windows are contiguous
(a window's median is one `np.partition` over the rows). `fit_floor` keeps each pixel's fitted
floor (`Floor`: the baseline's 4 coefficients and one scale per window), so that the whitened
power at a few bins is had later from the powers there alone (`Floor.whiten`); on uniform stamps
`dft_power` gives those powers by direct sums at the bins (one matrix product), without the whole
transform, summed over pieces of the record (`dft_sums`) in any order.

No equation of the paper is used here (the paper stops at the sensitivity, eq. 21).
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import math

import numpy as np

from vibinverse.errors import DataError, InputError

FLOOR_HALF_WIDTH = 64  # h: the floor's windows are 2h + 1 = 129 Fourier bins
#: the largest magnitude a pixel's value may have (`spectrum_rows`, `pixels.noise_levels`): its
#: squares summed over 1e8 frames stay below float64's 1.8e308
LARGEST_VALUE = 1e150
MIN_HALF_WIDTH = 8  # fewer Fourier frequencies than 2 * 8 + 1 (35 frames): too short a record
BASELINE_DEGREE = 3  # the smooth baseline: a cubic in ln f fitted to ln P
BASELINE_DENSE, BASELINE_STRIDE = 256, 4  # ... at the first 256 frequencies and every 4th after
LOW_BINS = 4  # the first Fourier frequencies (1-4 cycles per record): drift lives there, searched apart (`slow_lines`)
# stamps within this fraction of a step from a uniform grid (a container's rounded stamps: 30 fps in
# milliseconds is 1.5 %) take the rfft: its phase error, at most 2 pi 0.02 f / fs <= 0.063 rad, loses
# < 0.4 % of a line's power
UNIFORM_TOLERANCE = 0.02
TINY = np.finfo(np.float64).tiny


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
    slow_lo: int = 0  # the slow bins searched (`slow_lines`): i in [slow_lo, slow_hi), within [0, LOW_BINS)
    slow_hi: int = 0

    @property
    def frequencies(self) -> np.ndarray:
        return (np.arange(self.n_freq) + 1.0) * self.df

    @property
    def n_searched(self) -> int:
        """M: the Fourier frequencies in the band (independent for white noise)."""
        return self.hi - self.lo

    @property
    def slow_bins(self) -> np.ndarray:
        """The slow bins searched (indices into the grid, below LOW_BINS; `slow_lines`)."""
        return np.arange(self.slow_lo, self.slow_hi)

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
    def window_runs(self) -> list[tuple[int, int, int]]:
        """[(first bin, last bin + 1, window)] of the runs of bins that take the same window."""
        nearest = self.windows[1]
        edges = np.r_[0, np.flatnonzero(np.diff(nearest)) + 1, nearest.size]
        return [(int(a), int(b), int(nearest[a])) for a, b in itertools.pairwise(edges)]

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
    """The Fourier frequencies of stamps `time` (s), the band searched (Hz, default: from the
    (LOW_BINS+1)-th Fourier frequency up to Nyquist; it must hold one) and the slow bins below it
    searched apart (those of the first LOW_BINS in the band). One-line DataError/InputError naming
    the field."""
    t = np.asarray(time, dtype=np.float64)
    if t.ndim != 1 or not np.all(np.isfinite(t)):
        raise DataError("time: stamps must be a finite 1-D coordinate, in seconds")
    need = 2 * (2 * MIN_HALF_WIDTH + 1) + 1
    if t.size < need:  # before the stamps' order: one frame has no order to break
        raise DataError(f"time: {t.size} frame(s) are too few for a detection map (at least {need})")
    steps = np.diff(t)
    if np.any(steps <= 0):
        first = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise DataError(f"time: stamps must increase strictly (index {first} does not)")
    mean_step = float(t[-1] - t[0]) / (t.size - 1)
    uniform = bool(np.max(np.abs(t - t[0] - mean_step * np.arange(t.size))) <= UNIFORM_TOLERANCE * mean_step)
    dt = mean_step if uniform else float(np.median(steps))
    span = t.size * dt if uniform else float(t[-1] - t[0]) + dt
    n_freq = (t.size - 1) // 2 if uniform else math.floor(0.5 * span / dt + 1e-9) - 1
    half = min(FLOOR_HALF_WIDTH, (n_freq - 1) // 2)
    if half < MIN_HALF_WIDTH:  # (then n_freq >= 2 * MIN_HALF_WIDTH + 1 > LOW_BINS too)
        raise DataError(f"time: {t.size} frames are too few for a detection map (at least {need})")
    df = 1.0 / span
    lo, hi = LOW_BINS, n_freq
    slow_lo, slow_hi = 0, LOW_BINS
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
                f"{(LOW_BINS + 1) * df:.6g} to {n_freq * df:.6g} Hz in steps of {df:.6g} Hz (the slow ones, "
                f"{df:.6g} to {LOW_BINS * df:.6g} Hz, are searched with them)"
            )
        lo, hi = int(inside[0]), int(inside[-1]) + 1
        slow = np.flatnonzero((f[:LOW_BINS] >= fmin) & (f[:LOW_BINS] <= fmax))
        slow_lo, slow_hi = (int(slow[0]), int(slow[-1]) + 1) if slow.size else (0, 0)
    return FrequencyGrid(t, uniform, dt, df, n_freq, lo, hi, half, slow_lo, slow_hi)


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


# ------------------------------------------------------------------------------------- the spectra
def spectrum_rows(y: np.ndarray, grid: FrequencyGrid) -> tuple[np.ndarray, np.ndarray]:
    """(means (pixels,), powers (pixels, n_freq)) of float64 series y (time, pixels; overwritten on
    irregular stamps) with their mean and least-squares line removed, at the grid's frequencies:
    |sum y e^{-2 pi i f t}|^2 / N by scipy's rfft down the columns on uniform stamps (the mean only
    touches f = 0; the line is taken out of the Fourier coefficients, `ramp_spectrum`), nifty-ls
    Lomb-Scargle ("psd" normalization, floating mean) on irregular ones."""
    mean, power, _ = spectra_rows(y, grid)
    return mean, power


def spectra_rows(y: np.ndarray, grid: FrequencyGrid) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`spectrum_rows` and the Fourier coefficients (pixels, LOW_BINS; complex) of the series less
    their mean and line at the first LOW_BINS frequencies, sum y e^{-2 pi i f (t - t_0)}: the rfft's
    on uniform stamps (|.|^2 / N is the power there), direct sums on irregular ones (their
    |.|^2 / N, the classical periodogram, differs from Lomb-Scargle's by the sampling's uneven
    weights)."""
    import scipy.fft

    n = y.shape[0]
    big = float(np.max(np.abs(y))) if y.size else 0.0
    if big > LARGEST_VALUE:  # NaN (a gap) passes: the cube's own checks take it
        raise DataError(
            f"cube: values up to {big:.3g} overflow the periodogram's float64 arithmetic (allowed up to "
            f"{LARGEST_VALUE:g}); rescale the data"
        )
    tc = grid.time - grid.time.mean()
    slope = (tc @ y) / float(tc @ tc)
    if grid.uniform:
        coef = scipy.fft.rfft(y, axis=0)
        mean = coef[0].real / n
        coef = coef[1 : grid.n_freq + 1]
        coef -= grid.ramp_spectrum[:, None] * slope[None, :]
        slow = np.ascontiguousarray(coef[:LOW_BINS].T)
        power = np.square(coef.real)
        power += np.square(coef.imag)
        power /= n
        return mean, np.ascontiguousarray(power.T), slow
    import nifty_ls

    mean = y.mean(axis=0)
    y -= mean[None, :]
    y -= tc[:, None] * slope[None, :]
    res = nifty_ls.lombscargle(
        grid.time,
        np.ascontiguousarray(y.T),
        fmin=grid.df,
        fmax=grid.n_freq * grid.df,
        Nf=grid.n_freq,
        normalization="psd",
        nthreads=1,  # dask's threads run the blocks in parallel
    )
    phase = (-2j * np.pi * grid.df) * np.outer(grid.time - grid.time[0], np.arange(1, LOW_BINS + 1))
    slow = y.T @ np.exp(phase)
    return mean, np.asarray(res.power, dtype=np.float64).reshape(-1, grid.n_freq), slow


def spectrum(y: np.ndarray, grid: FrequencyGrid) -> tuple[np.ndarray, np.ndarray]:
    """(means (pixels,), powers (n_freq, pixels)): `spectrum_rows` with the powers down the columns."""
    mean, rows = spectrum_rows(y, grid)
    return mean, rows.T


def periodogram(y: np.ndarray, grid: FrequencyGrid) -> np.ndarray:
    """Powers (n_freq, pixels) of series y (time, pixels) at the grid's frequencies, their mean and
    least-squares line removed (`spectrum`)."""
    series = np.asarray(y, dtype=np.float64)
    return spectrum(np.array(series.reshape(series.shape[0], -1)), grid)[1]


def dft_basis(grid: FrequencyGrid, bins: np.ndarray, frames: slice = slice(None)) -> np.ndarray:
    """(frames, 2 K + 1): cos and -sin of 2 pi (k + 1) n / N at the grid's `bins` k (K of them; the
    phase reduced modulo N in integers) for the samples n in `frames`, then the centred time of
    `ramp_spectrum`: the basis of `dft_sums` on uniform stamps."""
    n = grid.time.size
    k = np.asarray(bins, dtype=np.int64) + 1
    index = np.arange(n, dtype=np.int64)[frames]
    phase = (2 * np.pi / n) * (np.outer(index, k) % n)
    tc = (grid.time - grid.time.mean())[frames]
    return np.concatenate([np.cos(phase), -np.sin(phase), tc[:, None]], axis=1)


def dft_sums(y: np.ndarray, mean: np.ndarray, basis: np.ndarray) -> np.ndarray:
    """(2 K + 1, pixels): basis.T @ (y - mean) for series y (frames, pixels; any real dtype) and
    their means (pixels,), missing samples counted as the mean. Linear in y: the sums over pieces
    of the record add up to the record's (`dft_power`)."""
    yc = np.subtract(y, mean[None, :], dtype=np.float64)
    sums = basis.T @ yc
    bad = ~np.isfinite(sums).all(axis=0)
    if bad.any():
        fill = yc[:, bad]
        fill[~np.isfinite(fill)] = 0.0
        sums[:, bad] = basis.T @ fill
    return sums


def dft_power(sums: np.ndarray, grid: FrequencyGrid, bins: np.ndarray) -> np.ndarray:
    """Powers (pixels, K) at the grid's K `bins` (uniform stamps) from the record's `dft_sums` at
    them: the DFT sums less the least-squares line, as `spectrum_rows` takes it out of the rfft
    (the same periodogram to rounding), |.|^2 / N."""
    bins = np.asarray(bins, dtype=np.int64)
    k, n = bins.size, grid.time.size
    tc = grid.time - grid.time.mean()
    slope = sums[-1] / float(tc @ tc)
    ramp = grid.ramp_spectrum[bins]
    re = sums[:k] - ramp.real[:, None] * slope[None, :]
    im = sums[k : 2 * k] - ramp.imag[:, None] * slope[None, :]
    return ((re * re + im * im) / n).T


# ------------------------------------------------------------------------------------ the floor
@dataclasses.dataclass(frozen=True)
class Floor:
    """The fitted noise floor of some pixels (item 3): at bin k, floor = exp(A[k] @ coef) / scale[w],
    w the window bin k takes (`FrequencyGrid.windows`), A the baseline's basis."""

    coef: np.ndarray  # (pixels, BASELINE_DEGREE + 1): ln baseline = A @ coef
    scale: np.ndarray  # (pixels, windows): c / median of P / baseline over the window (inf when 0)

    def whiten(self, power: np.ndarray, grid: FrequencyGrid, bins: np.ndarray) -> np.ndarray:
        """Whitened powers z (pixels, K) of powers (pixels, K) at the grid's K `bins`; 0 where a pixel
        has no power."""
        bins = np.asarray(bins, dtype=np.int64)
        ratio = self.coef @ grid.baseline_basis[0][bins].T
        np.negative(ratio, out=ratio)
        with np.errstate(over="ignore", invalid="ignore"):  # a pixel without power: z = 0
            np.exp(ratio, out=ratio)
            ratio *= power
            return _finite(ratio * self.scale[:, grid.windows[1][bins]])

    def take(self, pixels: slice | np.ndarray) -> Floor:
        """The floor of some of the pixels."""
        return Floor(self.coef[pixels], self.scale[pixels])


def fit_floor(power: np.ndarray, grid: FrequencyGrid) -> tuple[np.ndarray, Floor]:
    """(P / baseline (pixels, n_freq), the floor) of powers in rows (pixels, n_freq) (item 3): the
    cubic in ln f fitted to ln P (`FrequencyGrid.baseline_basis`), and each window's median of
    P / baseline by one partition of the windows that tile the frequencies (and one of the last,
    which overlaps its neighbour when they do not tile exactly)."""
    h = grid.half_width
    w = 2 * h + 1
    a, fitted, pinv = grid.baseline_basis
    starts = grid.windows[0]
    n, tiles = grid.n_freq, grid.n_freq // w
    log_p = np.maximum(power[:, fitted], TINY)
    np.log(log_p, out=log_p)
    coef = log_p @ pinv.T  # the baseline: ln P ~ A @ coef
    ratio = coef @ a.T
    np.negative(ratio, out=ratio)
    with np.errstate(over="ignore", invalid="ignore"):  # a pixel without power: its z is set to 0
        np.exp(ratio, out=ratio)
        ratio *= power  # P / baseline
    median = np.empty((power.shape[0], starts.size))
    median[:, :tiles] = np.partition(ratio[:, : tiles * w].reshape(-1, tiles, w), h, axis=-1)[:, :, h]
    if starts.size > tiles:  # the last window, ending at the last frequency
        median[:, tiles] = np.partition(ratio[:, n - w :], h, axis=-1)[:, h]
    with np.errstate(divide="ignore"):
        scale = floor_constant(h) / median  # 1 / floor, in units of the baseline
    return ratio, Floor(coef, scale)


def white_floor(power: np.ndarray, grid: FrequencyGrid) -> np.ndarray:
    """Each pixel's two flat floors (pixels, 2) from its powers in rows (pixels, n_freq): the median
    power of its first and of its last floor window, / c, no baseline: the slow bins' references
    (`slow_lines`: the first is near them, the last where a drift's red spectrum has died out)."""
    h, w = grid.half_width, 2 * grid.half_width + 1
    ends = np.stack([power[:, :w], power[:, grid.n_freq - w :]], axis=1)
    return np.partition(ends, h, axis=2)[:, :, h] / floor_constant(h)


def whiten_rows(power: np.ndarray, grid: FrequencyGrid, bins: np.ndarray | None = None) -> tuple[np.ndarray, Floor]:
    """(whitened powers z (pixels, bins), the floor) of powers in rows (pixels, n_freq), at all
    frequencies or at `bins` (indices into the grid); 0 where a pixel has no power."""
    z, floor = fit_floor(power, grid)
    with np.errstate(invalid="ignore"):  # 0 * inf where a pixel has no power: set to 0 below
        for a, b, w in grid.window_runs:  # z = P / baseline * scale, in place, window by window
            z[:, a:b] *= floor.scale[:, w : w + 1]
    if bins is not None:
        bins = np.asarray(bins, dtype=np.int64)
        contiguous = bins.size and bins[-1] - bins[0] == bins.size - 1 and np.all(np.diff(bins) == 1)
        z = z[:, bins[0] : bins[-1] + 1] if contiguous else z[:, bins]
    return (_finite(z) if not np.isfinite(z).all() else z), floor


def whiten(power: np.ndarray, grid: FrequencyGrid, bins: np.ndarray | None = None) -> np.ndarray:
    """Whitened powers z = P / floor (item 3) of powers (n_freq, pixels), at all frequencies or at
    `bins` (indices into the grid); (frequencies, pixels), 0 where a pixel has no power."""
    return whiten_rows(np.ascontiguousarray(np.asarray(power, dtype=np.float64).T), grid, bins)[0].T


def _finite(z: np.ndarray) -> np.ndarray:
    with np.errstate(invalid="ignore"):
        z[~np.isfinite(z)] = 0.0
    return z


def refine(log_power: np.ndarray) -> np.ndarray:
    """Bin offsets in [-0.5, 0.5] of the vertex of the parabola through ln P at a peak's bin and its
    two neighbours, log_power (3, ...) = (ln P[k - 1], ln P[k], ln P[k + 1]); 0 where it opens upward."""
    a, b, c = log_power
    den = a - 2 * b + c
    with np.errstate(divide="ignore", invalid="ignore"):
        delta = np.where(den < 0, 0.5 * (a - c) / den, 0.0)
    return np.clip(np.nan_to_num(delta), -0.5, 0.5)
