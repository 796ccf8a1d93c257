"""Spectral starting values of the frame model (sec. 4.2): the drive line from the most steady
periodogram peak, the resonance from the residual's smoothed peak and its half-power width, and
amplitudes calibrated through the forward model (its response per unit drive and per unit noise).
Milliseconds, rough; the MAP decides between the candidates. Any stamps: the periodogram is the FFT
on a uniform grid and Lomb-Scargle on irregular stamps (`vibinverse.spectrum.periodogram`), the
sinusoids are least squares at the stamps.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d

from vibinverse.io.series import Series
from vibinverse.models.base import SignalModel
from vibinverse.spectrum import highpassed, line_candidates, periodogram, sinusoid


def frame_guesses(
    series: Series, like: SignalModel, bounds: dict[str, tuple[float, float]] | None = None
) -> list[dict[str, float]]:
    """Candidate initial values, one per plausible drive line (most steady first). Further drive
    lines (`drive_frequency[i]`, i >= 1) with a prior in `bounds` start at the strongest steady
    peak inside that prior, their amplitude and phase calibrated through the forward model."""
    bounds = bounds or {}
    nyq = 0.5 * series.fs
    has_drive = like.n_lines > 0
    lines = line_candidates(series, bounds.get(like.key + "drive_frequency", (0.0, nyq))) if has_drive else []
    guesses = [frame_guess(series, like, bounds, f) for f in lines] or [frame_guess(series, like, bounds, None)]
    for g in guesses:
        _extra_lines(series, like, bounds, g)
    return guesses


def _extra_lines(
    series: Series, like: SignalModel, bounds: dict[str, tuple[float, float]], guess: dict[str, float]
) -> None:
    k = like.key
    n_lines = like.n_lines
    t, y = series.time, series.intensity
    for i in range(1, n_lines):
        name = f"{k}drive_frequency[{i}]"
        if name not in bounds:
            continue
        found = line_candidates(series, bounds[name], n_candidates=1)
        if not found:
            continue
        f = found[0]
        guess[name] = f
        amp_sig, ph_sig, _ = sinusoid(t, y, f)
        probe = {**guess, f"{k}drive_amplitude[{i}]": 1.0, f"{k}drive_phase[{i}]": 0.0, k + "noise_rms": 0.0}
        for j in range(n_lines):
            if j != i:
                probe[f"{k}drive_amplitude[{j}]"] = 0.0
        probe.pop(k + "drive_amplitude", None)
        amp_m, ph_m, _ = sinusoid(t, like.components(probe).mean, f)
        guess[f"{k}drive_amplitude[{i}]"] = amp_sig / max(amp_m, 1e-300)
        guess[f"{k}drive_phase[{i}]"] = float(np.angle(np.exp(1j * (ph_sig - ph_m))))


def frame_guess(
    series: Series,
    like: SignalModel,
    bounds: dict[str, tuple[float, float]] | None = None,
    f_d: float | None = None,
    resonance: tuple[float, float] | None = None,
) -> dict[str, float]:
    """Initial values of the frame parameters from the spectrum (names as in FrameModel), given
    the drive line f_d (None: no drive), searching the resonance within its prior `bounds`, or
    taking it as given (`resonance` = (frequency, damping ratio), e.g. from SINDy)."""
    k = like.key
    bounds = bounds or {}
    t, y = series.time, series.intensity.copy()
    nyq = 0.5 * series.fs
    guess: dict[str, float] = {}
    resid = y - np.nanmean(y)
    has_drive = f_d is not None
    if has_drive:
        amp_sig, ph_sig, fit = sinusoid(t, y, f_d)
        resid = y - fit
        guess[k + "drive_frequency"] = f_d
    # second differences: white noise dominates them, the slow tilt process hardly enters
    d2 = np.diff(resid, 2)
    sigma = float(np.nanstd(d2) / np.sqrt(6.0))
    guess["noise.sigma"] = sigma
    # the resonance: the smoothed periodogram's peak within its prior, its half-power width; the
    # periodogram of the residual less its part slower than the prior's lower edge (`highpassed`)
    # and tapered: a gain drift of 20 % on the level leaked as 1/f^2 over the untapered spectrum,
    # and the Hann window's main lobe alone still held the prior's lower edge 400x over a 3.5 Hz
    # resonance
    lo_f, hi_f = bounds.get(k + "tilt_frequency", (0.3, nyq))
    fast = highpassed(t, resid, lo_f)
    series_r = Series(t, fast, series.source)
    fr, pr = periodogram(series_r, taper=True)
    pr = np.where(fr >= lo_f, pr, 0.0)  # what is left below the prior is not smoothed into it
    smooth = uniform_filter1d(pr, max(3, int(0.3 / (fr[1] - fr[0]))))
    if has_drive:
        smooth[np.abs(fr - guess[k + "drive_frequency"]) < 1.0] = 0.0
    smooth[(fr < lo_f) | (fr > hi_f)] = 0.0
    i = int(np.argmax(smooth))
    f_t = float(fr[i])
    half = smooth[i] / 2
    lo, hi = i, i
    while lo > 0 and smooth[lo] > half:
        lo -= 1
    while hi < len(fr) - 1 and smooth[hi] > half:
        hi += 1
    zeta = float(np.clip((fr[hi] - fr[lo]) / (2 * f_t), 0.002, 0.3))
    if resonance is not None:
        f_t, zeta = resonance
    guess[k + "tilt_frequency"] = f_t
    guess[k + "tilt_damping_ratio"] = zeta
    # amplitudes through the forward model: its response per unit drive and per unit noise
    probe = dict(guess)
    if has_drive:
        probe.update({k + "drive_amplitude": 1.0, k + "drive_phase": 0.0, k + "noise_rms": 0.0})
        c = like.components(probe)
        amp_m, ph_m, _ = sinusoid(t, c.mean, guess[k + "drive_frequency"])
        guess[k + "drive_amplitude"] = amp_sig / max(amp_m, 1e-300)
        guess[k + "drive_phase"] = float(np.angle(np.exp(1j * (ph_sig - ph_m))))
    probe.update({k + "noise_rms": 1.0, k + "drive_amplitude": 0.0, k + "drive_frequency": f_d or 1.0})
    c = like.components(probe)
    unit_var = c.tilt_variance()
    # the slow part is not the tilt: a gain drift's variance made the tilt's start so large that
    # the pixel saw it at second order
    stoch = max(float(np.nanvar(fast)) - sigma**2, 1e-6 * sigma**2)
    guess[k + "noise_rms"] = float(np.sqrt(stoch / max(unit_var, 1e-300)))
    return guess
