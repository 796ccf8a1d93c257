"""Spectral tools shared by the models' starting values and by design: periodogram (FFT on a uniform
grid, Lomb-Scargle by nifty-ls on irregular stamps), least-squares sinusoids and harmonics, and
ranked line candidates.

Milliseconds, rough, and gap-tolerant.
"""

from __future__ import annotations

import itertools

import numpy as np

from vibinverse.io.series import Series

#: the zero padding of `periodogram` (its frequencies k / (PAD x span))
PAD = 4
#: the running median that makes a periodogram's local background spans this many Fourier bins
#: (1 / span each): wide against a line (one bin) and a light resonance, narrow against the slope
#: of coloured noise
BACKGROUND_BINS = 32


def local_background(power: np.ndarray, width: int) -> np.ndarray:
    """The running median of `power` over `width` ordinates, divided by ln 2: the mean of an
    exponential ordinate whose median it is. At the ends the ordinates are mirrored (a sampled
    spectrum is even about 0 and about Nyquist): repeating the end value instead made a small last
    ordinate the median of half a window and Nyquist a candidate."""
    from scipy.ndimage import median_filter

    width = max(3, min(int(width), power.size) | 1)
    return np.maximum(median_filter(power, size=width, mode="mirror") / np.log(2.0), np.finfo(float).tiny)


def periodogram(series: Series, pad: int = PAD, taper: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Power of the de-meaned series on (0, Nyquist]. Uniform sampling: FFT with `pad`-fold zero
    padding, gaps filled with the mean, |sum y e^{-i w t}|^2 / N. Irregular stamps (jitter, dropped
    frames): the floating-mean Lomb-Scargle periodogram of the valid samples (nifty-ls, a NUFFT:
    milliseconds where a direct sum took seconds), in its "psd" normalization, which is the same
    |sum y e^{-i w t}|^2 / N on a uniform grid; frequencies k / (pad * span) up to half the median
    sample rate.

    `taper`: the series less its least-squares line, times a Hann window over its span (at the
    stamps), scaled to keep white noise's level (`tapered`): a slow component (a drift, a gain
    drift of 20 % on the level) leaks from its ends as 1/f^2 over the untapered spectrum and
    buried a 10 Hz drive and a 3.5 Hz resonance under it 70 times over; the Hann window's leakage
    falls as 1/f^6, at the price of peaks twice as wide."""
    good = np.isfinite(series.intensity)
    y = series.intensity - np.nanmean(series.intensity)
    if taper:
        y = tapered(series.time, y)
    if series.uniform:
        filled = np.where(good, y, 0.0)
        n = pad * filled.size
        power = np.abs(np.fft.rfft(filled, n)) ** 2 / max(good.sum(), 1)
        freqs = np.fft.rfftfreq(n, series.dt)
        return freqs[1:], power[1:]
    import nifty_ls

    t = np.ascontiguousarray(series.time[good], dtype=np.float64)
    df = 1.0 / (pad * (t[-1] - t[0]))
    nf = max(int(0.5 * series.fs / df), 2)
    res = nifty_ls.lombscargle(t, np.ascontiguousarray(y[good]), fmin=df, fmax=nf * df, Nf=nf, normalization="psd")
    return res.freq(), np.asarray(res.power, dtype=float)


def tapered(t: np.ndarray, y: np.ndarray) -> np.ndarray:
    """y (NaN at gaps) less its least-squares line over the valid samples, times the Hann window
    sin^2(pi (t - t0) / span) at the stamps, divided by the window's rms over the valid samples."""
    t = np.asarray(t, dtype=float)
    good = np.isfinite(y)
    if good.sum() < 3:
        return y
    line = np.polyval(np.polyfit(t[good] - t[0], y[good], 1), t - t[0])
    span = t[-1] - t[0]
    window = np.sin(np.pi * (t - t[0]) / span) ** 2 if span > 0 else np.ones_like(t)
    rms = float(np.sqrt(np.mean(window[good] ** 2)))
    return (y - line) * window / max(rms, np.finfo(float).tiny)


#: a slow component (a drift, a gain drift) has at most this many cycles per record: `line_candidates`
#: regresses out what is slower than this and than its band
SLOW_CYCLES = 4.0
#: `highpassed` regresses out at most this many slow sequences (an hour-long record's slow part lies
#: hundreds of bins below any resonance, where the taper alone keeps it)
MAX_SLOW_SEQUENCES = 32
#: `highpassed` computes its sequences on at most this many points and interpolates them (an hour at
#: 100 Hz took 1.2 s on all 360,000)
SLOW_GRID = 8192
#: sequences beyond the 2 N W well-concentrated ones: a slow sinusoid near f_cut in a 20 s record
#: left ~1e-3 of its power without them, ~1e-5 with them
SLOW_EXTRA = 3


