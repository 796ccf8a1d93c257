"""Checks of a fitted model against the data: are its standardized one-step residuals white and
Gaussian, as they are when the model describes the data?

Whiteness: the Ljung-Box portmanteau test (Ljung & Box 1978), Q = n (n + 2) sum_k rho_k^2 / (n - k)
over lags 1..h, chi-squared with h degrees of freedom when the residuals are white; rho_k is formed
from the pairs where both samples exist, so gaps are allowed. Normality: D'Agostino and Pearson's
K^2 test of skewness and kurtosis (`scipy.stats.normaltest`). A check fails at p < `ALPHA`: 1 %, so
that a model that does describe the data is flagged in 1 fit in 100 per check; each check also
needs a departure that matters (WHITE_MATERIAL; SKEW_MATERIAL, KURTOSIS_MATERIAL), which a long
record detects long before it does.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy import stats

ALPHA = 0.01
MAX_LAGS = 20
#: departures from normality too small to matter, however long the record that detects them: the
#: Gaussian likelihood's estimates stay consistent under non-Gaussian innovations, and an excess
#: kurtosis k widens the true sd of a variance parameter (noise_rms, sigma) by sqrt(1 + k / 2) over
#: the Gaussian one: under 6 % at 0.25; a skewness of 0.1 is a 1-in-60 asymmetry of the tails at
#: 3 sd. Below n ~ 10^4 a normality test fails before these are reached. (A one-hour 200 Hz frame
#: record without sensor noise, 720 000 residuals: skewness 0.002, excess kurtosis -0.002, p = 0.79.
#: Its kurtosis of 0.064 to 1.33 before, p = 1e-25, came from a dozen residuals of 5-30 sd at the
#: start: the simulator's stationary start skipped a step, `forward.motion.frame.propagate_zoh`.)
SKEW_MATERIAL, KURTOSIS_MATERIAL = 0.1, 0.25
#: the same for whiteness: 2 sum_k |rho_k| over the lags tested bounds how far the residuals'
#: spectrum, 1 + 2 sum_k rho_k cos(2 pi f k dt) in units of white noise's, departs from flat; within
#: 12.5 % a parameter's true sd differs from the one the fit reports by under 6 %, as above. Below
#: n ~ 10^4 the Ljung-Box test cannot reject with a smaller departure. (The one-hour frame record
#: without sensor noise, seed 1: p = 0.0008 from |rho_k| <= 0.003, departure 0.06: the linearized
#: observation's quadratic term, ~1e-4 of the signal, against an innovation that small.)
WHITE_MATERIAL = 0.125


def autocorrelation(e: np.ndarray, lags: int) -> np.ndarray:
    """Sample autocorrelation of `e` at lags 1..`lags` over the pairs where both samples exist
    (NaN = gap), about the mean of the samples that exist."""
    good = np.isfinite(e)
    x = np.where(good, e - np.mean(e[good]), 0.0)
    var = float(np.dot(x, x)) / max(int(good.sum()), 1)
    out = np.empty(lags)
    for k in range(1, lags + 1):
        pairs = good[k:] & good[:-k]
        n = int(pairs.sum())
        out[k - 1] = float(np.dot(x[k:][pairs], x[:-k][pairs])) / n / var if n > 0 and var > 0 else math.nan
    return out


def ljung_box(e: np.ndarray, lags: int | None = None, rho: np.ndarray | None = None) -> tuple[float, float, int]:
    """(Q, p-value, lags) of the Ljung-Box test of `e` (NaN = gap); lags defaults to
    min(MAX_LAGS, n // 5); `rho`, the autocorrelation at lags 1..lags, when already computed."""
    n = int(np.isfinite(e).sum())
    h = int(lags if lags is not None else min(MAX_LAGS, n // 5))
    if h < 1:
        return math.nan, math.nan, 0
    rho = autocorrelation(e, h) if rho is None else rho
    k = np.arange(1, h + 1)
    q = float(n * (n + 2) * np.nansum(rho * rho / (n - k)))
    return q, float(stats.chi2.sf(q, h)), h


def in_band(e: np.ndarray, top: float) -> np.ndarray:
    """The residuals' part below `top` cycles per sample, on the coarser grid of 2 k samples that
    holds it (k its Fourier ordinates: the transform's ordinates up to k, inverted at length 2 k).
    White residuals in that band give white values (the ordinates are independent); gaps are zeros
    about the mean."""
    good = np.isfinite(e)
    x = np.where(good, e - np.mean(e[good]), 0.0)
    spec = np.fft.rfft(x)
    k = max(1, min(spec.size - 1, int(np.floor(top * x.size))))
    return np.fft.irfft(spec[: k + 1], 2 * k) * math.sqrt(2 * k / x.size)


def residual_checks(e: np.ndarray, top: float | None = None) -> dict[str, Any]:
    """Whiteness and normality of standardized residuals `e` (NaN = gap): the p-values, the lags
    used, and whether each check passes at ALPHA; {} with fewer than 20 residuals. `top` (cycles per
    sample): the residuals of a model fitted below a logger's anti-alias roll-off (`Series.passband`)
    are checked in that band (`in_band`); above it the filter shapes them, not the model."""
    if top is not None and top < 0.5 and np.isfinite(e).sum() >= 40:
        e = in_band(e, top)
    good = e[np.isfinite(e)]
    if good.size < 20:
        return {}
    h = min(MAX_LAGS, good.size // 5)
    rho = autocorrelation(e, h)
    _, p_white, h = ljung_box(e, h, rho)
    departure = float(2.0 * np.nansum(np.abs(rho)))
    p_normal = float(stats.normaltest(good).pvalue)
    skew, kurtosis = float(stats.skew(good)), float(stats.kurtosis(good))
    material = abs(skew) > SKEW_MATERIAL or abs(kurtosis) > KURTOSIS_MATERIAL
    return {
        "ljung_box_p": p_white,
        "lags": h,
        "normality_p": p_normal,
        "skewness": skew,
        "excess_kurtosis": kurtosis,
        "spectral_departure": departure,
        "white": bool(p_white >= ALPHA or departure <= WHITE_MATERIAL),
        "normal": bool(p_normal >= ALPHA or not material),
        "alpha": ALPHA,
    }


def describes_data(checks: dict[str, Any]) -> str | None:
    """A warning in plain words when the residual checks fail, else None."""
    if not checks:
        return None
    problems = []
    if not checks.get("white", True):
        problems.append(
            f"the residuals are not white (Ljung-Box p = {checks['ljung_box_p']:.2g} over {checks['lags']} lags): "
            "the model misses structure in the data (another resonance or line, drift or coloured noise)"
        )
    if not checks.get("normal", True):
        problems.append(
            f"the residuals are not Gaussian (normality p = {checks['normality_p']:.2g}): outliers, "
            "quantization or a noise model that does not fit"
        )
    return "; ".join(problems) or None
