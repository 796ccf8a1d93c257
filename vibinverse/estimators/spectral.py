"""Spectral estimates: Lomb-Scargle peaks and a sinusoid fit, calibrated through the forward model.

Seconds, rough, and gap-tolerant. They seed the MAP fit and report what a periodogram alone says.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import uniform_filter1d
from scipy.signal import lombscargle

from vibinverse.data import Series
from vibinverse.frame_model import FrameLikelihood


def periodogram(series: Series, pad: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Power of the de-meaned series on (0, Nyquist]. Uniform sampling: FFT with `pad`-fold zero
    padding, gaps filled with the mean; otherwise Lomb-Scargle on the valid samples."""
    good = np.isfinite(series.intensity)
    y = series.intensity - np.nanmean(series.intensity)
    if series.uniform:
        filled = np.where(good, y, 0.0)
        n = pad * filled.size
        power = np.abs(np.fft.rfft(filled, n)) ** 2 / max(good.sum(), 1)
        freqs = np.fft.rfftfreq(n, series.dt)
        return freqs[1:], power[1:]
    t = series.time[good]
    span = t[-1] - t[0]
    freqs = np.linspace(0.5 / span, 0.5 * series.fs, int(pad * span * series.fs / 2))
    return freqs, lombscargle(t, y[good], 2 * np.pi * freqs)  # y is de-meaned over the valid samples


def sinusoid(t: np.ndarray, y: np.ndarray, f: float) -> tuple[float, float, np.ndarray]:
    """Least-squares A cos(2 pi f t + phi) + c on the valid samples: (A, phi, fitted curve)."""
    good = np.isfinite(y)
    basis = np.stack([np.cos(2 * np.pi * f * t), np.sin(2 * np.pi * f * t), np.ones_like(t)], axis=1)
    coef = np.linalg.lstsq(basis[good], y[good], rcond=None)[0]
    return float(np.hypot(coef[0], coef[1])), float(np.arctan2(-coef[1], coef[0])), basis @ coef


def harmonics(t: np.ndarray, y: np.ndarray, f: float, nyq: float) -> tuple[tuple[float, float], tuple[float, float]]:
    """(amplitude, phase) of y's sinusoids at f and 2f (2f at or above Nyquist: (0, 0))."""
    return sinusoid(t, y, f)[:2], (sinusoid(t, y, 2 * f)[:2] if 2 * f < nyq else (0.0, 0.0))


def _refine(freqs: np.ndarray, power: np.ndarray, i: int) -> float:
    if 0 < i < len(freqs) - 1:
        a, b, c = np.log(power[i - 1:i + 2] + 1e-300)
        den = a - 2 * b + c
        if den < 0:
            return float(freqs[i] + 0.5 * (a - c) / den * (freqs[1] - freqs[0]))
    return float(freqs[i])


def line_candidates(series: Series, band: tuple[float, float], n_candidates: int = 3) -> list[float]:
    """Periodogram peaks in `band` (at least 0.3 Hz apart), most steady first: a drive is the same
    sinusoid in each quarter of the record, while a noise-driven resonance's phase wanders over its
    coherence time 1/(zeta omega). Steadiness ranks; the MAP fit decides between the candidates."""
    freqs, power = periodogram(series)
    sel = (freqs >= band[0]) & (freqs <= band[1])
    if not sel.any():
        return []
    idx = np.flatnonzero(sel)
    order = idx[np.argsort(power[idx])[::-1]]
    picked: list[int] = []
    for i in order:
        if all(abs(freqs[i] - freqs[j]) > 0.3 for j in picked):
            picked.append(int(i))
        if len(picked) == n_candidates:
            break
    t, y = series.time, series.intensity
    quarter = np.minimum((4 * (t - t[0]) / (t[-1] - t[0] + series.dt)).astype(int), 3)
    scored = []
    for i in picked:
        f = _refine(freqs, power, i)
        z = np.array([a * np.exp(1j * p) for a, p, _ in (sinusoid(t[quarter == j], y[quarter == j], f) for j in range(4))])
        scored.append((float(np.abs(z - z.mean()).max() / max(np.abs(z.mean()), 1e-300)), f))
    return [f for _, f in sorted(scored)]


def frame_guesses(series: Series, like: FrameLikelihood, bounds: dict[str, tuple[float, float]] | None = None
                  ) -> list[dict[str, float]]:
    """Candidate initial values, one per plausible drive line (most steady first). Further drive
    lines (`drive_frequency[i]`, i >= 1) with a prior in `bounds` start at the strongest steady
    peak inside that prior, their amplitude and phase calibrated through the forward model."""
    bounds = bounds or {}
    nyq = 0.5 * series.fs
    has_drive = bool(like.base["surfaces"][like.roof]["motion"].get("drive_frequency"))
    lines = line_candidates(series, bounds.get(like.key + "drive_frequency", (0.0, nyq))) if has_drive else []
    guesses = [frame_guess(series, like, bounds, f) for f in lines] or [frame_guess(series, like, bounds, None)]
    for g in guesses:
        _extra_lines(series, like, bounds, g)
    return guesses


def _extra_lines(series: Series, like: FrameLikelihood, bounds: dict[str, tuple[float, float]],
                 guess: dict[str, float]) -> None:
    k = like.key
    n_lines = len(like.base["surfaces"][like.roof]["motion"].get("drive_frequency") or [])
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


def frame_guess(series: Series, like: FrameLikelihood, bounds: dict[str, tuple[float, float]] | None = None,
                f_d: float | None = None, resonance: tuple[float, float] | None = None) -> dict[str, float]:
    """Initial values of the frame parameters from the spectrum (names as in FrameLikelihood), given
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
    series_r = Series(t, resid, series.source)
    fr, pr = periodogram(series_r)
    smooth = uniform_filter1d(pr, max(3, int(0.3 / (fr[1] - fr[0]))))
    if has_drive:
        smooth[np.abs(fr - guess[k + "drive_frequency"]) < 1.0] = 0.0
    lo_f, hi_f = bounds.get(k + "tilt_frequency", (0.3, nyq))
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
    unit_var = float(c.h @ c.p0 @ c.h)
    stoch = max(float(np.nanvar(resid)) - sigma**2, 1e-6 * sigma**2)
    guess[k + "noise_rms"] = float(np.sqrt(stoch / max(unit_var, 1e-300)))
    return guess