def highpassed(t: np.ndarray, y: np.ndarray, f_cut: float) -> np.ndarray:
    """y (NaN at gaps) less its least-squares fit on a constant and the first K discrete prolate
    spheroidal (Slepian) sequences of half-bandwidth f_cut over the record (NW = f_cut x span,
    K = 2 NW + SLOW_EXTRA, at most MAX_SLOW_SEQUENCES), fitted at the valid stamps (gaps, and
    irregular stamps by interpolation): the basis that holds most of the energy of anything slower
    than f_cut over a finite record (Slepian 1978), so a drift's or a gain drift's few cycles per
    record are removed to ~1e-5 of their power while a resonance above f_cut keeps its own.
    Regressed out instead of filtered, it leaves no filter transient at the record's ends."""
    from scipy.signal.windows import dpss

    t = np.asarray(t, dtype=float)
    good = np.isfinite(y)
    n = t.size
    span = float(t[-1] - t[0]) if n > 1 else 0.0
    k = min(int(2.0 * f_cut * span) + SLOW_EXTRA, MAX_SLOW_SEQUENCES)
    if span <= 0 or k < 1 or good.sum() <= 2 * (k + 1):
        return y - np.nanmean(y)
    nw = max(min(f_cut * span, (k - SLOW_EXTRA) / 2.0), 0.5)
    m = min(n, SLOW_GRID)  # the sequences are slow: computed on at most SLOW_GRID points, interpolated
    grid = np.linspace(t[0], t[-1], m)
    seq = np.atleast_2d(dpss(m, nw, k))
    basis = np.column_stack([np.ones(n), *(np.interp(t, grid, s) for s in seq)])
    coef, *_ = np.linalg.lstsq(basis[good], y[good], rcond=None)
    return y - basis @ coef


def sinusoid(t: np.ndarray, y: np.ndarray, f: float) -> tuple[float, float, np.ndarray]:
    """Least-squares A cos(2 pi f t + phi) + c on the valid samples: (A, phi, fitted curve). By the
    3 x 3 normal equations (eight dot products: ~5x faster than a QR of the n x 3 basis on long
    records, where the order search calls it dozens of times a candidate); by the QR where they are
    ill-conditioned (under about one cycle in the record)."""
    good = np.isfinite(y)
    arg = 2 * np.pi * f * np.asarray(t, dtype=float)
    cos, sin = np.cos(arg), np.sin(arg)
    if good.all():
        cg, sg, yg = cos, sin, np.asarray(y, dtype=float)
    else:
        cg, sg, yg = cos[good], sin[good], np.asarray(y, dtype=float)[good]
    sc, ss, n = float(cg.sum()), float(sg.sum()), float(cg.size)
    gram = np.array([[cg @ cg, cg @ sg, sc], [cg @ sg, sg @ sg, ss], [sc, ss, n]])
    rhs = np.array([cg @ yg, sg @ yg, float(yg.sum())])
    if np.linalg.cond(gram) < 1e8:
        coef = np.linalg.solve(gram, rhs)
    else:
        basis = np.stack([cg, sg, np.ones_like(cg)], axis=1)
        coef = np.linalg.lstsq(basis, yg, rcond=None)[0]
    curve = coef[0] * cos + coef[1] * sin + coef[2]
    return float(np.hypot(coef[0], coef[1])), float(np.arctan2(-coef[1], coef[0])), curve


#: records at least this long, on steady stamps without gaps, are scanned by `strongest_sinusoid`'s
#: closed-form normal equations (the short ones sinusoid by sinusoid, as before)
SCAN_MIN_SAMPLES = 20_000


def _geometric(theta: np.ndarray, n: int) -> np.ndarray:
    """sum_{k < n} e^{i theta k} per theta (n where e^{i theta} is 1)."""
    e = np.exp(1j * theta)
    den = 1.0 - e
    flat = np.abs(den) < 1e-12
    return np.where(flat, complex(n), (1.0 - np.exp(1j * n * theta)) / np.where(flat, 1.0, den))


def strongest_sinusoid(t: np.ndarray, y: np.ndarray, freqs: np.ndarray) -> float:
    """The frequency of `freqs` whose least-squares sinusoid (`sinusoid`) has the largest amplitude
    (the first of equal ones; `sinusoid_amplitudes`)."""
    return float(np.asarray(freqs, dtype=float)[int(np.argmax(sinusoid_amplitudes(t, y, freqs)))])


def sinusoid_amplitudes(t: np.ndarray, y: np.ndarray, freqs: np.ndarray) -> np.ndarray:
    """The amplitude of the least-squares sinusoid (`sinusoid`) at each of `freqs`. On a long record
    on steady stamps without gaps and an evenly spaced grid, the 3 x 3 normal equations of every
    grid frequency at once: the data's sums sum y e^{i w t_k} by one complex rotation of the
    samples per grid step, the basis' sums by geometric series (a one-hour 200 Hz record: 0.11 s
    for 41 frequencies against 1.2 s one by one); the same amplitudes to rounding, by `sinusoid`
    where they are ill-conditioned."""
    from vibinverse.io.file_basics import steady

    t = np.asarray(t, dtype=float)
    y = np.asarray(y, dtype=float)
    freqs = np.asarray(freqs, dtype=float)
    n = t.size
    fast = (
        n >= SCAN_MIN_SAMPLES
        and freqs.size > 1
        and bool(np.all(np.isfinite(y)))
        and steady(t)
        and np.allclose(np.diff(freqs), freqs[1] - freqs[0], rtol=1e-9, atol=0.0)
    )
    if not fast:
        return np.array([sinusoid(t, y, f)[0] for f in freqs])
    dt = (t[-1] - t[0]) / (n - 1)
    k = np.arange(n)
    omega = 2.0 * np.pi * freqs
    rotated = y * np.exp(1j * (omega[0] * dt) * k)
    step = np.exp(1j * (2.0 * np.pi * (freqs[1] - freqs[0]) * dt) * k)
    data = np.empty(freqs.size, dtype=complex)  # sum_k y_k e^{i w (t_k - t_0)}
    for j in range(freqs.size):
        data[j] = rotated.sum()
        if j + 1 < freqs.size:
            rotated *= step
    shift = np.exp(1j * omega * t[0])
    xy = shift * data  # sum y cos + i sum y sin
    s1 = shift * _geometric(omega * dt, n)  # sum cos + i sum sin
    s2 = shift**2 * _geometric(2.0 * omega * dt, n)  # sum e^{2 i w t_k}
    total = float(y.sum())
    amps = np.empty(freqs.size)
    for j in range(freqs.size):
        cc, ss, cs = 0.5 * (n + s2[j].real), 0.5 * (n - s2[j].real), 0.5 * s2[j].imag
        gram = np.array([[cc, cs, s1[j].real], [cs, ss, s1[j].imag], [s1[j].real, s1[j].imag, float(n)]])
        if np.linalg.cond(gram) < 1e8:
            coef = np.linalg.solve(gram, np.array([xy[j].real, xy[j].imag, total]))
            amps[j] = float(np.hypot(coef[0], coef[1]))
        else:
            amps[j] = sinusoid(t, y, float(freqs[j]))[0]
    return amps


def harmonics(t: np.ndarray, y: np.ndarray, f: float, nyq: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """(amplitude, phase) of y's sinusoids at f and 2f (2f at or above Nyquist: (0, 0))."""
    return sinusoid(t, y, f)[:2], (sinusoid(t, y, 2 * f)[:2] if 2 * f < nyq else (0.0, 0.0))


def _refine(freqs: np.ndarray, power: np.ndarray, i: int) -> float:
    if 0 < i < len(freqs) - 1:
        a, b, c = np.log(power[i - 1 : i + 2] + 1e-300)
        den = a - 2 * b + c
        if den < 0:
            return float(freqs[i] + 0.5 * (a - c) / den * (freqs[1] - freqs[0]))
    return float(freqs[i])


def line_candidates(series: Series, band: tuple[float, float], n_candidates: int = 3) -> list[float]:
    """Periodogram peaks in `band` (at least 0.3 Hz apart), most steady first: a drive is the same
    sinusoid in each quarter of the record, while a noise-driven resonance's phase wanders over its
    coherence time 1/(zeta omega). Steadiness ranks; the MAP fit decides between the candidates.

    Each peak is taken from the periodogram of what the peaks before it leave (their sinusoids
    subtracted): a strong, lightly damped resonance's window sidelobes would otherwise hide a weak
    line far from it. What is slower than the band (below its lower edge, and below SLOW_CYCLES
    cycles per record: a band that starts between two lines is no slow part) is regressed out
    first (`highpassed`): a gain drift of 20 % on a bright level leaked as 1/f^2 over the whole
    periodogram and buried a 10 Hz drive 70 times over (a Hann taper would do it too, but it
    silences a decay at the record's start). A peak is the largest ratio of the power to its local
    background (the running median over BACKGROUND_BINS Fourier bins, `local_background`), not the largest power: under
    coloured noise (AR(1), 1/f, a drift) the raw periodogram's largest values are the noise's low
    frequencies, and a drive standing 20 times over its neighbours at 10 Hz came after three of
    them (the scene fit then started its drive there and stayed); over a flat floor the two
    rankings agree."""
    t, y = series.time, series.intensity
    span = float(t[-1] - t[0]) if t.size > 1 else 0.0
    slow = min(band[0], SLOW_CYCLES / span) if span > 0 else 0.0
    resid = highpassed(t, y, slow) if slow > 0 else y - np.nanmean(y)
    picked: list[float] = []
    for _ in range(n_candidates):
        freqs, power = periodogram(Series(t, resid, series.source))
        sel = (freqs >= band[0]) & (freqs <= band[1])
        for f in picked:
            sel &= np.abs(freqs - f) > 0.3
        if not sel.any():
            break
        idx = np.flatnonzero(sel)
        excess = power / local_background(power, PAD * BACKGROUND_BINS)
        f = _refine(freqs, power, int(idx[np.argmax(excess[idx])]))
        picked.append(f)
        resid = resid - sinusoid(t, resid, f)[2]
    quarter = np.minimum((4 * (t - t[0]) / (t[-1] - t[0] + series.dt)).astype(int), 3)
    scored = []
    for f in picked:
        z = np.array(
            [a * np.exp(1j * p) for a, p, _ in (sinusoid(t[quarter == j], y[quarter == j], f) for j in range(4))]
        )
        scored.append((float(np.abs(z - z.mean()).max() / max(np.abs(z.mean()), 1e-300)), f))
    return [f for _, f in sorted(scored)]


#: `passband_top`: the spectrum's level is the median of each of at most ROLLOFF_BANDS equal bands
#: of at least ROLLOFF_ORDINATES ordinates up to Nyquist (fewer than ROLLOFF_MIN_BANDS: not read)
ROLLOFF_BANDS, ROLLOFF_ORDINATES, ROLLOFF_MIN_BANDS = 100, 40, 40
#: the trend below a roll-off is a power law fitted over this fraction of Nyquist below the knee,
#: where the levels stay within ROLLOFF_SMOOTH_DB of it in rms beside their own scatter (no peak
#: there): the median of N exponential ordinates has a log sd of 1 / (ln 2 sqrt N), 6.3 / sqrt N dB
ROLLOFF_WINDOW, ROLLOFF_SMOOTH_DB = 0.25, 1.0
#: a roll-off: the top 3 % of the band ROLLOFF_DROP_DB below that trend's extrapolation and
#: ROLLOFF_BELOW_DB below every band from 0.1 x Nyquist to the knee
ROLLOFF_DROP_DB, ROLLOFF_BELOW_DB = 10.0, 6.0
#: the passband ends ROLLOFF_MARGIN x Nyquist below the last band whose 3-band running median is
#: within ROLLOFF_KEPT_DB of the trend (the roll-off's first decibel is in the trend's window)
ROLLOFF_KEPT_DB, ROLLOFF_MARGIN = 1.0, 0.025


def band_levels(y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(level dB, lower edge, upper edge) of equal bands up to Nyquist (edges as fractions of it):
    each the median ordinate of the periodogram of the record's differences over |1 - e^{-iw}|^2 (the
    record's own spectrum, without the leakage of a drift's end-to-end jump), in decibels."""
    d = np.diff(np.asarray(y, dtype=float))
    m = d.size
    spec = np.fft.rfft(d)[1 : m // 2 + 1]
    w = 2.0 * np.pi * np.arange(1, spec.size + 1) / m
    power = (spec.real**2 + spec.imag**2) / m / (4.0 * np.sin(0.5 * w) ** 2)
    nb = int(min(ROLLOFF_BANDS, spec.size // ROLLOFF_ORDINATES))
    if nb < 1:
        return np.empty(0), np.empty(0), np.empty(0)
    edges = np.linspace(0, spec.size, nb + 1).astype(int)
    level = np.array([np.median(power[a:b]) for a, b in itertools.pairwise(edges)])
    level = 10.0 * np.log10(np.maximum(level, np.finfo(float).tiny))
    return level, edges[:-1] / spec.size, edges[1:] / spec.size


def passband_top(series: Series) -> float | None:
    """The top (Hz) of the band below a logger's anti-alias roll-off, None when the record shows
    none (or is gappy, irregular or under ROLLOFF_MIN_BANDS x ROLLOFF_ORDINATES x 2 samples).

    A record low-pass filtered before it was sampled or decimated (a logger's anti-alias filter;
    `scipy.signal.decimate` and MATLAB's `decimate`: a Chebyshev filter from 0.8 x Nyquist; a
    sigma-delta converter's from ~0.9) has a spectrum that plunges towards Nyquist, which a sampled
    continuous-time model (white noise flat to Nyquist, resonances' tails aliased) cannot follow:
    fitted to the whole band, 20-90 min 10 Hz building records so decimated got five or six modes,
    one a broad "mode" near Nyquist carrying the noise floor, claimed. Read here from the band
    levels (`band_levels`): from the highest knee down (0.95 to 0.5 x Nyquist by 0.025), the first
    window below it that a power law fits within ROLLOFF_SMOOTH_DB (beside the levels' scatter) is
    the trend; a roll-off when the top 3 % of the band lies ROLLOFF_DROP_DB under the trend's
    extrapolation and ROLLOFF_BELOW_DB under every band from 0.1 x Nyquist to the knee (a
    resonance's tail falls as a power law, and a floor after a peak is no lower than the floor
    before it). The top: ROLLOFF_MARGIN x Nyquist below the upper edge of the last band whose
    3-band running median is within ROLLOFF_KEPT_DB of the trend. Measured: white noise, AR(1)
    phi 0.9, a random walk, a box filter (frame exposure), a resonance at 0.7 or 0.9 x Nyquist on
    a flat floor and a steep resonance tail give none; `decimate` (IIR, 0.8) of white noise by 10
    gives 0.8 x Nyquist, a 255-tap FIR at 0.9 0.825. `decimate`'s FIR variant (a Hamming window
    whose -6 dB point is Nyquist) folds its own transition back: white noise stays within 3 dB of
    flat, and none is read."""
    from scipy.ndimage import median_filter

    y = np.asarray(series.intensity, dtype=float)
    if not series.uniform or not np.all(np.isfinite(y)) or y.size < 2 * ROLLOFF_MIN_BANDS * ROLLOFF_ORDINATES:
        return None
    level, lo, hi = band_levels(y)
    if level.size < ROLLOFF_MIN_BANDS:
        return None
    scatter = 6.3 / np.sqrt((y.size - 1) // 2 / level.size)  # dB, a band level's sd
    smooth = float(np.hypot(ROLLOFF_SMOOTH_DB, 2.0 * scatter))
    mid = 0.5 * (lo + hi)
    top = float(np.median(level[lo >= 0.97 - 1e-9]))
    for knee in np.arange(0.95, 0.5 - 1e-9, -0.025):
        window = (lo >= knee - ROLLOFF_WINDOW - 1e-9) & (hi <= knee + 1e-9)
        x = np.log10(mid[window])
        coef = np.polyfit(x, level[window], 1)
        if np.sqrt(np.mean((np.polyval(coef, x) - level[window]) ** 2)) > smooth:
            continue  # a peak or the roll-off itself in the window: a lower knee
        drop = float(np.polyval(coef, np.log10(0.985))) - top
        below = float(level[(lo >= 0.1) & (hi <= knee + 1e-9)].min()) - top
        if drop < ROLLOFF_DROP_DB or below < ROLLOFF_BELOW_DB:
            return None  # a smooth stretch with no plunge after it
        near = median_filter(level - np.polyval(coef, np.log10(mid)), size=3, mode="nearest")
        kept = np.flatnonzero((lo >= knee - ROLLOFF_WINDOW - 1e-9) & (near >= -ROLLOFF_KEPT_DB))
        return float(((hi[kept.max()] if kept.size else knee) - ROLLOFF_MARGIN) * 0.5 * series.fs)
    return None


def white_floor(series: Series) -> float | None:
    """An upper bound of the record's white-noise sigma: the square root of the lowest band's
    median ordinate over ln 2 (`band_levels`, the bands from 0.05 x Nyquist to the series' `top`;
    white noise of sigma has mean ordinate sigma^2, median sigma^2 ln 2). None for a gappy or
    irregular record, or one too short for bands."""
    y = np.asarray(series.intensity, dtype=float)
    if not series.uniform or not np.all(np.isfinite(y)):
        return None
    level, lo, hi = band_levels(y)
    inside = (lo >= 0.05) & (hi * 0.5 * series.fs <= series.top * (1.0 + 1e-9))
    if not inside.any():
        return None
    return float(np.sqrt(10.0 ** (level[inside].min() / 10.0) / np.log(2.0)))
